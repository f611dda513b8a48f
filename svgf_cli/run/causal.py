"""The causal driver: the filter over a chunk's frames in order (`run_causal`), each frame
read one ahead by the reader thread and written behind by the writer thread.

Memory holds about three frames whatever the sequence length: the one filtered, the one
read and the one written (the writer thread reads a denoised frame's planes while the next
one is filtered: safe because `DenoisedFrame` arrays are fresh per frame, not the filter's
buffers). The one filtered reads its light layers once its colour filter is done and then
lets go of the input pixels a layered filter writes anew (`light.LightLayerReader`), the one
written of every channel its output replaces (`output.release_light_inputs`,
`output.release_replaced`). With ``--low-memory``, two: the
next frame is read once the one before is filtered and handed to the writer.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

from svgf_cli.filters.params import SVGFParams
from svgf_cli.frame import DenoisedFrame, Frame
from svgf_cli.progress import Progress
from svgf_cli.run.filter import FrameFilter, PassFilter
from svgf_cli.run.history import HistoryFile
from svgf_cli.run.light import LightLayerReader
from svgf_cli.run.stop import StopFlag, interrupted
from svgf_cli.run.tasks import FrameTask, RunConfig, RunStats, WarmupCount
from svgf_cli.run.workers import (
    ReadAhead,
    Reader,
    WriteBehind,
    default_reader,
    frame_reader,
    frame_writer,
)

if TYPE_CHECKING:
    from svgf_cli.io.exr import ReadResult


class CausalFilter(PassFilter, Protocol):
    """The filter of a causal run (``filters.denoiser.Denoiser``; stand-ins in tests)."""

    def process(self, frame: Frame) -> DenoisedFrame: ...


def default_denoiser(params: SVGFParams, debug_layers: bool) -> CausalFilter:
    from svgf_cli.filters.denoiser import Denoiser

    return Denoiser(params, debug_layers=debug_layers)


def layered_denoiser(params: SVGFParams, debug_layers: bool) -> CausalFilter:
    from svgf_cli.filters.composable import LayeredDenoiser

    return LayeredDenoiser(params, debug_layers=debug_layers)


def run_causal(
    tasks: Sequence[FrameTask],
    config: RunConfig,
    progress: Progress,
    *,
    stop: StopFlag | None = None,
    history: HistoryFile | None = None,
    save_history_to: Path | None = None,
    warmup_total: int | None = None,
    on_first_frame: Callable[[ReadResult], None] | None = None,
    make_denoiser: Callable[[SVGFParams, bool], CausalFilter] = default_denoiser,
    read: Reader = default_reader,
    warm_colours: dict[int, np.ndarray] | None = None,
) -> RunStats:
    """Run the filter over ``tasks`` in order, writing the frames that have an output (see
    `chunk.run_sequence`); an output frame in ``warm_colours`` (taken out as it is used)
    gets that colour (`warm_start`)."""
    warm_colours = warm_colours if warm_colours is not None else {}
    stats = RunStats()
    if not tasks:
        return stats
    started = time.perf_counter()
    light = LightLayerReader(config, progress)
    if light.enabled and make_denoiser is default_denoiser:
        make_denoiser = layered_denoiser
    # A layered filter writes the light layers anew: their input pixels need not be held.
    release_light = light.enabled and make_denoiser is layered_denoiser
    frames = FrameFilter(
        config, progress, stats, make_denoiser, history=history, on_first_frame=on_first_frame
    )
    if warmup_total is None:
        warmup_total = sum(1 for t in tasks if t.output is None)
    warmup = WarmupCount(progress, warmup_total)
    with (
        ReadAhead(tasks, frame_reader(config, read), stats,
                  eager=not config.low_memory) as reads,
        WriteBehind(frame_writer(config), progress, stats) as writes,
    ):
        frame_started = time.perf_counter()
        for task, result, read_seconds in reads:
            frames.admit(task, result)
            light.attach(task, result, release=release_light)
            if task.output is not None and task.frame in warm_colours:
                result.frame = replace(result.frame, final_colour=warm_colours.pop(task.frame))
            writes.poll()  # report a finished write now rather than a frame later
            denoised, compute_seconds = frames.process(task, result, frames.filter.process)
            if task.output is None:
                warmup.frame_done(task.frame)
            else:
                # The writer thread reads these planes while the next frame is filtered: safe
                # because DenoisedFrame arrays are fresh per frame, not the denoiser's buffers.
                writes.submit_denoised(task, result, denoised, config, frame_started)
                # Only the writer holds this frame now: memory is freed when it is done.
                denoised = result = None  # type: ignore[assignment]
            # --low-memory: the next frame is read only now, beside this frame's write alone
            # (the write before it is done); otherwise it is under way already.
            reads.prefetch()
            frame_started = time.perf_counter()
            progress.detail(
                f"frame {task.frame}: read {read_seconds:.3f} s, compute {compute_seconds:.3f} s"
            )
            if stop:
                writes.finish()
                raise interrupted(stop, task.frame)
        writes.finish()
    if save_history_to is not None:
        frames.save_history(save_history_to, tasks[-1].input)
    stats.wall_seconds = time.perf_counter() - started
    return stats
