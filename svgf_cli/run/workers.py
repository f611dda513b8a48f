"""The I/O threads of a pass: one reader thread one frame ahead of the filter (`ReadAhead`,
reading with `frame_reader`) and one writer thread with one write in flight (`WriteBehind`,
writing with `frame_writer`).

Each owns its thread, started with SIGINT/SIGTERM blocked (`stop.block_signals`). With the
filter working on one frame between them, memory holds about three frames whatever the
sequence length (two with ``ReadAhead(after=WriteBehind.in_flight)`` or not ``eager``).
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor, wait
from pathlib import Path
from typing import TYPE_CHECKING

from svgf_cli import __version__
from svgf_cli.errors import InputError, SvgfError
from svgf_cli.frame import DenoisedFrame
from svgf_cli.progress import Progress
from svgf_cli.run.output import OutputFrame, build_output
from svgf_cli.run.stop import block_signals
from svgf_cli.run.tasks import FrameTask, RunConfig, RunStats

if TYPE_CHECKING:
    from svgf_cli.io.exr import ReadResult
    from svgf_cli.io.layers import LayerMapping

# A frame reader: ``read(path, mapping)``; `default_reader` also takes ``passthrough=``.
# (``...``: stand-in readers in tests take only the two positional arguments.)
Reader = Callable[..., "ReadResult"]
# Writes one task's output file; returns the writer's notes.
Writer = Callable[[FrameTask, OutputFrame], list[str]]


def default_reader(path: Path, mapping: LayerMapping, *, passthrough: bool = True) -> ReadResult:
    from svgf_cli.io.exr import read_frame

    return read_frame(path, mapping, mapping.motion_convention, passthrough=passthrough)


class FirstRead:
    """A reader that hands out one frame already decoded, on its first call, when that call
    is for the same file and wants its pass-through channels; every other read (and that
    one otherwise) is `default_reader`'s. `svgf denoise` decodes the first frame to fix the
    signal set before the run: this saves decoding it again (~2 CPU-s for a 1080p
    production frame, 80 channels). The frame is let go at the first call either way."""

    takes_passthrough = True

    def __init__(self, path: Path, result: ReadResult) -> None:
        self.path = Path(path)
        self.result: ReadResult | None = result

    def __call__(self, path: Path, mapping: LayerMapping, *, passthrough: bool = True
                 ) -> ReadResult:
        cached, self.result = self.result, None
        if cached is not None and passthrough and Path(path) == self.path:
            return cached
        return default_reader(path, mapping, passthrough=passthrough)


def frame_reader(
    config: RunConfig, read: Reader = default_reader
) -> Callable[[FrameTask], ReadResult]:
    """``read`` of one task's input with the run's options; any failure becomes one
    InputError (exit 3) naming the file."""

    def read_task(task: FrameTask) -> ReadResult:
        try:
            if read is default_reader or getattr(read, "takes_passthrough", False):
                return read(task.input, config.mapping, passthrough=not config.colour_only)
            return read(task.input, config.mapping)
        except SvgfError:
            raise
        except FileNotFoundError:
            raise InputError("input file not found", str(task.input)) from None
        except (OSError, RuntimeError, ValueError) as exc:
            raise InputError(f"cannot read: {exc}", str(task.input)) from None

    return read_task


class ReadAhead:
    """The frames of ``tasks``, read in the given order by one thread, one frame ahead.

    Iterating yields ``(task, result, read_seconds)``. While the caller works on one frame
    the next one is read, never more, so memory holds at most two read frames; the order is
    the caller's (a backward pass reads the tasks reversed). Read and wait seconds are added
    to ``stats``. With ``after``, a read starts only once the future ``after`` returns
    when the read is queued (None: at once) is done, e.g. the write in flight
    (:meth:`WriteBehind.in_flight`: then a read overlaps at most the write of the frame
    just filtered, never an older one, and two frames are in memory, not three). Not
    ``eager``: the next read starts when the caller asks (:meth:`prefetch`, e.g. once the
    frame it holds is filtered), or when it asks for that frame: one read frame at a time,
    never two. Owns its thread: leaving the ``with`` block cancels a read not yet started
    and waits for one under way.
    """

    def __init__(
        self, tasks: Sequence[FrameTask], read: Callable[[FrameTask], ReadResult],
        stats: RunStats, after: Callable[[], Future[object] | None] | None = None,
        eager: bool = True,
    ) -> None:
        self._tasks = tasks
        self._read = read
        self._stats = stats
        self._after = after
        self._eager = eager
        self._position = 0
        self._executor = ThreadPoolExecutor(
            1, thread_name_prefix="svgf-read", initializer=block_signals
        )
        self._upcoming = self._submit(0)

    def _submit(self, position: int) -> Future[tuple[ReadResult, float]] | None:
        if position >= len(self._tasks):
            return None
        waiting = self._after() if self._after is not None else None
        return self._executor.submit(self._timed_read, self._tasks[position], waiting)

    def _timed_read(self, task: FrameTask, waiting: Future[object] | None
                    ) -> tuple[ReadResult, float]:
        if waiting is not None:
            wait((waiting,))  # its outcome is its owner's to report
        started = time.perf_counter()
        result = self._read(task)
        return result, time.perf_counter() - started

    def __iter__(self) -> ReadAhead:
        return self

    def __next__(self) -> tuple[FrameTask, ReadResult, float]:
        # No generator: its suspended frame would hold the previous result a frame longer.
        self.prefetch()
        if self._upcoming is None:
            raise StopIteration
        task = self._tasks[self._position]
        wait_started = time.perf_counter()
        result, seconds = self._upcoming.result()
        self._upcoming = None
        self._stats.wait_read_seconds += time.perf_counter() - wait_started
        self._stats.read_seconds += seconds
        self._position += 1
        if self._eager:  # the next frame is read while this one is filtered (depth one)
            self.prefetch()
        return task, result, seconds

    def prefetch(self) -> None:
        """Start reading the next frame now, if it is not read or under way already."""
        if self._upcoming is None:
            self._upcoming = self._submit(self._position)

    def close(self) -> None:
        self._upcoming = None
        self._position = len(self._tasks)  # no read starts after this
        self._executor.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> ReadAhead:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def frame_writer(config: RunConfig) -> Writer:
    """Write one task's output file with the run's options (atomically: `write_output`);
    returns the writer's notes."""
    from svgf_cli.io.exr import io_threads
    from svgf_cli.io.output import write_output

    def write_task(task: FrameTask, output: OutputFrame) -> list[str]:
        assert task.output is not None
        return write_output(
            task.output,
            output.source,
            part_index=output.part_index,
            channels=output.channels,
            attributes=output.attributes,
            software=f"svgf {__version__}",
            compression=config.compression,
            keep_only=output.keep_only,
            threads=io_threads(),
        )

    return write_task


class WriteBehind:
    """Output frames written by one thread, at most one write in flight.

    ``submit`` first waits for the write in flight, so the caller filters the next frame
    while this one is written. A finished write is reported once, in order: its notes as
    warnings, ``Progress.frame_done`` with the frame's wall time (from ``started`` to the
    end of its write), its seconds and frame number in ``stats``. Owns its thread: leaving
    the ``with`` block waits for a write in flight even when an error unwinds (never a
    half-done write), without reporting it (the error is the one to report).
    """

    def __init__(self, write: Writer, progress: Progress, stats: RunStats) -> None:
        self._write = write
        self._progress = progress
        self._stats = stats
        self._executor = ThreadPoolExecutor(
            1, thread_name_prefix="svgf-write", initializer=block_signals
        )
        self._pending: tuple[FrameTask, Future[tuple[float, list[str]]], float] | None = None

    def submit_denoised(self, task: FrameTask, result: ReadResult, denoised: DenoisedFrame,
                        config: RunConfig, started: float) -> None:
        """Build the output file's content of a denoised frame, report its warnings and
        :meth:`submit` it."""
        output = build_output(result, denoised, config, task)
        for message in output.warnings:
            self._progress.warning(f"{task.input}: {message}")
        self.submit(task, output, started)

    def _timed_write(self, task: FrameTask, output: OutputFrame) -> tuple[float, list[str]]:
        started = time.perf_counter()
        notes = self._write(task, output)
        return time.perf_counter() - started, notes

    def submit(self, task: FrameTask, output: OutputFrame, started: float) -> None:
        """Queue ``output`` to ``task.output`` once the write in flight is finished."""
        self.finish()
        self._pending = (task, self._executor.submit(self._timed_write, task, output), started)

    def in_flight(self) -> Future[tuple[float, list[str]]] | None:
        """The write in flight, if any (not reported: :meth:`finish` does that)."""
        return self._pending[1] if self._pending is not None else None

    def poll(self) -> None:
        """Report the write in flight if it is done (now rather than a frame later)."""
        if self._pending is not None and self._pending[1].done():
            self.finish()

    def finish(self) -> None:
        """Wait for the write in flight and report it; its error propagates."""
        if self._pending is None:
            return
        task, future, started = self._pending
        self._pending = None
        seconds, notes = future.result()
        self._stats.write_seconds += seconds
        for note in notes:
            self._progress.warning(f"{task.output}: {note}")
        self._stats.frames_written += 1
        self._stats.written.append(task.frame)
        self._progress.frame_done(task.frame, time.perf_counter() - started)

    def close(self) -> None:
        if self._pending is not None:
            # Never leave a write half-done; the error being unwound is the one to report.
            with contextlib.suppress(Exception):
                self._pending[1].result()
            self._pending = None
        self._executor.shutdown(wait=True)

    def __enter__(self) -> WriteBehind:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
