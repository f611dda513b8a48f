"""Lone despike (optional): pixels whose mode no neighbour shares, against the output."""

from __future__ import annotations

import numpy as np

from svgf_cli.filters.context import FrameContext, StageBase
from svgf_cli.filters.despike import despike_lone
from svgf_cli.filters.params import SVGFParams

F32 = np.float32


class DespikeLone(StageBase):
    """The composed output's pixels whose mode no neighbour shares, despiked against their
    output neighbours (``filters.despike.despike_lone``), counted."""

    name = "despike_lone"
    reads = ("output", "mode", "depth")
    writes = ("output", "despike_luminance")
    clock = "despike"

    def enabled(self, params: SVGFParams) -> bool:
        return params.despike > 0.0

    def run(self, ctx: FrameContext) -> None:
        output = ctx.output
        assert output is not None
        emission = ctx.frame.emission
        clamped = np.zeros(ctx.depth.shape[0], dtype=np.int64)
        despike_lone(output, emission if emission is not None else output,
                     emission is not None, ctx.mode, ctx.depth, len(ctx.names),
                     F32(ctx.params.despike), ctx.weights, ctx.work["despike_luminance"],
                     clamped)
        ctx.counts["despiked_lone"] = int(clamped.sum())
