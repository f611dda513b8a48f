"""Edge filter (optional): the renderer's pixel filter across outlines, which
centre-sampled frames lack."""

from __future__ import annotations

import numpy as np

from svgf_cli.filters.context import FrameContext, StageBase
from svgf_cli.filters.edge_filter import edge_filter, edge_filter_weight
from svgf_cli.filters.params import SVGFParams

F32 = np.float32


class EdgeFilter(StageBase):
    """Each pair of neighbouring pixels on two surfaces exchanges ``w`` of its whole
    colour, emission included (``filters.edge_filter``; auto: only on frames sampled at
    pixel centres). After the pixel filter, which leaves the emission and what the a-trous
    kept apart as sharp as the samples."""

    name = "edge_filter"
    reads = ("output", "depth", "frame.mesh_id")
    writes = ("output",)
    clock = "pixel_filter"

    def enabled(self, params: SVGFParams) -> bool:
        return params.edge_filter != 0.0

    def run(self, ctx: FrameContext) -> bool:
        output = ctx.output
        assert output is not None
        weight = edge_filter_weight(ctx.params.edge_filter, ctx.frame.centre_sampled)
        if weight <= 0.0:
            return False
        filtered_output = np.empty_like(output)
        edge_filter(output, ctx.frame.mesh_id, ctx.frame.depth, F32(weight), filtered_output)
        ctx.output = filtered_output
        return True
