"""Reprojection of every signal's history into this frame."""

from __future__ import annotations

import numpy as np

from svgf_cli.filters.buffers import lend_stale_history
from svgf_cli.filters.context import FrameContext, StageBase, TemporalState
from svgf_cli.filters.reproject import reproject
from svgf_cli.frame import Frame

F32 = np.float32


class Reproject(StageBase):
    """Last frame's colour, moments and history length resampled at this frame's pixels
    through the motion vectors, taps rejected by the depth, normal, mesh-id and mode tests
    (Schied et al. 2017, sec. 4.1; ``filters.reproject``), into the buffers the blend
    accumulates in place. Without history (the first frame, ``temporal`` off) they are
    cleared: blend factor 1 everywhere. Then last frame's history is dead until it is
    replaced: it lends its planes as scratch (``filters.buffers.lend_stale_history``)."""

    name = "reproject"
    reads = ("history", "depth", "normal", "motion", "mode", "depth_slope", "normal_width")
    writes = ("accumulated", "moments", "history_length")
    clock = "reproject"

    def run(self, ctx: FrameContext) -> None:
        p, work, frame = ctx.params, ctx.work, ctx.frame
        accumulated = work["accumulated"]
        moments = work["moments"]
        history_length = work["history_length"]
        illumination = work[ctx.illumination_name]
        history = ctx.resident.history
        ctx.reprojected = p.temporal and history is not None
        if ctx.reprojected:
            assert history is not None
            reproject(
                ctx.motion, ctx.depth, ctx.normal, frame.mesh_id, ctx.mode, ctx.depth_slope,
                ctx.normal_width, history["prev_depth"], history["prev_normal"],
                history["prev_mesh_id"], history["history_mode"],
                history["history_illumination"], history["history_moments"],
                history["history_length"], F32(p.depth_tolerance), F32(p.depth_slack),
                F32(p.normal_tolerance), accumulated, moments, history_length,
                catmull_rom=p.history_catmull_rom,
            )
            self.lend(ctx)
            ctx.temporal = TemporalState(
                ctx.names, illumination, ctx.mode, accumulated, moments, history_length,
                ctx.depth, ctx.weights,
                gradient_samples(frame) if p.antilag_gradients else None,
                tuple(signal.glossy for signal in frame.signals),
                antilag_scratch=ctx.plane("antilag_scratch"), bidirectional=ctx.bidirectional,
            )
        else:
            # Blend factor 1 everywhere; clear the stale contents (weight 0, but 0 * inf).
            history_length.fill(0.0)
            accumulated.fill(0.0)
            moments.fill(0.0)
            self.lend(ctx)
            ctx.temporal = TemporalState(ctx.names, illumination, ctx.mode, accumulated,
                                         moments, history_length, ctx.depth, ctx.weights,
                                         bidirectional=ctx.bidirectional)

    @staticmethod
    def lend(ctx: FrameContext) -> None:
        work = ctx.work
        stale = ctx.resident.history_buffers(work)
        ctx.borrowed = lend_stale_history(stale, work.num_signals, work.height, work.width)


def gradient_samples(
    frame: Frame,
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray] | None] | None:
    """Per signal, its temporal gradient samples as (mask, previous, current), or None;
    a sample with a non-finite value is no sample. None when no signal has any."""
    if all(signal.gradient is None for signal in frame.signals):
        return None
    samples: list[tuple[np.ndarray, np.ndarray, np.ndarray] | None] = []
    for signal in frame.signals:
        gradient = signal.gradient
        if gradient is None:
            samples.append(None)
            continue
        finite = np.isfinite(gradient.previous) & np.isfinite(gradient.current)
        mask = np.where(finite & (gradient.mask > 0), F32(1.0), F32(0.0))
        samples.append((mask, np.where(finite, gradient.previous, F32(0.0)),
                        np.where(finite, gradient.current, F32(0.0))))
    return samples
