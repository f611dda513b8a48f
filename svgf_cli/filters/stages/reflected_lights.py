"""Reflected lights: glossy signals filtered as radiance where a specular path hit a light."""

from __future__ import annotations

import dataclasses

import numpy as np

from svgf_cli.filters import modulate
from svgf_cli.filters.context import MAX_REFLECTANCE, FrameContext, StageBase
from svgf_cli.filters.params import SVGFParams
from svgf_cli.filters.reflected_albedo import SharpObjects

F32 = np.float32
_NONE_SHARP = SharpObjects(0, np.zeros(1, dtype=np.uint8))  # no object is sharp


class MarkReflectedLights(StageBase):
    """Each glossy signal's demodulation colour replaced by the G-buffer albedo where that
    is no reflectance (``modulate.emitter_colour``): a specular path reached a light there,
    and the signal is filtered as radiance. A lit pixel needs fewer lit neighbours on the
    objects the reflected albedo found sharp (``ctx.sharp_objects``), and none within two
    pixels of a light's large image (``modulate.unmark_large_images``). Written into workspace
    planes (the caller's planes are never modified); demodulation and remodulation both read
    the replaced colour, so the modes agree. ``ctx.marked`` gets the pixels marked per
    glossy signal."""

    name = "reflected_lights"
    reads = ("frame.albedo", "frame.mesh_id", "depth", "sharp_objects")
    writes = ("reflected_lights", "reflected_lights_scratch", "emitter_colour.<i>")
    clock = "demodulate"

    def enabled(self, params: SVGFParams) -> bool:
        return params.glossy_emitter_radiance

    def run(self, ctx: FrameContext) -> None:
        frame, work, marked = ctx.frame, ctx.work, ctx.marked
        marked.update({signal.name: 0 for signal in frame.signals if signal.glossy})
        if not marked:
            return
        lit = work["reflected_lights"]
        if not modulate.reflected_lights(frame.albedo, F32(MAX_REFLECTANCE), lit):
            return  # the albedo AOV is a reflectance everywhere: nothing to mark
        scratch = work["reflected_lights_scratch"]
        modulate.unmark_large_images(lit, scratch[0], scratch[1])
        rows = np.zeros(frame.height, dtype=np.int64)
        signals = []
        for index, signal in enumerate(frame.signals):
            if signal.glossy:
                colour = work[f"emitter_colour.{index}"]
                sharp = ctx.sharp_objects.get(index, _NONE_SHARP)
                table = sharp.table if sharp.table.size else _NONE_SHARP.table
                modulate.emitter_colour(signal.albedo, frame.albedo, lit, ctx.depth,
                                        frame.mesh_id, np.int64(sharp.low_id), table, colour,
                                        rows)
                marked[signal.name] = int(rows.sum())
                signal = dataclasses.replace(signal, albedo=colour)
            signals.append(signal)
        ctx.frame = dataclasses.replace(frame, signals=signals)
