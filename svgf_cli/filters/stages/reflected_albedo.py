"""Reflected albedo (optional): sharp reflections demodulated by the albedo they reflect."""

from __future__ import annotations

import dataclasses

from svgf_cli.filters.context import FrameContext, StageBase
from svgf_cli.filters.params import SVGFParams
from svgf_cli.filters.reflected_albedo import reflect


class ReflectedAlbedo(StageBase):
    """Each glossy signal's demodulation colour replaced, on diffuse-free pixels of objects
    whose G-buffer albedo shows a sharp reflection, by that albedo (floored) or a mix of
    the two by how sharp (``filters.reflected_albedo``); demodulation and remodulation both
    read the new colour. New arrays (the caller's planes are never modified);
    ``counts["reflected_albedo.<signal>"]`` gets the pixels changed, ``ctx.sharp_objects``
    the objects found sharp per signal (for ``reflected_lights``, after it) and
    ``ctx.rough_objects`` those found rough (for ``history_clamp``)."""

    name = "reflected_albedo"
    reads = ("frame.signals", "frame.albedo", "frame.mesh_id", "depth")
    writes = ("frame.signals", "sharp_objects", "rough_objects")
    clock = "demodulate"

    def enabled(self, params: SVGFParams) -> bool:
        return params.reflected_albedo

    def run(self, ctx: FrameContext) -> bool:
        frame = ctx.frame
        glossy = [i for i, signal in enumerate(frame.signals) if signal.glossy]
        if not glossy:
            return False
        diffuse = [signal.albedo for signal in frame.signals if not signal.glossy]
        signals = list(frame.signals)
        for index in glossy:
            signal = signals[index]
            found, rough = reflect(signal.albedo, frame.albedo, diffuse, ctx.depth,
                                   frame.mesh_id)
            if rough is not None:
                ctx.rough_objects[index] = rough
            if found is not None:
                signals[index] = dataclasses.replace(signal, albedo=found[0])
                ctx.counts[f"reflected_albedo.{signal.name}"] = found[1]
                ctx.sharp_objects[index] = found[2]
        ctx.frame = dataclasses.replace(frame, signals=signals)
        return True
