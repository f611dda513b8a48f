"""Anti-lag (optional): the history shortened where it disagrees with this frame."""

from __future__ import annotations

import numpy as np

from svgf_cli.filters.antilag import antilag
from svgf_cli.filters.bidirectional import PASS_ANTILAG_SIGMA_SCALE
from svgf_cli.filters.context import FrameContext, StageBase
from svgf_cli.filters.params import SVGFParams, antilag_radius_for

F32 = np.float32


class AntiLag(StageBase):
    """Per signal, the history length lowered where the history differs from this frame by
    more than ``antilag_sigma`` standard errors of the window's noise, and by a share of
    that from ``antilag_sigma_start`` on (``filters.antilag``; with A-SVGF temporal
    gradient samples when the frame has them, Schied et al. 2018), so the blend gives the
    frame more weight there. A bidirectional pass tests at ``PASS_ANTILAG_SIGMA_SCALE`` of
    the sigma (the start stays). Only where there is a history; counted."""

    name = "antilag"
    reads = ("demodulated", "moments", "history_length", "depth")
    writes = ("history_length", "antilag_scratch", "antilag_lambda")
    clock = "reproject"

    def enabled(self, params: SVGFParams) -> bool:
        return params.antilag

    def run(self, ctx: FrameContext) -> bool:
        temporal, p, work = ctx.temporal, ctx.params, ctx.work
        if not ctx.reprojected or temporal is None:
            return False
        scratch = temporal.antilag_scratch
        if scratch is None:
            scratch = work["antilag_scratch"]
        ctx.counts["antilag"] = antilag(
            temporal.current, temporal.history_moments, temporal.history_length,
            temporal.depth, np.array(temporal.luminance_weights, dtype=F32),
            antilag_radius_for(p, ctx.frame.height, ctx.frame.width, ctx.frame.samples_per_pixel),
            antilag_sigma(p, temporal.bidirectional), p.antilag_spatial_samples,
            p.antilag_tolerance, p.moments_alpha, scratch, work["antilag_lambda"],
            temporal.gradients, p.antilag_sigma_start,
        )
        return True


def antilag_sigma(params: SVGFParams, bidirectional: bool) -> float:
    """The significance anti-lag tests at: a bidirectional pass's false alarm costs less
    (the other side refills the history), so it tests at ``PASS_ANTILAG_SIGMA_SCALE``."""
    return params.antilag_sigma * (PASS_ANTILAG_SIGMA_SCALE if bidirectional else 1.0)
