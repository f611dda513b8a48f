"""The file driver of a bidirectional run (``--bidirectional``): two passes over a chunk.

Reuses the runner's parts (`ReadAhead`, `FrameFilter`, `WriteBehind`, the output builder):

1. **Forward pass**, frames in order up to the last output frame: the causal filter
   (``Denoiser.forward_step``); at each output frame the history it resampled is packed
   (``filters.bidirectional.pack_history``: half floats) and written to a private scratch
   folder (``io.spill``) by one writer thread. Inputs are read without their passthrough
   layers (nothing is written in this pass).
2. **Reverse pass**, from the chunk's last frame (its reverse warm-up) down to the first
   output frame (``filters.two_pass.ReversePass``): at each output frame the forward state
   is read back (by its own reader thread, while the frame before is written; its file
   deleted once read), unpacked into the reverse pass's combination buffers, combined in
   place with the reverse history, filtered and written like a causal run's output.

Memory: one Denoiser (the forward state is unpacked into its combination buffers, which
are let go between output frames), two frames (the reverse pass reads frame ``t - 1``
only once the write of ``t + 1`` is done: the frame filtered or written, and the one read)
and one packed state (let go plane by plane as it is unpacked), whatever the length; disk:
one packed state per output frame between the passes (about 35 MB per 1080p frame with two
signals). The scratch folder is removed however the run ends (success, error, SIGINT or
SIGTERM: the runner's stop flag ends a pass between frames). Resume with ``--skip-existing``
as a causal run: outputs are only written by the reverse pass, atomically, last to first.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import Any

from svgf_cli.filters.bidirectional import pack_history, unpack_history
from svgf_cli.io.spill import ScratchFolder
from svgf_cli.progress import Progress
from svgf_cli.runner import (
    FrameFilter,
    FrameTask,
    ReadAhead,
    RunConfig,
    RunStats,
    StopFlag,
    WarmupCount,
    WriteBehind,
    _block_signals,
    _default_reader,
    _interrupted,
    frame_reader,
    frame_writer,
)


class _SpillWrites:
    """Packed forward states written by one thread, one write in flight (the next frame is
    filtered meanwhile). Leaving the ``with`` block waits for the write in flight."""

    def __init__(self, scratch: ScratchFolder) -> None:
        self._scratch = scratch
        self._executor = ThreadPoolExecutor(
            1, thread_name_prefix="svgf-spill", initializer=_block_signals
        )
        self._pending: Future[None] | None = None

    def submit(self, frame: int, packed: tuple[dict[str, Any], dict[str, float]]) -> None:
        self.finish()
        self._pending = self._executor.submit(self._scratch.write, frame, *packed)

    def finish(self) -> None:
        if self._pending is not None:
            pending, self._pending = self._pending, None
            pending.result()

    def __enter__(self) -> _SpillWrites:
        return self

    def __exit__(self, *exc_info: object) -> None:
        try:
            if self._pending is not None:
                self._pending.exception()  # wait; the error being unwound is the one to report
        finally:
            self._executor.shutdown(wait=True)


class _StateReads:
    """Packed forward states read back by one thread, one read in flight. The read of the
    next output frame's state starts when :meth:`prefetch` is called (after the frame before
    it is filtered), never while a frame is combined and filtered: at most one packed state
    is held at the memory peak, none beside an unpacked one."""

    def __init__(self, scratch: ScratchFolder, frames: Sequence[int]) -> None:
        self._scratch = scratch
        self._frames = list(frames)
        self._position = 0
        self._executor = ThreadPoolExecutor(
            1, thread_name_prefix="svgf-state", initializer=_block_signals
        )
        self._pending: Future[tuple[dict[str, Any], dict[str, float]]] | None = None

    def prefetch(self) -> None:
        """Start reading the next state, if any and not started yet."""
        if self._pending is None and self._position < len(self._frames):
            self._pending = self._executor.submit(self._scratch.read,
                                                  self._frames[self._position])

    def take(self, frame: int) -> tuple[dict[str, Any], dict[str, float]]:
        """Frame ``frame``'s state (the next one in order), waiting for its read."""
        assert self._frames[self._position] == frame, (frame, self._frames[self._position])
        self.prefetch()
        assert self._pending is not None
        pending, self._pending = self._pending, None
        self._position += 1
        return pending.result()

    def __enter__(self) -> _StateReads:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self._pending = None
        self._executor.shutdown(wait=True, cancel_futures=True)


def _reverse_tasks(tasks: Sequence[FrameTask], first_output: int) -> list[FrameTask]:
    """The reverse pass's frames, last to ``first_output``. A gap resets the history at the
    frame before it in time (the one the reverse pass meets after the gap)."""
    reverse = []
    for i in range(len(tasks) - 1, first_output - 1, -1):
        gap_after = i + 1 < len(tasks) and tasks[i + 1].reset_history
        reverse.append(replace(tasks[i], reset_history=gap_after))
    return reverse


def _make_reverse_pass(params: Any, debug_layers: bool) -> Any:
    from svgf_cli.filters.two_pass import ReversePass

    return ReversePass(params, debug_layers=debug_layers)


def _make_forward_pass(params: Any, debug_layers: bool) -> Any:
    from svgf_cli.filters.denoiser import Denoiser

    return Denoiser(params, debug_layers=False)


def run_bidirectional(
    tasks: Sequence[FrameTask],
    config: RunConfig,
    progress: Progress,
    *,
    stop: StopFlag | None = None,
    on_first_frame: Callable[[Any], None] | None = None,
    read: Callable[..., Any] = _default_reader,
) -> RunStats:
    """Both passes over one chunk's ``tasks`` (frames in time order; history-only frames
    before the first output are the forward warm-up, after the last the reverse one)."""
    stats = RunStats()
    outputs = [i for i, t in enumerate(tasks) if t.output is not None]
    if not outputs:
        return stats
    started = time.perf_counter()
    forward_tasks = list(tasks[: outputs[-1] + 1])
    reverse_tasks = _reverse_tasks(tasks, outputs[0])
    warmup = WarmupCount(progress, (len(forward_tasks) - len(outputs))
                         + (len(reverse_tasks) - len(outputs)))
    progress.passes = 2
    with ScratchFolder(config.scratch_dir) as scratch:
        _forward_pass(forward_tasks, config, progress, stats, scratch, warmup, stop,
                      on_first_frame, read)
        _reverse_pass(reverse_tasks, config, progress, stats, scratch, warmup, stop, read)
        progress.detail(f"scratch: {scratch.bytes_written / 2**20:.0f} MB written to "
                        f"{scratch.path}")
    stats.wall_seconds = time.perf_counter() - started
    return stats


def _forward_pass(
    tasks: Sequence[FrameTask], config: RunConfig, progress: Progress, stats: RunStats,
    scratch: ScratchFolder, warmup: WarmupCount, stop: StopFlag | None,
    on_first_frame: Callable[[Any], None] | None, read: Callable[..., Any],
) -> None:
    frames = FrameFilter(config, progress, stats, _make_forward_pass,
                         on_first_frame=on_first_frame)
    # Nothing is written in this pass: the passthrough layers need not be decoded.
    lean = replace(config, colour_only=True)
    with (
        ReadAhead(tasks, frame_reader(lean, read), stats) as reads,
        _SpillWrites(scratch) as spills,
    ):
        for task, result, _ in reads:
            frames.admit(task, result)
            names = result.frame.names
            if task.output is None:
                frames.process(task, result, lambda f: frames.denoiser.forward_step(
                    f, keep=lambda _history: None))
                warmup.frame_done(task.frame)
            else:
                packed, _ = frames.process(task, result, lambda f, n=names: (
                    frames.denoiser.forward_step(f, keep=lambda h: pack_history(n, h))))
                spills.submit(task.frame, packed)
                progress.forward_done(task.frame)
            if stop:
                raise _interrupted(stop, task)
        spills.finish()


def _reverse_pass(
    tasks: Sequence[FrameTask], config: RunConfig, progress: Progress, stats: RunStats,
    scratch: ScratchFolder, warmup: WarmupCount, stop: StopFlag | None,
    read: Callable[..., Any],
) -> None:
    frames = FrameFilter(config, progress, stats, _make_reverse_pass)
    written = [t.frame for t in tasks if t.output is not None]
    with (
        WriteBehind(frame_writer(config), progress, stats) as writes,
        _StateReads(scratch, written) as states,
        # Frame t - 1 is read once the write of t + 1 is done: with its passthrough
        # layers a frame is the largest thing in flight, and three of them beside the
        # Denoiser's buffers were the peak. Reads and writes still overlap the filtering.
        ReadAhead(tasks, frame_reader(config, read), stats, after=writes.in_flight) as reads,
    ):
        states.prefetch()  # the first output frame's, while the reverse warm-up runs
        frame_started = time.perf_counter()
        for task, result, _ in reads:
            frames.admit(task, result)
            writes.poll()
            forward = None
            if task.output is not None:
                # Unpacked straight into the reverse pass's combination buffers, where it
                # is combined in place: no other copy of the state is held.
                frame = result.frame
                into = frames.denoiser.forward_buffers(len(frame.names), frame.height,
                                                       frame.width)
                forward = unpack_history(frame.names, *states.take(task.frame), out=into)
                frame = into = None
            denoised, _ = frames.process(
                task, result, lambda f, h=forward: frames.denoiser.process(f, h))
            forward = None
            # The next state is read while this frame is written and the next one read.
            states.prefetch()
            if task.output is None:
                warmup.frame_done(task.frame)
            else:
                writes.submit_denoised(task, result, denoised, config, frame_started)
                denoised = result = None
            frame_started = time.perf_counter()
            if stop:
                writes.finish()
                raise _interrupted(stop, task)
        writes.finish()


def scratch_note(parent: Path | None) -> str:
    """Where the scratch goes, for the start-up log."""
    from svgf_cli.io.spill import default_parent

    return str(parent if parent is not None else default_parent())
