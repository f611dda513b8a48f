"""Pixel filter (optional): the renderer's pixel filter that centre-sampled frames lack."""

from __future__ import annotations

import numpy as np

from svgf_cli.filters.context import FrameContext, StageBase
from svgf_cli.filters.params import SVGFParams
from svgf_cli.filters.pixel_filter import pixel_filter, pixel_filter_weight

F32 = np.float32


class PixelFilter(StageBase):
    """A [w, 1-2w, w] kernel per axis over the output without its emission
    (``filters.pixel_filter``; auto: only on frames sampled at pixel centres). After TAA,
    whose history must stay the unfiltered output (the kernel would compound)."""

    name = "pixel_filter"
    reads = ("output", "frame.emission")
    writes = ("output",)
    clock = "pixel_filter"

    def enabled(self, params: SVGFParams) -> bool:
        return params.pixel_filter != 0.0

    def run(self, ctx: FrameContext) -> bool:
        output = ctx.output
        assert output is not None
        weight = pixel_filter_weight(ctx.params.pixel_filter, ctx.frame.centre_sampled)
        if weight <= 0.0:
            return False
        emission = ctx.frame.emission
        if emission is None:
            emission = np.zeros_like(output)
        filtered_output = np.empty_like(output)
        pixel_filter(output, emission, F32(weight), filtered_output)
        ctx.output = filtered_output
        return True
