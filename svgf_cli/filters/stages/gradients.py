"""Geometry gradients: unit normals and the reprojection's depth and normal thresholds."""

from __future__ import annotations

from svgf_cli.filters.context import FrameContext, StageBase
from svgf_cli.filters.gradients import depth_gradients, normal_gradient, unit_normals


class Gradients(StageBase):
    """Unit normals, the depth's screen-space derivatives (the a-trous depth weight,
    Schied et al. 2017 eq. 3) and the per-pixel depth and normal thresholds of the
    reprojection tests. The thresholds live in the variance planes until the variance is
    estimated (``filters.buffers.SHARING``; a plane of their own for the second with one
    signal)."""

    name = "gradients"
    reads = ("depth", "normal_in")
    writes = ("normal", "ddx", "ddy", "depth_slope", "normal_width")
    clock = "gradients"

    def run(self, ctx: FrameContext) -> None:
        work = ctx.work
        unit_normals(ctx.normal_in, ctx.depth, work["normal"])
        ctx.normal = work["normal"]
        ctx.depth_slope = work["variance"][0]
        ctx.normal_width = (work["variance"][1] if work.num_signals > 1
                            else work["normal_width"])
        depth_gradients(ctx.depth, work["ddx"], work["ddy"], ctx.depth_slope)
        normal_gradient(ctx.normal, ctx.depth, ctx.normal_width)
