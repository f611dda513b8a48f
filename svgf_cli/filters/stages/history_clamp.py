"""History clamp (optional): the reprojected history bounded by this frame's neighbourhood."""

from __future__ import annotations

from svgf_cli.filters.clamp import history_clamp
from svgf_cli.filters.context import FrameContext, StageBase
from svgf_cli.filters.params import SVGFParams


def clamp_ks(params: SVGFParams, glossy: tuple[bool, ...]) -> list[float]:
    """Per signal, its history clamp's k (``glossy_history_clamp`` for glossy signals)."""
    glossy_k = params.glossy_history_clamp or params.history_clamp
    return [glossy_k if g else params.history_clamp for g in glossy]


class HistoryClamp(StageBase):
    """Each signal's reprojected history clamped to this frame's 3x3 mean +- k sigma, its
    moments scaled with it (``filters.clamp.history_clamp``; k: ``history_clamp``, for
    glossy signals ``glossy_history_clamp``; k <= 0 leaves a signal alone). Only where
    there is a history."""

    name = "history_clamp"
    reads = ("demodulated", "depth")
    writes = ("accumulated", "moments")
    clock = "reproject"

    def enabled(self, params: SVGFParams) -> bool:
        return params.history_clamp > 0.0 or params.glossy_history_clamp > 0.0

    def run(self, ctx: FrameContext) -> bool:
        temporal, p = ctx.temporal, ctx.params
        if not ctx.reprojected or temporal is None:
            return False
        ks = clamp_ks(p, temporal.glossy or (False,) * len(temporal.names))
        if max(ks) > 0.0:  # one pass for all signals
            history_clamp(temporal.history_illumination, temporal.history_moments,
                          temporal.history_length, temporal.current, temporal.depth, ks,
                          temporal.luminance_weights)
        return True
