"""Turning objects (optional): their light's history fetched by the object's translation."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from svgf_cli.filters.antilag import CELL, antilag, cell_shape, scratch_shape
from svgf_cli.filters.clamp import history_clamp
from svgf_cli.filters.context import FrameContext, StageBase, TemporalState
from svgf_cli.filters.object_motion import turning_pixels
from svgf_cli.filters.params import SVGFParams, antilag_radius_for
from svgf_cli.filters.reproject import reproject
from svgf_cli.filters.stages.antilag import antilag_sigma
from svgf_cli.filters.stages.history_clamp import clamp_ks, clamp_radii

F32 = np.float32
# An adopted history counts as at most this many frames. An object's light is only in part
# a function of how it faces the light: where it now is, what stands near it and what it
# sees change as it moves, and its resampled history carries the drift. Measured on the
# rolling balls of testdata/cycles/roll and testdata/lag/shadow (relMSE, video JOD; caps 1,
# 2, 3, 5 and none): 1 is best on both (docs/algorithm.md#turning-objects).
TURNED_FRAMES = F32(1.0)


@dataclass
class TurnedHistory:
    """Every signal's history resampled at a turning object's translation, over the box
    ``rows`` x ``columns`` (the turning pixels' bounding box and anti-lag's reach around
    it): colour (S, 3, h, w), moments (S, 2, h, w) and the length the history clamp and
    anti-lag leave it (S, h, w); ``turning`` (S, h, w) marks per signal the turning pixels
    whose history this one is to replace."""

    rows: slice
    columns: slice
    turning: np.ndarray
    colour: np.ndarray
    moments: np.ndarray
    length: np.ndarray


class ObjectHistory(StageBase):
    """On an object that turns about its own axis (a rolling ball), each signal's history
    resampled a second time, at the object's translation instead of the material point's
    motion (``filters.object_motion``), then clamped and tested as the ``history_clamp``
    and ``antilag`` stages test the material point's; :class:`AdoptObjectHistory` keeps it
    where it is trusted with the longer history. Runs while last frame's history is whole
    (before anti-lag borrows its memory)."""

    name = "object_history"
    reads = ("history", "depth", "normal", "motion", "mode", "depth_slope", "normal_width",
             "demodulated")
    writes = ("turned_history",)
    clock = "reproject"

    def enabled(self, params: SVGFParams) -> bool:
        return params.object_history and params.antilag

    def run(self, ctx: FrameContext) -> bool:
        ctx.turned = None
        temporal, history = ctx.temporal, ctx.resident.history
        if not ctx.reprojected or temporal is None or history is None:
            return False
        translation = turning_pixels(ctx.motion, ctx.normal, ctx.frame.mesh_id,
                                     history["prev_normal"], history["prev_mesh_id"],
                                     ctx.depth > 0)
        turning = np.isfinite(translation[0])
        if not turning.any():
            return False
        radius = antilag_radius_for(ctx.params, ctx.frame.height, ctx.frame.width,
                                    ctx.frame.samples_per_pixel)
        rows, columns = _box(turning, CELL * (radius + 1) + 2)
        ctx.turned = _resample(ctx, temporal, history, translation, turning, rows, columns)
        return True


class AdoptObjectHistory(StageBase):
    """Where :class:`ObjectHistory` chose a turning pixel's history resampled at the
    translation, it replaces the material point's, with the length the history clamp and
    anti-lag left it, at most ``TURNED_FRAMES`` (after anti-lag, so that anti-lag's windows
    around the object judge the same histories as without these stages)."""

    name = "adopt_object_history"
    reads = ("turned_history", "history_length")
    writes = ("accumulated", "moments", "history_length")
    clock = "reproject"

    def enabled(self, params: SVGFParams) -> bool:
        return params.object_history and params.antilag

    def run(self, ctx: FrameContext) -> bool:
        turned, temporal = ctx.turned, ctx.temporal
        ctx.turned = None
        if turned is None or temporal is None:
            return False
        rows, columns = turned.rows, turned.columns
        length = temporal.history_length[:, rows, columns]
        replace = turned.turning
        for s in range(length.shape[0]):
            where = replace[s]
            for target, source in ((temporal.history_illumination, turned.colour),
                                   (temporal.history_moments, turned.moments)):
                for c in range(source.shape[1]):
                    target[s, c, rows, columns][where] = source[s, c][where]
        length[replace] = np.minimum(turned.length[replace], TURNED_FRAMES)
        ctx.counts["object_history"] = (ctx.counts.get("object_history", 0)
                                        + int(np.count_nonzero(replace)))
        return True


def _box(mask: np.ndarray, margin: int) -> tuple[slice, slice]:
    """The bounding box of ``mask`` grown by ``margin``, its origin on anti-lag's cell grid."""
    height, width = mask.shape
    rows = np.flatnonzero(mask.any(axis=1))
    columns = np.flatnonzero(mask.any(axis=0))
    y0 = max(int(rows[0]) - margin, 0) // CELL * CELL
    x0 = max(int(columns[0]) - margin, 0) // CELL * CELL
    return (slice(y0, min(int(rows[-1]) + margin + 1, height)),
            slice(x0, min(int(columns[-1]) + margin + 1, width)))


def _resample(ctx: FrameContext, temporal: TemporalState, history: dict[str, np.ndarray],
              translation: np.ndarray, turning: np.ndarray, rows: slice,
              columns: slice) -> TurnedHistory:
    """The history over the box, resampled at ``translation`` on the turning pixels and
    through the motion vectors around them (anti-lag's windows there see the same history
    as the material point's), clamped and tested by anti-lag; ``turning`` kept only where
    anti-lag, before any clamp, trusts it with a longer history than the material point's.

    Before the clamp: the clamp pulls a history to within ``history_clamp`` standard
    deviations of this frame's 3x3 neighbourhood and its moments with it, after which
    anti-lag no longer sees a material point's light that turned by less than that."""
    p, frame = ctx.params, ctx.frame
    crop = np.ascontiguousarray
    box = (rows, columns)
    motion = crop(np.where(turning[box], translation[:, rows, columns],
                           ctx.motion[:, rows, columns]))
    depth = crop(ctx.depth[box])
    current = crop(temporal.current[:, :, rows, columns])
    num_signals = current.shape[0]
    height, width = depth.shape
    colour = np.empty_like(current)
    moments = np.empty((num_signals, 2, height, width), F32)
    length = np.empty((num_signals, height, width), F32)
    reproject(motion, depth, crop(ctx.normal[:, rows, columns]), crop(frame.mesh_id[box]),
              crop(ctx.mode[box]), crop(ctx.depth_slope[box]), crop(ctx.normal_width[box]),
              history["prev_depth"], history["prev_normal"], history["prev_mesh_id"],
              history["history_mode"], history["history_illumination"],
              history["history_moments"], history["history_length"], F32(p.depth_tolerance),
              F32(p.depth_slack), F32(p.normal_tolerance), colour, moments, length,
              catmull_rom=p.history_catmull_rom, origin=(rows.start, columns.start))
    tested = _tested(ctx, temporal, current, depth)
    # Temporal gradient samples measure the change of the light along the motion vectors:
    # evidence about the material point's history only.
    gradients = None if temporal.gradients is None else [
        None if samples is None else tuple(crop(plane[box]) for plane in samples)
        for samples in temporal.gradients]
    material = tested(crop(temporal.history_moments[:, :, rows, columns]),
                      crop(temporal.history_length[:, rows, columns]), gradients)
    turned = tested(moments, length.copy())
    glossy = temporal.glossy or (False,) * num_signals
    ks = clamp_ks(p, glossy)
    if max(ks) > 0.0:  # the window of the whole frame's clamp (its size, not the box's)
        history_clamp(colour, moments, length, current, depth, ks, temporal.luminance_weights,
                      clamp_radii(p, glossy, frame.height, frame.width))
    tested(moments, length)
    return TurnedHistory(rows, columns, turning[box] & (turned > material), colour, moments,
                         length)


def _tested(ctx: FrameContext, temporal: TemporalState, current: np.ndarray,
            depth: np.ndarray) -> Callable[..., np.ndarray]:
    """A function of a history's moments and length (over the box), and optionally its
    temporal gradient samples, that returns the length anti-lag leaves it, shortened in
    place."""
    p = ctx.params
    num_signals, _, height, width = current.shape
    weights = np.array(temporal.luminance_weights, dtype=F32)
    scratch = np.empty(scratch_shape(num_signals, height, width), F32)
    weight = np.empty((num_signals, *cell_shape(height, width)), F32)
    # The frame's, not the box's.
    radius = antilag_radius_for(p, ctx.frame.height, ctx.frame.width, ctx.frame.samples_per_pixel)

    def tested(moments: np.ndarray, length: np.ndarray,
               gradients: list[tuple[np.ndarray, ...] | None] | None = None) -> np.ndarray:
        antilag(current, moments, length, depth, weights, radius,
                antilag_sigma(p, temporal.bidirectional), p.antilag_spatial_samples,
                p.antilag_tolerance, p.moments_alpha, scratch, weight, gradients,
                p.antilag_sigma_start)
        return length

    return tested
