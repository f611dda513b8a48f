"""The two passes of a bidirectional run over arrays (the file driver is ``svgf_cli.run``).

A forward pass (:class:`ForwardPass`, frames in order) hands back, per frame, the history
it resampled; a reverse pass (:class:`ReversePass`, frames in reverse order) combines it with
its own history at the same frame (``filters.bidirectional``) and filters the combination.
Both are pipelines of ``filters.pipeline`` (``forward``, ``reverse``). The reverse pass
reprojects frame ``t + 1`` into ``t`` with the motion to the next frame: the frame's own
``motion_next`` when the renderer wrote it, else the inverse of frame ``t + 1``'s backward
motion (``filters.invert_motion``). A-SVGF gradient samples describe the change from the
previous frame, so the reverse pass does not use them (its anti-lag uses the statistical
test alone).

:func:`denoise_bidirectional` runs both passes over frames held in memory (tests,
evaluation of short sequences); a file run spills the forward histories instead.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from svgf_cli.filters.bidirectional import SideHistory, unpack_history
from svgf_cli.filters.buffers import combined_role
from svgf_cli.filters.denoiser import used_gbuffer
from svgf_cli.filters.engine import PipelineFilter
from svgf_cli.filters.invert_motion import NO_MOTION, invert_motion
from svgf_cli.filters.params import SVGFParams
from svgf_cli.filters.stages.capture import Keep
from svgf_cli.filters.stages.temporal_albedo import colour_count
from svgf_cli.frame import DenoisedFrame, Frame

F32 = np.float32

PackedHistory = tuple[dict[str, np.ndarray], dict[str, float]]

__all__ = ["ForwardPass", "Keep", "PackedHistory", "ReversePass", "denoise_bidirectional"]


class ForwardPass(PipelineFilter):
    """The forward pass of a bidirectional run: the ``forward`` pipeline fed the frames in
    order (the causal filter's temporal stages, its unfiltered accumulation stored as the
    history: ``filters.stages.pass_history``), handing back at each frame the history it
    resampled there (after anti-lag, before the blend), as :class:`Keep` asks."""

    kind = "forward"

    def __init__(self, params: SVGFParams, debug_layers: bool = False) -> None:
        del debug_layers  # the forward pass composes no output
        super().__init__(params, debug_layers=False)

    def process(self, frame: Frame, keep: Keep = Keep.COPY) -> Any:
        """The next frame: a :class:`SideHistory` (``Keep.COPY``), a
        :data:`PackedHistory` (``Keep.PACKED``) or None (``Keep.NOTHING``)."""
        return self._run(frame, bidirectional=True, keep=keep).kept


class ReversePass(PipelineFilter):
    """The reverse pass: the ``reverse`` pipeline fed the frames last to first, each frame's
    motion replaced by its motion to the next frame. Call :meth:`process` with the frames in
    reverse order and, for each frame to output, the forward pass's history there."""

    kind = "reverse"

    # Also hand back each output frame's G-buffer as the stages used it, its motion the one
    # to the next frame (``filters.composable.LayeredDenoiser``, as the Denoiser's).
    gbuffer_output = False

    def __init__(self, params: SVGFParams, debug_layers: bool = False) -> None:
        super().__init__(params, debug_layers=debug_layers)
        self.derived_holes = 0  # holes of the last derived motion (information)
        # With gbuffer_output: the G-buffer as used and the medium pixels of the last frame
        # processed without output (a warm-up frame), for a filter of the same frame's
        # other layers to warm up on (``filters.composable.LayeredReversePass``).
        self.warmup_gbuffer: tuple[Frame, np.ndarray | None] | None = None
        # The motion to the next frame derived for the frame processed next (from the
        # frame just processed, so none of its planes is kept): reused frame after frame
        # (the pipeline keeps no reference to a motion). The inversion's scratch is
        # allocated per frame, so it is not held while the frame is filtered.
        self._derived: np.ndarray | None = None
        self._derived_ready = False

    def reset(self) -> None:
        """Drop the history (a gap in the sequence): the next frame starts cold."""
        super().reset()
        self._derived_ready = False

    def forward_buffers(self, num_signals: int, height: int, width: int) -> SideHistory:
        """Where to put the forward history of the next output frame: a forward history
        written into them (a file run unpacks the spilled state there) is combined in place;
        any other is copied in first. They do not outlive the next output frame
        (``filters.stages.release``)."""
        work = self.resident.workspace(height, width, num_signals)
        albedo = albedo_length = None
        if self.params.temporal_albedo:
            # One per distinct colour, as this pass has them (all signals' before its first
            # frame); a forward history of another count is copied into fresh buffers.
            albedo, albedo_length = self.resident.forward_albedo_buffers(
                colour_count(self.resident.albedo_slots) or num_signals, height, width)
        return SideHistory(work[combined_role(self.params.firefly_clamp)],
                           work["combined_moments"], work["combined_length"], albedo,
                           albedo_length)

    def motion_to_next(self, frame: Frame) -> np.ndarray:
        """``frame.motion_next``, else the inverse of the later frame's backward motion
        (derived when that frame was processed, if it had no ``motion_next`` either: a
        renderer writes it on every frame or on none), else (the last frame of the
        sequence) no motion anywhere."""
        if frame.motion_next is not None:
            return frame.motion_next
        motion = self._motion_buffer(frame.height, frame.width)
        if not self._derived_ready:
            motion.fill(NO_MOTION)
            self.derived_holes = frame.height * frame.width
        return motion

    def _motion_buffer(self, height: int, width: int) -> np.ndarray:
        shape = (2, height, width)
        if self._derived is None or self._derived.shape != shape:
            self._derived = np.empty(shape, dtype=F32)
            self._derived_ready = False
        return self._derived

    def process(self, frame: Frame, forward: SideHistory | None) -> DenoisedFrame | None:
        """The next frame (going backwards in time); the output when ``forward`` is given
        (best given in :meth:`forward_buffers`), None for a warm-up frame."""
        reverse = dataclasses.replace(
            frame,
            motion=self.motion_to_next(frame),
            motion_next=None,
            # Gradient samples describe the change from the previous frame: not this pass's.
            signals=[dataclasses.replace(s, gradient=None) for s in frame.signals],
        )
        into = None if forward is None else self._receive(reverse, forward)
        ctx = self._run(reverse, bidirectional=True, forward=forward, into=into)
        result = None
        self.warmup_gbuffer = None
        if forward is None and self.gbuffer_output:
            self.warmup_gbuffer = (used_gbuffer(ctx), ctx.medium_pixels)
        if forward is not None:
            assert ctx.output is not None
            result = DenoisedFrame(color=ctx.output, layers=ctx.layers, counts=ctx.counts,
                                   emission=ctx.frame.emission, medium=ctx.medium_pixels,
                                   emission_averaged=ctx.emission_averaged,
                                   outline_spill=ctx.outline_spill,
                                   gbuffer=used_gbuffer(ctx) if self.gbuffer_output else None)
        # The frame before this one (processed next) gets its motion to this one now.
        self._derived_ready = False
        if frame.motion_next is None:
            motion = self._motion_buffer(frame.height, frame.width)
            self.derived_holes = invert_motion(
                _finite(frame.motion, NO_MOTION), _finite(frame.depth, F32(0.0)), motion)
            self._derived_ready = True
        return result

    def _receive(self, frame: Frame, forward: SideHistory) -> SideHistory:
        """The buffers the combination is written in, holding ``forward`` (copied in
        unless it is already there)."""
        into = self.forward_buffers(len(frame.names), frame.height, frame.width)
        pairs = [(forward.colour, into.colour), (forward.moments, into.moments),
                 (forward.length, into.length)]
        if forward.albedo is not None and forward.albedo_length is not None:
            into.albedo, into.albedo_length = self.resident.forward_albedo_buffers(
                *forward.albedo_length.shape)
            pairs += [(forward.albedo, into.albedo),
                      (forward.albedo_length, into.albedo_length)]
        for given, buffer in pairs:
            if given is not buffer:
                if given.shape != buffer.shape:
                    raise ValueError(f"forward history of shape {given.shape}, expected "
                                     f"{buffer.shape}")
                np.copyto(buffer, given)
        return into


def denoise_bidirectional(
    frames: Sequence[Frame], params: SVGFParams, *, debug_layers: bool = False,
    half: bool = False,
) -> list[DenoisedFrame]:
    """Both passes over ``frames`` (in order) held in memory; the outputs in order.

    ``half`` stores the forward histories as a file run spills them (half floats), to
    measure what that costs."""
    forward = ForwardPass(params)
    kept: list[SideHistory] = []
    for frame in frames:
        if half:
            kept.append(unpack_history(frame.names, *forward.process(frame, Keep.PACKED)))
        else:
            kept.append(forward.process(frame, Keep.COPY))
    reverse = ReversePass(params, debug_layers=debug_layers)
    outputs: list[DenoisedFrame] = []
    for frame, history in zip(reversed(frames), reversed(kept), strict=True):
        result = reverse.process(frame, history)
        assert result is not None
        outputs.append(result)
    return outputs[::-1]


def _finite(plane: np.ndarray, replacement: np.float32) -> np.ndarray:
    """``plane`` itself when every value is finite, else a copy with ``replacement`` there
    (the inversion runs with fast-math flags that assume finite values)."""
    finite = np.isfinite(plane)
    return plane if finite.all() else np.where(finite, plane, replacement).astype(F32)
