"""Medium pixels: the G-buffer of a pixel whose sample scattered in fog or smoke
(``filters.medium``)."""

from __future__ import annotations

import dataclasses

import numpy as np

from svgf_cli.filters.context import FrameContext, StageBase
from svgf_cli.filters.medium import (
    MEDIUM_DEPTH,
    MEDIUM_ID,
    MEDIUM_SURFACE,
    NO_FILL,
    fill_sources,
    filled,
)
from svgf_cli.filters.params import SVGFParams


class FillMedium(StageBase):
    """Each medium pixel (no surface, medium light around it) takes the G-buffer (depth,
    normal, motion, object id, albedo and every signal's demodulation colour) of the
    nearest surface within ``medium_fill_radius`` pixels, or becomes a medium surface of
    its own, and its emission joins the medium's signal (`emission_into_medium`); the
    frame's planes are copied, never written. A frame without medium light
    (``Frame.medium`` None: no volume passes) skips it."""

    name = "fill_medium"
    reads = ("frame.medium", "depth", "normal_in", "motion", "frame.mesh_id", "frame.albedo",
             "frame.signals", "frame.emission")
    writes = ("depth", "normal_in", "motion", "frame", "medium_pixels", "medium_signal")
    clock = "medium"

    def enabled(self, params: SVGFParams) -> bool:
        return params.medium_fill_radius > 0

    def run(self, ctx: FrameContext) -> bool | None:
        frame = ctx.frame
        if frame.medium is None:
            return False
        sources = np.empty(ctx.depth.shape, np.int32)
        if not fill_sources(ctx.depth, frame.medium, ctx.params.medium_fill_radius, sources):
            return None
        ctx.medium_pixels = sources != NO_FILL
        ctx.depth = filled(ctx.depth, sources, MEDIUM_DEPTH)
        normal = filled(ctx.normal_in, sources)
        own = sources == MEDIUM_SURFACE
        normal[0][own], normal[1][own], normal[2][own] = 0.0, 0.0, 1.0
        ctx.normal_in = normal
        ctx.motion = filled(ctx.motion, sources)
        albedos: dict[int, np.ndarray] = {}  # signals sharing a colour share its fill
        for signal in frame.signals:
            if id(signal.albedo) not in albedos:
                albedos[id(signal.albedo)] = filled_unless_constant(signal.albedo, sources)
        signals = [dataclasses.replace(s, albedo=albedos[id(s.albedo)]) for s in frame.signals]
        emission = frame.emission
        medium = next((i for i, s in enumerate(frame.signals) if s.radiance is frame.medium),
                      None)
        ctx.medium_signal = medium
        if emission is not None and medium is not None:
            signals[medium].radiance, emission = emission_into_medium(
                frame.medium, emission, ctx.medium_pixels)
        ctx.frame = dataclasses.replace(
            frame, mesh_id=filled(frame.mesh_id, sources, MEDIUM_ID),
            albedo=filled(frame.albedo, sources), signals=signals, emission=emission)
        return None


def filled_unless_constant(plane: np.ndarray, sources: np.ndarray) -> np.ndarray:
    """:func:`filled` of ``plane``, or ``plane`` itself where every value has the same bits
    (a signal demodulated by white: filling gives the same plane, and a copy would only be
    more memory)."""
    bits = plane.reshape(-1).view(np.uint32) if plane.dtype == np.float32 else None
    if bits is not None and bits.size:
        # A sample of ~1000 values first: a textured colour is told apart without two
        # passes over the whole plane.
        sample = bits[::max(1, bits.size // 1024)]
        if sample.min() == sample.max() and bits.min() == bits.max():
            return plane
    return filled(plane, sources)


def emission_into_medium(medium: np.ndarray, emission: np.ndarray, pixels: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray]:
    """The medium's light with the emission of the medium ``pixels`` added, and the emission
    without it (copies). What a renderer files as emission there (Cycles' ``Env``: the sky
    seen through the medium; a light behind it) is one sample of the light the medium lets
    through, as noisy as the medium's own: it is filtered with it, not added back raw."""
    light, rest = medium.copy(), emission.copy()
    light[:, pixels] += emission[:, pixels]
    rest[:, pixels] = 0.0
    return light, rest
