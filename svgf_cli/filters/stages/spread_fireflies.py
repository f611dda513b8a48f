"""Firefly spreading (optional): fireflies bounded against the history, energy kept."""

from __future__ import annotations

from svgf_cli.filters.context import FrameContext, StageBase
from svgf_cli.filters.fireflies import GLOSSY_RADIUS, RADIUS, spread_fireflies
from svgf_cli.filters.params import SVGFParams


class SpreadFireflies(StageBase):
    """The current samples that are fireflies against the history anti-lag left, bounded
    and their excess shared over their surface (``filters.fireflies``): in the 9x9, a
    glossy signal's in its 3x3, at most the firefly's bound to each pixel
    (``glossy_spread_fireflies``; else left alone). Not on a
    frame without history: a single frame cannot tell a small highlight in a combined
    colour from a firefly. Counted per signal."""

    name = "spread_fireflies"
    reads = ("demodulated", "moments", "mode", "depth")
    writes = ("demodulated", "despike_luminance")
    clock = "reproject"

    def enabled(self, params: SVGFParams) -> bool:
        return params.spread_fireflies > 0.0

    def run(self, ctx: FrameContext) -> bool:
        temporal, signals = ctx.temporal, ctx.frame.signals
        if not ctx.reprojected or temporal is None:
            return False
        glossy = temporal.glossy or (False,) * len(temporal.names)
        glossy_radius = GLOSSY_RADIUS if ctx.params.glossy_spread_fireflies else 0
        spread = spread_fireflies(
            temporal.current, [signal.albedo for signal in signals],
            tuple(signal.guide_albedo for signal in signals), temporal.history_moments,
            temporal.mode, temporal.depth,
            tuple(glossy_radius if g else RADIUS for g in glossy),
            ctx.params.spread_fireflies, temporal.luminance_weights,
            ctx.work["despike_luminance"], capped=tuple(glossy))
        ctx.counts.update({f"fireflies_spread.{name}": count
                           for name, count in zip(temporal.names, spread, strict=True)})
        return True
