"""The sequential driver, with a stand-in denoiser and reader (no numba, no EXR reads).

These pin the driver's own contract: read-ahead depth, signal handling, errors mid-sequence,
history files. The real Denoiser is exercised end to end in test_cli_*.py.
"""

from __future__ import annotations

import dataclasses
import io
import os
import signal
import threading
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from svgf_cli.errors import EXIT_SIGINT, EXIT_SIGTERM, InputError, UsageError
from svgf_cli.filters.params import SVGFParams
from svgf_cli.frame import DenoisedFrame, Frame
from svgf_cli.progress import Progress
from svgf_cli.run.chunk import run_sequence
from svgf_cli.run.history import load_history
from svgf_cli.run.output import OutputFrame
from svgf_cli.run.stop import Interrupted, stop_on_signals
from svgf_cli.run.tasks import FrameTask, RunConfig, RunStats, pending_tasks
from svgf_cli.run.workers import ReadAhead, WriteBehind

W, H = 8, 6


def make_frame(value: float, width: int = W, height: int = H) -> Frame:
    plane = np.full((3, height, width), value, np.float32)
    return Frame.combined(
        plane,
        albedo=np.ones((3, height, width), np.float32),
        normal=np.zeros((3, height, width), np.float32),
        depth=np.ones((height, width), np.float32),
        motion=np.zeros((2, height, width), np.float32),
        mesh_id=np.zeros((height, width), np.int32),
    )


class FakeDenoiser:
    """Exponential moving average: output depends on every earlier frame."""

    def __init__(self, params: SVGFParams, debug: bool) -> None:
        self.history: np.ndarray | None = None
        self.frames_processed = 0
        self.on_process: Any = None

    def process(self, frame: Frame) -> DenoisedFrame:
        current = frame.signal("color").radiance
        if self.on_process is not None:
            self.on_process(self.frames_processed)
        color = current if self.history is None else 0.8 * self.history + 0.2 * current
        self.history = color.copy()
        self.frames_processed += 1
        return DenoisedFrame(color=color.copy(), layers={})

    def reset(self) -> None:
        self.history = None

    def state(self) -> dict[str, np.ndarray]:
        return {"history": self.history.copy()} if self.history is not None else {}

    def load_state(self, state: dict[str, np.ndarray]) -> None:
        self.history = state["history"].copy()


class FakeReader:
    def __init__(self, sizes: dict[int, tuple[int, int]] | None = None) -> None:
        self.started: list[int] = []
        self.sizes = sizes or {}
        self.lock = threading.Lock()

    def __call__(self, path: Path, mapping: Any) -> Any:
        frame_no = int(path.stem.split(".")[-1])
        with self.lock:
            self.started.append(frame_no)
        if "bad" in path.name:
            raise InputError("not an OpenEXR file (bad magic number)", str(path))
        width, height = self.sizes.get(frame_no, (W, H))
        return SimpleNamespace(
            frame=make_frame(float(frame_no), width, height),
            alpha=None,
            info=SimpleNamespace(attributes={"shot": "x"}, compression="zip"),
            warnings=[],
        )


CONFIG = RunConfig(params=SVGFParams(), preset="paper", mapping=SimpleNamespace())


def quiet() -> Progress:
    return Progress("lines", 0, quiet=True, out=io.StringIO(), err=io.StringIO())


def tasks_for(tmp_path: Path, frames: range, warmup: int = 0) -> list[FrameTask]:
    return [
        FrameTask(
            f,
            tmp_path / f"in.{f:04d}.exr",
            None if i < warmup else tmp_path / "out" / f"out.{f:04d}.exr",
        )
        for i, f in enumerate(frames)
    ]


def run(tasks: list[FrameTask], reader: FakeReader | None = None, **kwargs: Any) -> Any:
    (tasks[0].input.parent / "out").mkdir(exist_ok=True)
    factory = kwargs.pop("factory", FakeDenoiser)
    return run_sequence(
        tasks,
        CONFIG,
        kwargs.pop("progress", quiet()),
        make_denoiser=factory,
        read=reader or FakeReader(),
        **kwargs,
    )


def test_reads_run_at_most_one_frame_ahead(tmp_path: Path) -> None:
    reader = FakeReader()
    ahead: list[int] = []

    def factory(params: SVGFParams, debug: bool) -> FakeDenoiser:
        d = FakeDenoiser(params, debug)
        d.on_process = lambda n: ahead.append(len(reader.started) - n)
        return d

    stats = run(tasks_for(tmp_path, range(1, 21), warmup=3), reader, factory=factory)
    assert stats.frames_processed == 20 and stats.frames_written == 17
    # While frame n is filtered, frames n and n+1 (the prefetch) may have been read: memory
    # is bounded by a constant number of frames, whatever the sequence length.
    assert max(ahead) <= 2
    assert reader.started == list(range(1, 21))
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [
        f"out.{f:04d}.exr" for f in range(4, 21)
    ]


@pytest.mark.parametrize("low_memory", [False, True])
def test_low_memory_reads_no_frame_beside_the_filter(tmp_path: Path, low_memory: bool) -> None:
    """--low-memory: while frame n is filtered no later frame has been read (the read of
    n + 1 starts once n is handed to the writer); by default n + 1 is read meanwhile. The
    same frames are written either way."""
    reader = FakeReader()
    ahead: list[int] = []

    def factory(params: SVGFParams, debug: bool) -> FakeDenoiser:
        d = FakeDenoiser(params, debug)

        def slow_filter(n: int) -> None:
            threading.Event().wait(0.03)  # an eager read of n + 1 has started meanwhile
            ahead.append(len(reader.started) - n)

        d.on_process = slow_filter
        return d

    tasks = tasks_for(tmp_path, range(1, 8), warmup=2)
    (tmp_path / "out").mkdir()
    config = dataclasses.replace(CONFIG, low_memory=low_memory)
    stats = run_sequence(tasks, config, quiet(), make_denoiser=factory, read=reader)
    assert stats.frames_written == 5 and reader.started == list(range(1, 8))
    if low_memory:
        assert ahead == [1] * 7
    else:
        assert ahead[:-1] == [2] * 6 and ahead[-1] == 1


@pytest.mark.parametrize(
    ("signum", "code"), [(signal.SIGINT, EXIT_SIGINT), (signal.SIGTERM, EXIT_SIGTERM)]
)
def test_signal_finishes_the_frame_in_flight(tmp_path: Path, signum: int, code: int) -> None:
    def factory(params: SVGFParams, debug: bool) -> FakeDenoiser:
        d = FakeDenoiser(params, debug)
        # The signal lands while frame 4 (index 3) is being filtered.
        d.on_process = lambda n: os.kill(os.getpid(), signum) if n == 3 else None
        return d

    # What the test process was started with: Python's handler for SIGINT, or SIG_IGN for a
    # background job of a non-interactive shell (stop_on_signals catches it either way).
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    with stop_on_signals() as stop, pytest.raises(Interrupted) as raised:
        run(tasks_for(tmp_path, range(1, 11)), factory=factory, stop=stop)
    assert raised.value.exit_code == code
    assert "frame 4 was the last one finished" in str(raised.value)
    written = sorted(p.name for p in (tmp_path / "out").iterdir())
    # Frame 4 was in flight: it is finished and complete; nothing after it; no temp files.
    assert written == [f"out.{f:04d}.exr" for f in range(1, 5)]
    assert {s: signal.getsignal(s) for s in before} == before  # handlers given back


def test_a_failed_run_returns_only_after_the_read_in_flight(tmp_path: Path) -> None:
    # When a frame fails, the next frame's read (prefetched) may be under way: the run must
    # not return while it still touches the input (a farm moves or deletes it next).
    finished: list[int] = []

    class SlowReader(FakeReader):
        def __call__(self, path: Path, mapping: Any) -> Any:
            result = super().__call__(path, mapping)
            if int(path.stem.split(".")[-1]) == 3:
                time.sleep(0.3)
                finished.append(3)
            return result

    reader = SlowReader()

    def factory(params: SVGFParams, debug: bool) -> FakeDenoiser:
        d = FakeDenoiser(params, debug)

        def fail_on_frame_2(n: int) -> None:
            if n == 1:
                deadline = time.monotonic() + 5.0
                while 3 not in reader.started and time.monotonic() < deadline:
                    time.sleep(0.005)
                raise RuntimeError("filter failed")

        d.on_process = fail_on_frame_2
        return d

    with pytest.raises(RuntimeError, match="filter failed"):
        run(tasks_for(tmp_path, range(1, 6)), reader, factory=factory)
    assert finished == [3]


def test_bad_frame_stops_with_earlier_frames_written(tmp_path: Path) -> None:
    tasks = tasks_for(tmp_path, range(1, 7))
    tasks[3] = FrameTask(4, tmp_path / "bad.0004.exr", tmp_path / "out" / "out.0004.exr")
    with pytest.raises(InputError, match=r"bad\.0004\.exr: not an OpenEXR file"):
        run(tasks)
    written = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert written == ["out.0001.exr", "out.0002.exr", "out.0003.exr"]


def test_resolution_change_names_both_sizes(tmp_path: Path) -> None:
    reader = FakeReader(sizes={3: (10, 6)})
    with pytest.raises(InputError) as raised:
        run(tasks_for(tmp_path, range(1, 5)), reader)
    message = str(raised.value)
    assert "in.0003.exr" in message and "8x6" in message and "10x6" in message
    assert not (tmp_path / "out" / "out.0003.exr").exists()


def test_wall_time_is_the_run_s_own_duration(tmp_path: Path) -> None:
    # The summary and the farm's reports print it: a duration, within the call's.
    before = time.perf_counter()
    stats = run(tasks_for(tmp_path, range(1, 4)))
    assert 0.0 < stats.wall_seconds <= time.perf_counter() - before
    # Reading, filtering and writing are each part of the run (each on one thread).
    for part in (stats.read_seconds, stats.compute_seconds, stats.write_seconds,
                 stats.wait_read_seconds):
        assert 0.0 <= part <= stats.wall_seconds
    assert stats.compute_seconds > 0.0


def test_each_written_frame_reports_its_own_duration(tmp_path: Path) -> None:
    # The progress line's seconds per frame and the farm's ETA come from these.
    reported: list[float] = []

    class Recording(Progress):
        def frame_done(self, frame: int, seconds: float) -> None:
            reported.append(seconds)
            super().frame_done(frame, seconds)

    progress = Recording("lines", 0, quiet=True, out=io.StringIO(), err=io.StringIO())
    before = time.perf_counter()
    run(tasks_for(tmp_path, range(1, 4)), progress=progress)
    assert len(reported) == 3 and all(0.0 < s <= time.perf_counter() - before for s in reported)


def test_history_round_trip_continues_exactly(tmp_path: Path) -> None:
    full = run(tasks_for(tmp_path, range(1, 9)))
    assert full.frames_written == 8
    reference = {p.name: p.read_bytes() for p in (tmp_path / "out").iterdir()}
    for p in (tmp_path / "out").iterdir():
        p.unlink()
    history = tmp_path / "h.npz"
    first_half = tasks_for(tmp_path, range(1, 5))
    run(first_half, save_history_to=history)
    saved = load_history(history)
    assert saved.last_frame == 4 and (saved.width, saved.height) == (W, H)
    with np.load(history) as payload:  # which input the history follows, for people
        assert str(payload["svgf_input"]) == str(first_half[-1].input)
    run(tasks_for(tmp_path, range(5, 9)), history=saved)
    resumed = {p.name: p.read_bytes() for p in (tmp_path / "out").iterdir()}
    assert resumed == reference


def test_history_from_other_params_is_refused(tmp_path: Path) -> None:
    history = tmp_path / "h.npz"
    run(tasks_for(tmp_path, range(1, 3)), save_history_to=history)
    other = RunConfig(params=SVGFParams(alpha=0.05), preset="paper", mapping=None)
    with pytest.raises(UsageError, match=r"alpha 0\.2 \(saved\) != 0\.05"):
        run_sequence(
            tasks_for(tmp_path, range(3, 5)),
            other,
            quiet(),
            history=load_history(history),
            make_denoiser=FakeDenoiser,
            read=FakeReader(),
        )


def test_history_file_that_is_not_ours(tmp_path: Path) -> None:
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a zip")
    with pytest.raises(InputError, match="junk.npz: cannot read history file"):
        load_history(junk)
    with pytest.raises(InputError, match="history file not found"):
        load_history(tmp_path / "missing.npz")


def test_pending_tasks_skip_existing_outputs(tmp_path: Path) -> None:
    tasks = tasks_for(tmp_path, range(1, 4))
    (tmp_path / "out").mkdir()
    tasks[0].output.write_bytes(b"x")  # type: ignore[union-attr]
    todo = pending_tasks(tasks, overwrite=False)
    assert [t.output is None for t in todo] == [True, False, False]
    assert pending_tasks(tasks, overwrite=True) == tasks


def test_read_ahead_and_write_behind_serve_a_reversed_pass(tmp_path: Path) -> None:
    """The parts a backward pass reuses: reads in the order given, one frame ahead; writes
    one in flight, each reported once and in order."""
    tasks = tasks_for(tmp_path, range(1, 6))[::-1]
    reader = FakeReader()
    stats = RunStats()
    progress = Progress("lines", len(tasks), out=io.StringIO(), err=io.StringIO())
    in_flight: list[int] = []
    most_in_flight = 0

    def write(task: FrameTask, output: OutputFrame) -> list[str]:
        nonlocal most_in_flight
        in_flight.append(task.frame)
        most_in_flight = max(most_in_flight, len(in_flight))
        threading.Event().wait(0.01)  # a write that takes a moment
        in_flight.remove(task.frame)
        return [f"note {task.frame}"]

    ahead = []
    with (
        ReadAhead(tasks, lambda t: reader(t.input, None), stats) as reads,
        WriteBehind(write, progress, stats) as writes,
    ):
        for position, (task, _, _) in enumerate(reads):
            ahead.append(len(reader.started) - position)
            output = OutputFrame(None, 0, {}, {}, None, [])
            writes.submit(task, output, 0.0)
        writes.finish()
    assert reader.started == [5, 4, 3, 2, 1] and max(ahead) <= 2
    assert most_in_flight == 1
    assert stats.written == [5, 4, 3, 2, 1] and stats.frames_written == 5
    lines = progress.out.getvalue().splitlines()
    assert [line.split("(frame ")[1].split(",")[0] for line in lines] == ["5", "4", "3", "2", "1"]
    assert progress.err.getvalue().splitlines()[0] == f"WARNING: {tasks[0].output}: note 5"


def test_read_ahead_not_eager_reads_a_frame_only_when_asked(tmp_path: Path) -> None:
    """``eager=False`` (--low-memory): the next frame's read starts at ``prefetch`` or when
    the frame is asked for, never beside the frame the caller holds; every frame is read
    once and in order, and leaving the block starts no read."""
    tasks = tasks_for(tmp_path, range(1, 6))
    reader = FakeReader()
    seen, held = [], []
    with ReadAhead(tasks, lambda t: reader(t.input, None), RunStats(), eager=False) as reads:
        for position, (task, _, _) in enumerate(reads):
            threading.Event().wait(0.02)  # a read started now would have begun meanwhile
            held.append(len(reader.started))
            seen.append(task.frame)
            if position % 2 == 0:
                reads.prefetch()  # odd positions: asked for by the loop itself
                reads.prefetch()  # once only
            if position == 3:
                break
    assert seen == [1, 2, 3, 4] and held == [1, 2, 3, 4]
    threading.Event().wait(0.05)
    assert reader.started == [1, 2, 3, 4]  # frame 5: never asked for


def test_write_behind_finishes_the_write_in_flight_when_an_error_unwinds(tmp_path: Path) -> None:
    finished: list[int] = []

    def slow_write(task: FrameTask, output: OutputFrame) -> list[str]:
        threading.Event().wait(0.2)
        finished.append(task.frame)
        return []

    task = tasks_for(tmp_path, range(1, 2))[0]
    progress = quiet()
    with pytest.raises(InputError), WriteBehind(slow_write, progress, RunStats()) as writes:
        writes.submit(task, OutputFrame(None, 0, {}, {}, None, []), 0.0)
        raise InputError("a later frame is bad", "in.0002.exr")
    assert finished == [1]  # waited for, not abandoned
    assert progress.done == 0  # and not reported: the error is what the run reports
