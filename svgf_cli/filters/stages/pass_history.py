"""A bidirectional pass's colour history: its accumulation, lightly filtered where static."""

from __future__ import annotations

import numpy as np

from svgf_cli.filters.bidirectional import STATIC_FILTERED_SHARE, STATIC_MOTION
from svgf_cli.filters.buffers import combined_role
from svgf_cli.filters.context import FrameContext, Spatial, StageBase
from svgf_cli.filters.feedback import blend_history
from svgf_cli.filters.stages.atrous import iterate
from svgf_cli.filters.stages.variance import estimate

F32 = np.float32


class PassHistory(StageBase):
    """The colour history a pass of a bidirectional run keeps: its accumulation as blended
    (with ``spatial_variance_blur_color``, the colour entering the a-trous), and where the
    pixel does not move a share ``STATIC_FILTERED_SHARE`` of the first a-trous iteration's
    output (``filters.feedback.blend_history``; a causal run keeps its feedback iteration's
    output). The combination weighs each side as an average of its effective samples; a
    spatially filtered history is a blurred one, and where the pixels move the blur
    compounds with the resampling in both passes; where they do not, some of it pays
    (``docs/bidirectional.md``). A reverse pass's output frame protects the combination."""

    name = "pass_history"
    reads = ("accumulated", "moments", "history_length")
    writes = ("history_colour",)

    def run(self, ctx: FrameContext) -> None:
        work = ctx.work
        protected = ((combined_role(ctx.params.firefly_clamp),) if ctx.forward is not None
                     else ())
        spatial = Spatial("accumulated", work["moments"], work["history_length"],
                          min(1, ctx.iterations), protected, feeds_back=False)
        estimate(ctx, spatial)
        iterate(ctx, spatial)
        ctx.history_name = spatial.history_name
        if spatial.name == spatial.history_name:
            return  # no a-trous iteration: the accumulation itself
        blend_history(ctx.plane(spatial.history_name), ctx.plane(spatial.name), ctx.motion,
                      F32(STATIC_MOTION), F32(STATIC_FILTERED_SHARE), F32(0.0))
