"""Temporal accumulation: the blend of this frame into its reprojected history."""

from __future__ import annotations

import numpy as np

from svgf_cli.filters.context import FrameContext, StageBase
from svgf_cli.filters.reproject import accumulate_in_place

F32 = np.float32


class Accumulate(StageBase):
    """The exponential moving average of colour and luminance moments (Schied et al. 2017,
    sec. 4.1 and eq. 2-3), ``alpha = max(alpha, 1/h)`` per signal with
    ``h = min(cap, h_prev + 1)``, in place in the reprojected history."""

    name = "accumulate"
    reads = ("demodulated", "depth")
    writes = ("accumulated", "moments", "history_length")
    clock = "reproject"

    def run(self, ctx: FrameContext) -> None:
        p, work = ctx.params, ctx.work
        accumulate_in_place(
            work[ctx.illumination_name], work["accumulated"], work["moments"],
            work["history_length"], ctx.depth, F32(p.alpha), F32(p.moments_alpha),
            F32(p.history_cap), ctx.weights,
        )
