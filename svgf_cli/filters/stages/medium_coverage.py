"""The medium's signal demodulated by the medium's coverage (``filters.medium.coverage``)."""

from __future__ import annotations

import dataclasses

import numpy as np

from svgf_cli.filters.context import FrameContext, StageBase
from svgf_cli.filters.medium import coverage
from svgf_cli.filters.params import SVGFParams, medium_coverage_radius_for


class MediumCoverage(StageBase):
    """The medium's signal (Cycles' ``VolumeDir + VolumeInd``), filtered as radiance
    otherwise, takes the coverage of the medium pixels (``fill_medium``) as its demodulation
    colour, as a surface's light takes its albedo: inside a fog only some pixels' samples
    scatter, and the light of one scattering is what is smooth, across the fog and up to its
    edge. The medium's edge, which the G-buffer of the surface behind does not have, is then
    a change of colour the filter keeps, and the few bright samples among zeros no longer
    lose to the zeros around them at the luminance stop. Frames without medium pixels skip
    it (docs/algorithm.md#the-mediums-coverage)."""

    name = "medium_coverage"
    reads = ("medium_pixels", "medium_signal", "frame.signals")
    writes = ("frame",)
    clock = "medium"

    def enabled(self, params: SVGFParams) -> bool:
        return params.medium_coverage_radius != 0 and params.medium_fill_radius > 0

    def run(self, ctx: FrameContext) -> bool | None:
        if ctx.medium_pixels is None or ctx.medium_signal is None:
            return False
        cover = coverage(ctx.medium_pixels,
                         medium_coverage_radius_for(ctx.params, *ctx.medium_pixels.shape))
        signals = list(ctx.frame.signals)
        signals[ctx.medium_signal] = dataclasses.replace(
            signals[ctx.medium_signal], albedo=np.ascontiguousarray(np.broadcast_to(
                cover, (3, *cover.shape))))
        ctx.frame = dataclasses.replace(ctx.frame, signals=signals)
        return None
