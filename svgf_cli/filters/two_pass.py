"""The two passes of a bidirectional run over arrays (the file driver is ``svgf_cli.bidir``).

A forward pass (:meth:`Denoiser.forward_step`, frames in order) keeps, per frame, the
history it resampled; a reverse pass (:class:`ReversePass`, frames in reverse order) combines
it with its own history at the same frame (``filters.bidirectional``) and filters the
combination. The reverse pass reprojects frame ``t + 1`` into ``t`` with the motion to the
next frame: the frame's own ``motion_next`` when the renderer wrote it, else the inverse of
frame ``t + 1``'s backward motion (``filters.invert_motion``). A-SVGF gradient samples
describe the change from the previous frame, so the reverse pass does not use them (its
anti-lag uses the statistical test alone).

:func:`denoise_bidirectional` runs both passes over frames held in memory (tests,
evaluation of short sequences); a file run spills the forward histories instead.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from svgf_cli.filters.bidirectional import SideHistory, pack_history, unpack_history
from svgf_cli.filters.denoiser import Denoiser
from svgf_cli.filters.invert_motion import NO_MOTION, invert_motion
from svgf_cli.filters.params import SVGFParams
from svgf_cli.frame import DenoisedFrame, Frame

F32 = np.float32


class ReversePass:
    """The reverse pass: a Denoiser fed the frames last to first, each frame's motion
    replaced by its motion to the next frame. Call :meth:`process` with the frames in
    reverse order and, for each frame to output, the forward pass's history there."""

    def __init__(self, params: SVGFParams, debug_layers: bool = False) -> None:
        self.denoiser = Denoiser(params, debug_layers=debug_layers)
        self.derived_holes = 0  # holes of the last derived motion (information)
        # The motion to the next frame derived for the frame processed next (from the
        # frame just processed, so none of its planes is kept): reused frame after frame
        # (the Denoiser keeps no reference to a motion). The inversion's scratch is
        # allocated per frame, so it is not held while the frame is filtered.
        self._derived: np.ndarray | None = None
        self._derived_ready = False

    def reset(self) -> None:
        """Drop the history (a gap in the sequence): the next frame starts cold."""
        self.denoiser.reset()
        self._derived_ready = False

    def forward_buffers(self, num_signals: int, height: int, width: int) -> SideHistory:
        """Where to put the forward history of the next output frame
        (:meth:`Denoiser.forward_buffers`: combined in place, no copy)."""
        return self.denoiser.forward_buffers(num_signals, height, width)

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
        """The next frame (going backwards in time); the output when ``forward`` is given."""
        reverse = dataclasses.replace(
            frame,
            motion=self.motion_to_next(frame),
            motion_next=None,
            # Gradient samples describe the change from the previous frame: not this pass's.
            signals=[dataclasses.replace(s, gradient=None) for s in frame.signals],
        )
        result = self.denoiser.reverse_step(reverse, forward)
        # The frame before this one (processed next) gets its motion to this one now.
        self._derived_ready = False
        if frame.motion_next is None:
            motion = self._motion_buffer(frame.height, frame.width)
            self.derived_holes = invert_motion(
                _finite(frame.motion, NO_MOTION), _finite(frame.depth, F32(0.0)), motion)
            self._derived_ready = True
        return result


def denoise_bidirectional(
    frames: Sequence[Frame], params: SVGFParams, *, debug_layers: bool = False,
    half: bool = False,
) -> list[DenoisedFrame]:
    """Both passes over ``frames`` (in order) held in memory; the outputs in order.

    ``half`` stores the forward histories as a file run spills them (half floats), to
    measure what that costs."""
    forward = Denoiser(params)
    kept: list[SideHistory] = []
    for frame in frames:
        if half:
            packed = forward.forward_step(frame, lambda h, n=frame.names: pack_history(n, h))
            kept.append(unpack_history(frame.names, *packed))
        else:
            kept.append(forward.forward_step(frame))
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
