"""The driver of a bidirectional run (``--bidirectional``): two passes over a chunk
(`run_bidirectional`), with the causal run's parts (`workers.ReadAhead`,
`filter.FrameFilter`, `workers.WriteBehind`, the output builder) and the scratch threads
(`scratch.SpillWrites`, `scratch.StateReads`):

1. **Forward pass**, frames in order up to the last output frame: the causal filter
   (``filters.two_pass.ForwardPass``); at each output frame the history it resampled is
   packed (``Keep.PACKED``: ``filters.bidirectional.pack_history``, half floats) and
   written to a private scratch folder (``io.spill``) by one writer thread. Inputs are read
   without their passthrough layers (nothing is written in this pass).
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
SIGTERM: the stop flag ends a pass between frames). Resume with ``--skip-existing``
as a causal run: outputs are only written by the reverse pass, atomically, last to first.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

from svgf_cli.filters.bidirectional import unpack_history
from svgf_cli.filters.composable import LayeredReversePass
from svgf_cli.filters.params import SVGFParams
from svgf_cli.filters.two_pass import ForwardPass, Keep, ReversePass
from svgf_cli.io.spill import ScratchFolder
from svgf_cli.progress import Progress
from svgf_cli.run.filter import FrameFilter
from svgf_cli.run.light import LightLayerReader
from svgf_cli.run.scratch import SpillWrites, StateReads
from svgf_cli.run.stop import StopFlag, interrupted
from svgf_cli.run.tasks import FrameTask, RunConfig, RunStats, WarmupCount
from svgf_cli.run.workers import (
    ReadAhead,
    Reader,
    WriteBehind,
    Writer,
    default_reader,
    frame_reader,
    frame_writer,
)

if TYPE_CHECKING:
    from svgf_cli.io.exr import ReadResult


@dataclass
class _Pass:
    """What both passes of one run share."""

    config: RunConfig
    progress: Progress
    stats: RunStats
    scratch: ScratchFolder
    warmup: WarmupCount
    stop: StopFlag | None
    read: Reader
    write: Writer


def reverse_tasks(tasks: Sequence[FrameTask], first_output: int) -> list[FrameTask]:
    """The reverse pass's frames, last to ``first_output``. A gap resets the history at the
    frame before it in time (the one the reverse pass meets after the gap)."""
    reverse = []
    for i in range(len(tasks) - 1, first_output - 1, -1):
        gap_after = i + 1 < len(tasks) and tasks[i + 1].reset_history
        reverse.append(replace(tasks[i], reset_history=gap_after))
    return reverse


def run_bidirectional(
    tasks: Sequence[FrameTask],
    config: RunConfig,
    progress: Progress,
    *,
    stop: StopFlag | None = None,
    on_first_frame: Callable[[ReadResult], None] | None = None,
    read: Reader = default_reader,
    write: Writer | None = None,
) -> RunStats:
    """Both passes over one chunk's ``tasks`` (frames in time order; history-only frames
    before the first output are the forward warm-up, after the last the reverse one).
    ``write``: where the output frames go (default: their files, `workers.frame_writer`)."""
    stats = RunStats()
    outputs = [i for i, t in enumerate(tasks) if t.output is not None]
    if not outputs:
        return stats
    started = time.perf_counter()
    forward_tasks = list(tasks[: outputs[-1] + 1])
    backward = reverse_tasks(tasks, outputs[0])
    warmup = WarmupCount(progress, (len(forward_tasks) - len(outputs))
                         + (len(backward) - len(outputs)))
    progress.passes = 2
    with ScratchFolder(config.scratch_dir) as scratch:
        run = _Pass(config, progress, stats, scratch, warmup, stop, read,
                    write or frame_writer(config))
        _forward_pass(run, forward_tasks, on_first_frame)
        _reverse_pass(run, backward)
        progress.detail(f"scratch: {scratch.bytes_written / 2**20:.0f} MB written to "
                        f"{scratch.path}")
    stats.wall_seconds = time.perf_counter() - started
    return stats


def _forward_pass(run: _Pass, tasks: Sequence[FrameTask],
                  on_first_frame: Callable[[ReadResult], None] | None) -> None:
    frames = FrameFilter(run.config, run.progress, run.stats, ForwardPass,
                         on_first_frame=on_first_frame)
    # Nothing is written in this pass: the passthrough layers need not be decoded.
    lean = replace(run.config, colour_only=True)
    with (
        ReadAhead(tasks, frame_reader(lean, run.read), run.stats) as reads,
        SpillWrites(run.scratch) as spills,
    ):
        for task, result, _ in reads:
            frames.admit(task, result)
            if task.output is None:
                frames.process(task, result, frames.filter.process, Keep.NOTHING)
                run.warmup.frame_done(task.frame)
            else:
                packed, _ = frames.process(task, result, frames.filter.process, Keep.PACKED)
                spills.submit(task.frame, packed)
                run.progress.forward_done(task.frame)
            if run.stop:
                raise interrupted(run.stop, task.frame)
        spills.finish()


def layered_reverse(params: SVGFParams, debug_layers: bool) -> LayeredReversePass:
    """The reverse pass with the light layers of its output frames."""
    return LayeredReversePass(params, debug_layers=debug_layers)


def _reverse_pass(run: _Pass, tasks: Sequence[FrameTask]) -> None:
    config, stats = run.config, run.stats
    writes_to = [t.frame for t in tasks if t.output is not None]
    # The light layers are split from the combined colour, as a causal run's from its own.
    light = LightLayerReader(config, run.progress)
    frames = FrameFilter(config, run.progress, stats,
                         layered_reverse if light.enabled else ReversePass)
    with (
        WriteBehind(run.write, run.progress, stats) as writes,
        StateReads(run.scratch, writes_to) as states,
        # Frame t - 1 is read once the write of t + 1 is done: with its passthrough
        # layers a frame is the largest thing in flight, and three of them beside the
        # Denoiser's buffers were the peak. Reads and writes still overlap the filtering.
        ReadAhead(tasks, frame_reader(config, run.read), stats, after=writes.in_flight) as reads,
    ):
        states.prefetch()  # the first output frame's, while the reverse warm-up runs
        frame_started = time.perf_counter()
        for task, result, _ in reads:
            frames.admit(task, result)
            writes.poll()
            forward = None
            # Read once the colour is filtered; their input pixels let go once read.
            light.attach(task, result, release=True)
            if task.output is not None:
                # Unpacked straight into the reverse pass's combination buffers, where it
                # is combined in place: no other copy of the state is held.
                frame = result.frame
                into = frames.filter.forward_buffers(len(frame.names), frame.height,
                                                     frame.width)
                forward = unpack_history(frame.names, *states.take(task.frame), out=into)
                frame = into = None  # type: ignore[assignment]
            denoised, _ = frames.process(task, result, frames.filter.process, forward)
            forward = None
            # The next state is read while this frame is written and the next one read.
            states.prefetch()
            if task.output is None:
                run.warmup.frame_done(task.frame)
            else:
                assert denoised is not None  # an output frame gets its forward history
                writes.submit_denoised(task, result, denoised, config, frame_started)
                denoised = result = None  # type: ignore[assignment]
            frame_started = time.perf_counter()
            if run.stop:
                writes.finish()
                raise interrupted(run.stop, task.frame)
        writes.finish()


def scratch_note(parent: Path | None) -> str:
    """Where the scratch goes, for the start-up log."""
    from svgf_cli.io.spill import default_parent

    return str(parent if parent is not None else default_parent())
