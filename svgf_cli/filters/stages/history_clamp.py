"""History clamp (optional): the reprojected history bounded by this frame's neighbourhood."""

from __future__ import annotations

from svgf_cli.filters.clamp import history_clamp
from svgf_cli.filters.context import FrameContext, StageBase
from svgf_cli.filters.params import SVGFParams, history_clamp_radius_for


def clamp_ks(params: SVGFParams, glossy: tuple[bool, ...]) -> list[float]:
    """Per signal, its history clamp's k (``glossy_history_clamp`` for glossy signals)."""
    glossy_k = params.glossy_history_clamp or params.history_clamp
    return [glossy_k if g else params.history_clamp for g in glossy]


def clamp_radii(params: SVGFParams, glossy: tuple[bool, ...], height: int, width: int
                ) -> list[int]:
    """Per signal, its history clamp's window radius at this image size
    (``history_clamp_radius_for``); a glossy signal with its own k (``glossy_history_clamp``)
    keeps the 3x3: a reflection's neighbourhood is its bound."""
    radius = history_clamp_radius_for(params, height, width)
    own = params.glossy_history_clamp > 0.0
    return [1 if g and own else radius for g in glossy]


class HistoryClamp(StageBase):
    """Each signal's reprojected history clamped to this frame's 3x3 (or wider:
    ``clamp_radii``) mean +- k sigma, its moments scaled with it
    (``filters.clamp.history_clamp``; k: ``history_clamp``, for glossy signals
    ``glossy_history_clamp``; k <= 0 leaves a signal alone). Only where there is a
    history."""

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
        glossy = temporal.glossy or (False,) * len(temporal.names)
        ks = clamp_ks(p, glossy)
        if max(ks) > 0.0:  # one pass for the 3x3 signals, one per wider signal
            history_clamp(temporal.history_illumination, temporal.history_moments,
                          temporal.history_length, temporal.current, temporal.depth, ks,
                          temporal.luminance_weights,
                          clamp_radii(p, glossy, ctx.frame.height, ctx.frame.width))
        return True
