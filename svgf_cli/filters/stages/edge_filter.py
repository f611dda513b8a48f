"""Edge filter (optional): the renderer's pixel filter across outlines, which
centre-sampled frames lack, and a stronger spill where the outlines are noise."""

from __future__ import annotations

import numpy as np

from svgf_cli.filters.context import FrameContext, StageBase
from svgf_cli.filters.edge_filter import (
    NOISY_PASSES,
    OutlineSpill,
    edge_filter,
    edge_filter_weight,
    lone_samples,
    noisy_outline_weights,
    outline_share,
)
from svgf_cli.filters.params import SVGFParams

F32 = np.float32


class EdgeFilter(StageBase):
    """Each pair of neighbouring pixels on two surfaces exchanges ``w`` of its whole
    colour, emission included (``filters.edge_filter``; auto: only on frames sampled at
    pixel centres), plus, where the outlines are so dense that the G-buffer is noise (a
    defocused region), up to ``noisy_outline_weight`` more over ``NOISY_PASSES`` passes.
    After the pixel filter, which leaves the emission and what the a-trous kept apart as
    sharp as the samples."""

    name = "edge_filter"
    reads = ("output", "depth", "frame.mesh_id")
    writes = ("output",)
    clock = "pixel_filter"

    def enabled(self, params: SVGFParams) -> bool:
        return params.edge_filter != 0.0 or params.noisy_outline_weight > 0.0

    def run(self, ctx: FrameContext) -> bool:
        output = ctx.output
        assert output is not None
        mesh_id, depth = ctx.frame.mesh_id, ctx.frame.depth
        base = edge_filter_weight(ctx.params.edge_filter, ctx.frame.centre_sampled)
        noisy = None
        if ctx.params.noisy_outline_weight > 0.0:
            share = outline_share(mesh_id, depth)
            # Lone samples only where every sample went through its pixel's centre: in a
            # jittered frame one is as often an outline's other surface, which the history
            # averages (testdata/seq_jit: video JOD 8.636 -> 8.621 with them).
            lone = (lone_samples(mesh_id, depth, ctx.medium_pixels)
                    if ctx.frame.centre_sampled else None)
            noisy = noisy_outline_weights(share, ctx.params.noisy_outline_weight, lone)
            if not noisy.any():
                noisy = None
        if base <= 0.0 and noisy is None:
            return False
        if base > 0.0:
            filtered_output = np.empty_like(output)
            edge_filter(output, mesh_id, depth, np.full(depth.shape, base, dtype=F32),
                        filtered_output)
            output = filtered_output
        if noisy is not None:
            ctx.outline_spill = OutlineSpill.of(mesh_id, depth, noisy, NOISY_PASSES)
            output = ctx.outline_spill.apply(output)
        ctx.output = output
        return True
