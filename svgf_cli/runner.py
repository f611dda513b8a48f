"""The sequential driver shared by local runs, local chunks and Dask tasks.

Given the ordered frames of one chunk (``FrameTask``: frame number, input path, output path
or None for a history-only frame), it runs the Denoiser frame by frame. The next frame's read
runs in a reader thread while the current frame is filtered, and the previous frame's write
runs in a writer thread, each at most one deep: memory holds about three frames whatever the
sequence length. SIGINT/SIGTERM finish the frame in flight and then stop (exit 130/143).
"""

from __future__ import annotations

import contextlib
import json
import signal
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from svgf_cli import __version__
from svgf_cli.errors import EXIT_SIGINT, EXIT_SIGTERM, InputError, SvgfError, UsageError
from svgf_cli.filters.params import SVGFParams
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


@dataclass
class RunStats:
    """What a run did and where its time went (seconds, summed over frames)."""

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


# -- history files ------------------------------------------------------------------------

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


# -- the driver -----------------------------------------------------------------------------


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


def _denoiser_warnings(denoised: Any) -> list[str]:
    """What the Denoiser counted in this frame (``DenoisedFrame.warnings()``), if it says."""
    warnings = getattr(denoised, "warnings", None)
    if callable(warnings):
        warnings = warnings()
    return [str(w) for w in warnings or ()]


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
    from svgf_cli.io.exr import io_threads
    from svgf_cli.io.output import write_output

    stats = RunStats()
    if not tasks:
        return stats
    started = time.perf_counter()
    try:
        denoiser = make_denoiser(config.params, config.debug_aovs)
    except ValueError as exc:
        raise UsageError(f"invalid SVGF parameters: {exc}") from None
    if warmup_total is None:
        warmup_total = sum(1 for t in tasks if t.output is None)
    warmup_seen = 0
    size: tuple[int, int] | None = None
    size_source: Path | None = None
    if history is not None:
        check_history_params(history, config.params)

    def timed_read(task: FrameTask) -> tuple[Any, float]:
        t0 = time.perf_counter()
        try:
            if read is _default_reader:
                result = read(task.input, config.mapping, passthrough=not config.colour_only)
            else:
                result = read(task.input, config.mapping)
        except SvgfError:
            raise
        except FileNotFoundError:
            raise InputError("input file not found", str(task.input)) from None
        except (OSError, RuntimeError, ValueError) as exc:
            raise InputError(f"cannot read: {exc}", str(task.input)) from None
        return result, time.perf_counter() - t0

    def timed_write(task: FrameTask, output: OutputFrame) -> tuple[float, list[str]]:
        t0 = time.perf_counter()
        assert task.output is not None
        notes = write_output(
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
        return time.perf_counter() - t0, notes

    reader = ThreadPoolExecutor(1, thread_name_prefix="svgf-read", initializer=_block_signals)
    writer = ThreadPoolExecutor(1, thread_name_prefix="svgf-write", initializer=_block_signals)
    pending: tuple[FrameTask, Future[tuple[float, list[str]]], float] | None = None

    def finish_pending() -> None:
        nonlocal pending
        if pending is None:
            return
        task, future, frame_started = pending
        pending = None
        seconds, notes = future.result()
        stats.write_seconds += seconds
        for note in notes:
            progress.warning(f"{task.output}: {note}")
        stats.frames_written += 1
        stats.written.append(task.frame)
        progress.frame_done(task.frame, time.perf_counter() - frame_started)

    try:
        next_read: Future[tuple[Any, float]] | None = reader.submit(timed_read, tasks[0])
        frame_started = time.perf_counter()
        for position, task in enumerate(tasks):
            assert next_read is not None
            t_wait = time.perf_counter()
            result, read_seconds = next_read.result()
            stats.wait_read_seconds += time.perf_counter() - t_wait
            stats.read_seconds += read_seconds
            # Prefetch the next frame while this one is filtered (queue depth one).
            next_read = (
                reader.submit(timed_read, tasks[position + 1])
                if position + 1 < len(tasks)
                else None
            )
            frame = result.frame
            for message in result.warnings:
                text = str(message)
                progress.warning(text if str(task.input) in text else f"{task.input}: {text}")
            frame_size = (frame.width, frame.height)
            if size is None:
                size, size_source = frame_size, task.input
                if on_first_frame is not None:
                    on_first_frame(result)
                if history is not None:
                    if (history.width, history.height) != frame_size:
                        raise InputError(
                            f"resolution {frame_size[0]}x{frame_size[1]} does not match the "
                            f"history in {history.path} ({history.width}x{history.height})",
                            str(task.input),
                        )
                    try:
                        denoiser.load_state(history.state)
                    except ValueError as exc:
                        raise InputError(f"cannot use history: {exc}", str(history.path)) from None
            elif frame_size != size:
                raise InputError(
                    f"resolution changed from {size[0]}x{size[1]} ({size_source}) to "
                    f"{frame_size[0]}x{frame_size[1]}",
                    str(task.input),
                )
            if pending is not None and pending[1].done():
                finish_pending()  # report a finished write now rather than a frame later
            if task.reset_history:
                denoiser.reset()
            t0 = time.perf_counter()
            try:
                denoised = denoiser.process(frame)
            except ValueError as exc:
                raise InputError(str(exc), str(task.input)) from None
            compute_seconds = time.perf_counter() - t0
            stats.compute_seconds += compute_seconds
            stats.frames_processed += 1
            stats.last_frame = task.frame
            # The filter has what it keeps: let this frame's planes go now rather than
            # while the next frame is read (memory holds fewer frames at once).
            frame = None
            with contextlib.suppress(AttributeError):
                result.frame = None
            for message in _denoiser_warnings(denoised):
                progress.warning(f"{task.input}: {message}")

            if task.output is None:
                warmup_seen += 1
                progress.warmup(task.frame, warmup_seen, warmup_total)
                frame_started = time.perf_counter()
            else:
                # The writer thread reads these planes while the next frame is filtered: safe
                # because DenoisedFrame arrays are fresh per frame, not the denoiser's buffers.
                output = build_output(result, denoised, config, task)
                for message in output.warnings:
                    progress.warning(f"{task.input}: {message}")
                # One write in flight: wait for the previous one before queueing this one.
                finish_pending()
                pending = (task, writer.submit(timed_write, task, output), frame_started)
                # Only the writer holds this frame now: memory is freed when it is done.
                output = denoised = result = None
                frame_started = time.perf_counter()
            progress.detail(
                f"frame {task.frame}: read {read_seconds:.3f} s, compute {compute_seconds:.3f} s"
            )
            if stop:
                finish_pending()
                assert stop.signum is not None
                raise Interrupted(
                    stop.signum,
                    f"frame {task.frame} was the last one finished; "
                    "rerun with --skip-existing to resume",
                )
        finish_pending()
    finally:
        # Never leave a write half-done: wait for it even when unwinding an error.
        if pending is not None:
            # The original error is the one to report.
            with contextlib.suppress(Exception):
                pending[1].result()
        reader.shutdown(wait=True, cancel_futures=True)
        writer.shutdown(wait=True)
    if save_history_to is not None and size is not None and stats.last_frame is not None:
        save_history(
            save_history_to,
            denoiser.state(),
            stats.last_frame,
            config.params,
            (size[1], size[0]),
            tasks[-1].input,
        )
    stats.wall_seconds = time.perf_counter() - started
    return stats


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
