"""History gain (optional, causal runs): the history rescaled where the light changed by one
factor, before anti-lag."""

from __future__ import annotations

import numpy as np

from svgf_cli.filters.context import FrameContext, StageBase
from svgf_cli.filters.history_gain import history_gain
from svgf_cli.filters.params import SVGFParams, antilag_radius_for

F32 = np.float32


class HistoryGain(StageBase):
    """Per signal, the reprojected history times the factor by which a wide neighbourhood's
    light changed, where that change exceeds ``antilag_sigma`` standard errors and narrower
    windows down to the anti-lag's own confirm it within ``antilag_sigma_start``
    (``filters.history_gain``): a light switched or dimmed keeps its history's length
    instead of restarting. Causal runs only. Only where there is a history; counted."""

    name = "history_gain"
    reads = ("demodulated", "moments", "history_length", "depth")
    writes = ("accumulated", "moments", "antilag_scratch")
    clock = "reproject"

    def enabled(self, params: SVGFParams) -> bool:
        return params.antilag and params.antilag_gain

    def run(self, ctx: FrameContext) -> bool:
        temporal, p = ctx.temporal, ctx.params
        if not ctx.reprojected or temporal is None:
            return False
        scratch = temporal.antilag_scratch
        if scratch is None:
            scratch = ctx.work["antilag_scratch"]
        ctx.counts["history_gain"] = history_gain(
            temporal.current, temporal.history_illumination, temporal.history_moments,
            temporal.history_length, temporal.depth,
            np.array(temporal.luminance_weights, dtype=F32),
            antilag_radius_for(p, ctx.frame.height, ctx.frame.width,
                               ctx.frame.samples_per_pixel), p.antilag_sigma,
            p.antilag_sigma_start, p.antilag_tolerance, p.moments_alpha, scratch,
        )
        return True
