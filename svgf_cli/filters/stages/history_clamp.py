"""History clamp (optional): the reprojected history bounded by this frame's neighbourhood."""

from __future__ import annotations

import numpy as np

from svgf_cli.filters.clamp import heavy_tailed, history_clamp
from svgf_cli.filters.context import FrameContext, StageBase
from svgf_cli.filters.params import SVGFParams, history_clamp_radius_for

_NO_ROUGH = np.zeros(0, dtype=np.uint8)


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


def heavy_tail_masks(ctx: FrameContext, glossy: tuple[bool, ...], radius: int
                     ) -> list[np.ndarray | None] | None:
    """Per signal, None or (glossy signals clamped over the 3x3 by their own k, with
    ``glossy_heavy_tail`` on and a window wider than the 3x3 at this image size) where its
    history is heavy-tailed and its object not
    rough (``filters.clamp.heavy_tailed``; ``ctx.rough_objects``): there the glossy history
    takes the wider window. Counted as ``counts["heavy_tail.<signal>"]``."""
    threshold = ctx.params.glossy_heavy_tail
    temporal = ctx.temporal
    # Without their own k, glossy signals take the wider window everywhere (clamp_radii).
    own_k = ctx.params.glossy_history_clamp > 0.0
    if threshold <= 0.0 or radius <= 1 or not own_k or not any(glossy) or temporal is None:
        return None
    masks: list[np.ndarray | None] = []
    for index, is_glossy in enumerate(glossy):
        if not is_glossy:
            masks.append(None)
            continue
        rough = ctx.rough_objects.get(index)
        low, table = (rough.low_id, rough.table) if rough is not None else (0, _NO_ROUGH)
        mask = np.empty(temporal.depth.shape, dtype=np.bool_)
        ctx.counts[f"heavy_tail.{temporal.names[index]}"] = heavy_tailed(
            temporal.history_moments[index], temporal.history_length[index], temporal.depth,
            ctx.frame.mesh_id, low, table, np.float32(threshold), mask)
        masks.append(mask)
    return masks


class HistoryClamp(StageBase):
    """Each signal's reprojected history clamped to this frame's 3x3 (or wider:
    ``clamp_radii``) mean +- k sigma, its moments scaled with it
    (``filters.clamp.history_clamp``; k: ``history_clamp``, for glossy signals
    ``glossy_history_clamp``; k <= 0 leaves a signal alone). Only where there is a
    history. With ``glossy_heavy_tail`` a glossy signal's heavy-tailed pixels take the
    other signals' wider window (:func:`heavy_tail_masks`)."""

    name = "history_clamp"
    reads = ("demodulated", "depth", "frame.mesh_id", "rough_objects")
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
            radius = history_clamp_radius_for(p, ctx.frame.height, ctx.frame.width)
            history_clamp(temporal.history_illumination, temporal.history_moments,
                          temporal.history_length, temporal.current, temporal.depth, ks,
                          temporal.luminance_weights,
                          clamp_radii(p, glossy, ctx.frame.height, ctx.frame.width),
                          heavy_tail_masks(ctx, glossy, radius), radius)
        return True
