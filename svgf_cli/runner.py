"""The sequential driver shared by local runs, local chunks and Dask tasks.

Given the ordered frames of one chunk (``FrameTask``: frame number, input path, output path
or None for a history-only frame), `run_sequence` runs the Denoiser frame by frame. Its parts,
each owning what it says:

* `ReadAhead`: one reader thread, one frame ahead of the filter, in the order given;
* `FrameFilter`: the Denoiser and the checks each frame passes (resolution, a loaded history
  file, the reader's and the Denoiser's warnings);
* `WriteBehind`: one writer thread, one write in flight, and the report of each written frame;
* resume bookkeeping: `RunStats`, `WarmupCount`, history files (`load_history`,
  `save_history`), `pending_tasks` and `trim_tail`.

Memory holds about three frames whatever the sequence length. SIGINT/SIGTERM finish the frame
in flight and then stop (exit 130/143); the I/O threads never receive them.
"""

from __future__ import annotations

import contextlib
import json
import signal
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor, wait
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from svgf_cli import __version__
from svgf_cli.errors import EXIT_SIGINT, EXIT_SIGTERM, InputError, SvgfError, UsageError
from svgf_cli.filters.params import SVGFParams
from svgf_cli.heap import map_large_blocks
from svgf_cli.progress import Progress

# Prefix of the debug channels (--debug-aovs): a layer name no renderer writes, so they
# never collide with an input layer that is passed through.
DEBUG_PREFIX = "svgf."


@dataclass(frozen=True)
class FrameTask:
    """One frame of a chunk. ``output`` None: processed for history only, never written."""

    frame: int
    input: Path
    output: Path | None
    reset_history: bool = False  # --allow-gaps: a frame before this one is missing


@dataclass(frozen=True)
class RunConfig:
    """Everything a chunk needs besides its frames; picklable (shipped to Dask workers)."""

    params: SVGFParams
    preset: str
    mapping: Any  # svgf_cli.io.layers.LayerMapping
    float_colour: bool = False  # --float; else the colour keeps the input's pixel type
    compression: str | None = None  # None: each part keeps the input's compression
    debug_aovs: bool = False
    warmup_label: str = "all"
    threads: int | None = None
    colour_only: bool = False  # --colour-only: only the colour layer and its alpha
    scratch_dir: Path | None = None  # --scratch-dir (bidirectional); None: the system's


@dataclass
class RunStats:
    """What a run did and where its time went (seconds, summed over frames).

    Each part of the driver adds its own fields: `ReadAhead` the read seconds, `FrameFilter`
    the frames processed and compute seconds, `WriteBehind` the frames written.
    """

    frames_processed: int = 0
    frames_written: int = 0
    read_seconds: float = 0.0
    compute_seconds: float = 0.0
    write_seconds: float = 0.0
    wait_read_seconds: float = 0.0
    wall_seconds: float = 0.0
    last_frame: int | None = None
    written: list[int] = field(default_factory=list)

    def merge(self, other: RunStats) -> None:
        self.frames_processed += other.frames_processed
        self.frames_written += other.frames_written
        self.read_seconds += other.read_seconds
        self.compute_seconds += other.compute_seconds
        self.write_seconds += other.write_seconds
        self.wait_read_seconds += other.wait_read_seconds
        self.wall_seconds += other.wall_seconds
        self.written.extend(other.written)
        if other.last_frame is not None:
            self.last_frame = other.last_frame


class Interrupted(SvgfError):
    """SIGINT/SIGTERM arrived; the frame in flight was finished first."""

    def __init__(self, signum: int, detail: str) -> None:
        name = signal.Signals(signum).name
        super().__init__(f"interrupted by {name}; {detail}")
        self.signum = signum
        self.exit_code = EXIT_SIGINT if signum == signal.SIGINT else EXIT_SIGTERM

    def __reduce__(self) -> tuple[Any, ...]:
        return (_rebuild_interrupted, (self.signum, str(self)))


def _rebuild_interrupted(signum: int, message: str) -> Interrupted:
    exc = Interrupted.__new__(Interrupted)
    SvgfError.__init__(exc, message)
    exc.signum = signum
    exc.exit_code = EXIT_SIGINT if signum == signal.SIGINT else EXIT_SIGTERM
    return exc


class StopFlag:
    """Set by the signal handlers; polled between frames."""

    def __init__(self) -> None:
        self.signum: int | None = None

    def __bool__(self) -> bool:
        return self.signum is not None


@contextmanager
def stop_on_signals(immediate: bool = False) -> Iterator[StopFlag]:
    """Turn SIGINT/SIGTERM into a stop request for the duration of the block.

    The first signal only sets the flag (the runner finishes the frame in flight, then
    raises ``Interrupted``); a second one, or any signal with ``immediate``, raises at once.
    Outside the main thread (Dask workers) signals cannot be caught: the flag stays unset.
    """
    flag = StopFlag()
    if threading.current_thread() is not threading.main_thread():
        yield flag
        return

    def handler(signum: int, _frame: Any) -> None:
        if immediate or flag.signum is not None:
            raise Interrupted(signum, "stopped at once; rerun with --skip-existing to resume")
        flag.signum = signum

    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield flag
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


def _block_signals() -> None:
    """Keep SIGINT/SIGTERM off the I/O threads: only the main thread may receive them.

    CPython installs its handlers without SA_RESTART, so a signal delivered to a thread
    that is inside OpenEXR's read() or write() interrupts the system call (EINTR), which the
    library does not retry: the frame in flight was read or written wrong. Measured: a
    SIGINT during a read-ahead made the next written frame differ from the uninterrupted run.
    """
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})


class DenoiserLike(Protocol):
    frames_processed: int

    def process(self, frame: Any) -> Any: ...
    def reset(self) -> None: ...
    def state(self) -> dict[str, np.ndarray]: ...
    def load_state(self, state: dict[str, np.ndarray]) -> None: ...


def _default_denoiser(params: SVGFParams, debug_layers: bool) -> DenoiserLike:
    from svgf_cli.filters.denoiser import Denoiser

    return Denoiser(params, debug_layers=debug_layers)


def _default_reader(path: Path, mapping: Any, *, passthrough: bool = True) -> Any:
    from svgf_cli.io.exr import read_frame

    return read_frame(path, mapping, mapping.motion_convention, passthrough=passthrough)


# -- resume bookkeeping: history files, retries, warm-up ------------------------------------

_STATE_PREFIX = "state__"


@dataclass(frozen=True)
class HistoryFile:
    """A saved Denoiser state plus what it was computed from."""

    path: Path
    state: dict[str, np.ndarray]
    last_frame: int
    params_json: str
    width: int
    height: int


def load_history(path: Path) -> HistoryFile:
    """Read a ``--save-history`` file; InputError (exit 3) when missing or not one of ours."""
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: np.array(data[name]) for name in data.files}
    except FileNotFoundError:
        raise InputError("history file not found", str(path)) from None
    except (OSError, ValueError) as exc:
        raise InputError(f"cannot read history file: {exc}", str(path)) from None
    try:
        last_frame = int(arrays["svgf_last_frame"])
        params_json = str(arrays["svgf_params"])
        height, width = (int(v) for v in arrays["svgf_shape"])
    except (KeyError, ValueError, TypeError):
        raise InputError("not an svgf history file (no svgf_* metadata)", str(path)) from None
    state = {
        name[len(_STATE_PREFIX) :]: value
        for name, value in arrays.items()
        if name.startswith(_STATE_PREFIX)
    }
    return HistoryFile(path, state, last_frame, params_json, width, height)


def save_history(
    path: Path,
    state: Mapping[str, np.ndarray],
    last_frame: int,
    params: SVGFParams,
    shape: tuple[int, int],
    last_input: Path,
) -> None:
    """Write the Denoiser state atomically (temp name, then rename)."""
    payload = {f"{_STATE_PREFIX}{k}": np.asarray(v) for k, v in state.items()}
    payload["svgf_last_frame"] = np.array(last_frame, dtype=np.int64)
    payload["svgf_params"] = np.array(params.to_json())
    payload["svgf_shape"] = np.array(shape, dtype=np.int64)
    payload["svgf_version"] = np.array(__version__)
    payload["svgf_input"] = np.array(str(last_input))
    from svgf_cli.io.atomic import atomic_target

    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        with atomic_target(path) as tmp, open(tmp, "wb") as handle:
            np.savez(handle, **payload)
    except OSError as exc:
        raise SvgfError(f"cannot write history file: {exc.strerror or exc}", str(path)) from None


def check_history_params(history: HistoryFile, params: SVGFParams) -> None:
    """Refuse a state computed with other parameters (exit 2), naming what differs."""
    if history.params_json == params.to_json():
        return
    try:
        saved = json.loads(history.params_json)
    except ValueError:
        saved = {}
    current = json.loads(params.to_json())
    diffs = [
        f"{k} {saved.get(k)!r} (saved) != {current.get(k)!r}"
        for k in sorted(set(saved) | set(current))
        if saved.get(k) != current.get(k)
    ]
    raise UsageError(
        "history was saved with different parameters: " + ("; ".join(diffs) or "unknown"),
        str(history.path),
    )


def pending_tasks(tasks: Sequence[FrameTask], overwrite: bool) -> list[FrameTask]:
    """Retry-safe view of a chunk: outputs that already exist are not written again.

    Writes are atomic, so an existing output is a complete one; with ``overwrite`` every
    output is written (deterministic, so a retry rewrites identical bytes).
    """
    if overwrite:
        return list(tasks)
    return [
        t
        if t.output is None or not t.output.exists()
        else FrameTask(t.frame, t.input, None, t.reset_history)
        for t in tasks
    ]


def trim_tail(tasks: Sequence[FrameTask]) -> list[FrameTask]:
    """Drop history-only frames after the last written one (nothing depends on them)."""
    last = max((i for i, t in enumerate(tasks) if t.output is not None), default=-1)
    return list(tasks[: last + 1])


class WarmupCount:
    """Warm-up frames processed so far, reported as ``Warmup: n/total``."""

    def __init__(self, progress: Progress, total: int) -> None:
        self._progress = progress
        self.total = total
        self.seen = 0

    def frame_done(self, frame: int) -> None:
        self.seen += 1
        self._progress.warmup(frame, self.seen, self.total)


# -- the output of one frame ----------------------------------------------------------------


def output_attributes(config: RunConfig, task: FrameTask) -> dict[str, Any]:
    """The ``svgf/*`` provenance added to the colour's part (every input attribute is kept
    by the writer as it is).

    Everything here is a function of the options and the frame, never of the run (no
    timestamps, no host names), so a resumed or retried frame is byte-identical.
    """
    return {
        "svgf/version": __version__,
        "svgf/preset": config.preset,
        "svgf/params": config.params.to_json(),
        "svgf/frame": int(task.frame),
        "svgf/input": str(task.input),
        "svgf/warmup": config.warmup_label,
        "svgf/kind": "denoised",  # an input's svgf/kind ("input") would mislabel it
    }


@dataclass
class OutputFrame:
    """One frame ready for the writer thread: the file layout and the new planes."""

    source: Any  # svgf_cli.io.source.SourceFile
    part_index: int
    channels: dict[str, np.ndarray]
    attributes: dict[str, Any]
    keep_only: set[str] | None
    warnings: list[str]


def _colour_layout(
    result: Any, frame_shape: tuple[int, int], input_path: Path
) -> tuple[Any, int, tuple[str, ...]]:
    """(source, part index, channel names) the denoised colour is written to.

    The input's colour layer when it has one (``colour_channels``), else ``R,G,B`` added to
    the part holding the filtered signals. A reader without a decoded file (stand-ins in
    tests) gets a one-part layout with its alpha.
    """
    from svgf_cli.io.output import synthetic_source

    source = getattr(result, "source", None)
    if source is None:
        info = result.info
        source = synthetic_source(
            input_path,
            frame_shape,
            getattr(info, "attributes", None),
            getattr(info, "compression", None) or "zip",
            getattr(result, "alpha", None),
        )
    names = getattr(result, "colour_channels", None)
    anchor: str | None = names[0] if names else None
    if anchor is None:
        resolved = getattr(result, "resolved", None)
        signal = resolved[resolved.signal_roles[0]] if resolved is not None else None
        anchor = signal[0] if signal else None
    part = source.part_holding(anchor) if anchor else None
    return source, (part.index if part is not None else 0), tuple(names or ("R", "G", "B"))


def _layer_alpha(name: str) -> str:
    """``ViewLayer.Combined.R`` -> ``ViewLayer.Combined.A``; ``R`` -> ``A``."""
    layer, dot, _ = name.rpartition(".")
    return f"{layer}{dot}A"


def build_output(
    result: Any, denoised: Any, config: RunConfig, task: FrameTask
) -> OutputFrame:
    """Everything the writer needs for one frame, converted by the output value policy
    (non-finite -> 0, then half clamped to +-65504; each counted for a warning)."""
    from svgf_cli.io.output import prepare_colour

    color = denoised.color
    source, part_index, names = _colour_layout(result, color.shape[1:], task.input)
    part = source.parts[part_index]
    stored = part.channels.get(names[0])
    half = not config.float_colour and (stored is None or stored.type_name == "half")
    prepared = prepare_colour(color, half)
    warnings = []
    if prepared.nonfinite:
        warnings.append(f"{prepared.nonfinite} non-finite output value(s) set to 0")
    if prepared.clamped:
        warnings.append(
            f"{prepared.clamped} output value(s) beyond the half-float range clamped to "
            "+-65504 (--float keeps them)"
        )
    channels = dict(zip(names, prepared.planes, strict=True))
    if config.debug_aovs:
        for name, plane in denoised.layers.items():
            channels[f"{DEBUG_PREFIX}{name}"] = np.ascontiguousarray(plane, dtype=np.float32)
    keep_only = None
    if config.colour_only:
        keep_only = {_layer_alpha(names[0])} & set(part.channels)
    return OutputFrame(
        source, part_index, channels, output_attributes(config, task), keep_only, warnings
    )


# -- read-ahead -----------------------------------------------------------------------------


def frame_reader(
    config: RunConfig, read: Callable[..., Any] = _default_reader
) -> Callable[[FrameTask], Any]:
    """``read`` of one task's input with the run's options; any failure becomes one
    InputError (exit 3) naming the file."""

    def read_task(task: FrameTask) -> Any:
        try:
            if read is _default_reader:
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
    just filtered, never an older one, and two frames are in memory, not three). Owns its
    thread: leaving the ``with`` block cancels a read not yet started and waits for one
    under way.
    """

    def __init__(
        self, tasks: Sequence[FrameTask], read: Callable[[FrameTask], Any], stats: RunStats,
        after: Callable[[], Future[Any] | None] | None = None,
    ) -> None:
        self._tasks = tasks
        self._read = read
        self._stats = stats
        self._after = after
        self._position = 0
        self._executor = ThreadPoolExecutor(
            1, thread_name_prefix="svgf-read", initializer=_block_signals
        )
        self._upcoming = self._submit(0)

    def _submit(self, position: int) -> Future[tuple[Any, float]] | None:
        if position >= len(self._tasks):
            return None
        waiting = self._after() if self._after is not None else None
        return self._executor.submit(self._timed_read, self._tasks[position], waiting)

    def _timed_read(self, task: FrameTask, waiting: Future[Any] | None) -> tuple[Any, float]:
        if waiting is not None:
            wait((waiting,))  # its outcome is its owner's to report
        started = time.perf_counter()
        result = self._read(task)
        return result, time.perf_counter() - started

    def __iter__(self) -> ReadAhead:
        return self

    def __next__(self) -> tuple[FrameTask, Any, float]:
        # No generator: its suspended frame would hold the previous result a frame longer.
        if self._upcoming is None:
            raise StopIteration
        task = self._tasks[self._position]
        wait_started = time.perf_counter()
        result, seconds = self._upcoming.result()
        self._stats.wait_read_seconds += time.perf_counter() - wait_started
        self._stats.read_seconds += seconds
        self._position += 1
        # Prefetch the next frame while this one is filtered (queue depth one).
        self._upcoming = self._submit(self._position)
        return task, result, seconds

    def close(self) -> None:
        self._upcoming = None
        self._executor.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> ReadAhead:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


# -- filter ---------------------------------------------------------------------------------


def _denoiser_warnings(denoised: Any) -> list[str]:
    """What the Denoiser counted in this frame (``DenoisedFrame.warnings()``), if it says."""
    warnings = getattr(denoised, "warnings", None)
    if callable(warnings):
        warnings = warnings()
    return [str(w) for w in warnings or ()]


class FrameFilter:
    """The Denoiser of one pass, and the checks a frame passes before it is filtered.

    The first frame fixes the resolution, is checked against a loaded history file and then
    gets that history; every later frame must have the same resolution (InputError, exit 3,
    naming both sizes). Warnings of the reader and of the Denoiser are reported against the
    frame's input. Frames processed, the last frame and compute seconds go to ``stats``.
    """

    def __init__(
        self,
        config: RunConfig,
        progress: Progress,
        stats: RunStats,
        make_denoiser: Callable[[SVGFParams, bool], DenoiserLike],
        *,
        history: HistoryFile | None = None,
        on_first_frame: Callable[[Any], None] | None = None,
    ) -> None:
        try:
            self.denoiser = make_denoiser(config.params, config.debug_aovs)
        except ValueError as exc:
            raise UsageError(f"invalid SVGF parameters: {exc}") from None
        if history is not None:
            check_history_params(history, config.params)
        self._params = config.params
        self._progress = progress
        self._stats = stats
        self._history = history
        self._on_first_frame = on_first_frame
        self.size: tuple[int, int] | None = None  # (width, height) of the first frame
        self._size_source: Path | None = None

    def admit(self, task: FrameTask, result: Any) -> None:
        """Report the read's warnings and check the frame's resolution."""
        for message in result.warnings:
            text = str(message)
            self._progress.warning(text if str(task.input) in text else f"{task.input}: {text}")
        frame_size = (result.frame.width, result.frame.height)
        if self.size is None:
            self._first_frame(task, result, frame_size)
        elif frame_size != self.size:
            raise InputError(
                f"resolution changed from {self.size[0]}x{self.size[1]} ({self._size_source}) "
                f"to {frame_size[0]}x{frame_size[1]}",
                str(task.input),
            )

    def _first_frame(self, task: FrameTask, result: Any, frame_size: tuple[int, int]) -> None:
        self.size, self._size_source = frame_size, task.input
        if self._on_first_frame is not None:
            self._on_first_frame(result)
        history = self._history
        if history is None:
            return
        if (history.width, history.height) != frame_size:
            raise InputError(
                f"resolution {frame_size[0]}x{frame_size[1]} does not match the "
                f"history in {history.path} ({history.width}x{history.height})",
                str(task.input),
            )
        try:
            self.denoiser.load_state(history.state)
        except ValueError as exc:
            raise InputError(f"cannot use history: {exc}", str(history.path)) from None

    def process(
        self, task: FrameTask, result: Any, step: Callable[[Any], Any] | None = None
    ) -> tuple[Any, float]:
        """Filter an admitted frame (after a history reset when ``task`` asks for one), let
        go of its input planes, report the Denoiser's warnings. Returns the denoised frame
        and the seconds the filter took. ``step`` replaces ``denoiser.process`` (a pass of
        a bidirectional run)."""
        if task.reset_history:
            self.denoiser.reset()
        started = time.perf_counter()
        try:
            denoised = (step or self.denoiser.process)(result.frame)
        except ValueError as exc:
            raise InputError(str(exc), str(task.input)) from None
        seconds = time.perf_counter() - started
        self._stats.compute_seconds += seconds
        self._stats.frames_processed += 1
        self._stats.last_frame = task.frame
        # The filter has what it keeps: let this frame's planes go now rather than
        # while the next frame is read (memory holds fewer frames at once).
        with contextlib.suppress(AttributeError):
            result.frame = None
        for message in _denoiser_warnings(denoised):
            self._progress.warning(f"{task.input}: {message}")
        return denoised, seconds

    def save_history(self, path: Path, last_input: Path) -> None:
        """Save the Denoiser's state after the last frame processed (none: nothing)."""
        if self.size is None or self._stats.last_frame is None:
            return
        width, height = self.size
        state = self.denoiser.state()
        save_history(path, state, self._stats.last_frame, self._params, (height, width), last_input)


# -- write-behind ---------------------------------------------------------------------------


def frame_writer(config: RunConfig) -> Callable[[FrameTask, OutputFrame], list[str]]:
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

    def __init__(
        self,
        write: Callable[[FrameTask, OutputFrame], list[str]],
        progress: Progress,
        stats: RunStats,
    ) -> None:
        self._write = write
        self._progress = progress
        self._stats = stats
        self._executor = ThreadPoolExecutor(
            1, thread_name_prefix="svgf-write", initializer=_block_signals
        )
        self._pending: tuple[FrameTask, Future[tuple[float, list[str]]], float] | None = None

    def submit_denoised(self, task: FrameTask, result: Any, denoised: Any, config: RunConfig,
                        started: float) -> None:
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


# -- the driver -----------------------------------------------------------------------------


def run_sequence(
    tasks: Sequence[FrameTask],
    config: RunConfig,
    progress: Progress,
    *,
    stop: StopFlag | None = None,
    history: HistoryFile | None = None,
    save_history_to: Path | None = None,
    warmup_total: int | None = None,
    on_first_frame: Callable[[Any], None] | None = None,
    make_denoiser: Callable[[SVGFParams, bool], DenoiserLike] = _default_denoiser,
    read: Callable[[Path, Any], Any] = _default_reader,
) -> RunStats:
    """Run the Denoiser over ``tasks`` in order, writing the frames that have an output.

    Raises InputError (exit 3) for an unreadable frame or a resolution change (the frames
    before it are written, nothing for it), UsageError for a history file from other
    parameters, Interrupted after a SIGINT/SIGTERM once the frame in flight is written.
    """
    # Frame-sized arrays go back to the system when freed: without this the peak memory
    # grows with the frames run (svgf_cli.heap).
    map_large_blocks()
    if config.params.bidirectional:
        from svgf_cli.bidir import run_bidirectional

        return run_bidirectional(tasks, config, progress, stop=stop,
                                 on_first_frame=on_first_frame, read=read)
    stats = RunStats()
    if not tasks:
        return stats
    started = time.perf_counter()
    frames = FrameFilter(
        config, progress, stats, make_denoiser, history=history, on_first_frame=on_first_frame
    )
    if warmup_total is None:
        warmup_total = sum(1 for t in tasks if t.output is None)
    warmup = WarmupCount(progress, warmup_total)
    with (
        ReadAhead(tasks, frame_reader(config, read), stats) as reads,
        WriteBehind(frame_writer(config), progress, stats) as writes,
    ):
        frame_started = time.perf_counter()
        for task, result, read_seconds in reads:
            frames.admit(task, result)
            writes.poll()  # report a finished write now rather than a frame later
            denoised, compute_seconds = frames.process(task, result)
            if task.output is None:
                warmup.frame_done(task.frame)
            else:
                # The writer thread reads these planes while the next frame is filtered: safe
                # because DenoisedFrame arrays are fresh per frame, not the denoiser's buffers.
                writes.submit_denoised(task, result, denoised, config, frame_started)
                # Only the writer holds this frame now: memory is freed when it is done.
                denoised = result = None
            frame_started = time.perf_counter()
            progress.detail(
                f"frame {task.frame}: read {read_seconds:.3f} s, compute {compute_seconds:.3f} s"
            )
            if stop:
                writes.finish()
                raise _interrupted(stop, task)
        writes.finish()
    if save_history_to is not None:
        frames.save_history(save_history_to, tasks[-1].input)
    stats.wall_seconds = time.perf_counter() - started
    return stats


def _interrupted(stop: StopFlag, last: FrameTask) -> Interrupted:
    assert stop.signum is not None
    return Interrupted(
        stop.signum,
        f"frame {last.frame} was the last one finished; rerun with --skip-existing to resume",
    )
