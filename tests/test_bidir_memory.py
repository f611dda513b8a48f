"""A bidirectional run's memory is flat in the sequence length (docs/bidirectional.md#cost).

Two parts, each checked on its own: what the run keeps alive (read frames and forward
states: one kept per frame would grow with the length), and the heap policy that gives
freed frame-sized blocks back to the system (``svgf_cli.heap``: without it the resident
size grows with the frames run although nothing more is alive).
"""

from __future__ import annotations

import io
import threading
import time
import weakref
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_cli_support import exit_code, write_sequence

from svgf_cli import heap
from svgf_cli.filters.params import resolve_params
from svgf_cli.io.layers import build_mapping
from svgf_cli.io.spill import ScratchFolder
from svgf_cli.progress import Progress
from svgf_cli.run import bidirectional
from svgf_cli.run.chunk import run_sequence
from svgf_cli.run.tasks import FrameTask, RunConfig
from svgf_cli.run.workers import default_reader, frame_writer

FRAMES = range(1, 9)


class _Alive:
    """Weak references to what a run read, and the most of them alive when a read ends
    (a frame or state kept per frame would make it grow with the length)."""

    def __init__(self) -> None:
        self._refs: list[weakref.ref[Any]] = []
        self._lock = threading.Lock()
        self.most = 0

    def add(self, thing: Any) -> None:
        with self._lock:
            self.most = max(self.most, sum(r() is not None for r in self._refs))
            self._refs.append(weakref.ref(thing))



def _run_bidirectional(tmp_path: Path, read: Any) -> None:
    """A bidirectional run of the default preset over FRAMES of ``tmp_path / "seq"``, frames
    read with ``read``; every frame written."""
    config = RunConfig(params=resolve_params("default", bidirectional=True), preset="default",
                       mapping=build_mapping("svgf"), scratch_dir=tmp_path / "scratch")
    tasks = [FrameTask(f, tmp_path / "seq" / f"in.{f:04d}.exr", tmp_path / f"o.{f:04d}.exr")
             for f in FRAMES]
    quiet = Progress("lines", len(FRAMES), quiet=True, out=io.StringIO(), err=io.StringIO())
    stats = run_sequence(tasks, config, quiet, read=read)
    assert stats.frames_written == len(FRAMES)

def test_a_bidirectional_run_holds_a_bounded_number_of_frames_and_states(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    write_sequence(tmp_path / "seq", FRAMES)
    frames, states = _Alive(), _Alive()

    def read(path: Path, mapping: Any, **kwargs: Any) -> Any:
        result = default_reader(path, mapping, **kwargs)
        frames.add(result)
        return result

    def read_state(self: ScratchFolder, frame: int) -> Any:
        planes, factors = spill_read(self, frame)
        states.add(next(iter(planes.values())))
        return planes, factors

    spill_read = ScratchFolder.read
    monkeypatch.setattr(ScratchFolder, "read", read_state)
    _run_bidirectional(tmp_path, read)
    # Per pass: the frame filtered, the one written (reverse pass) and the one being read.
    assert 1 <= frames.most <= 2
    # A packed state is let go once unpacked, before the next one is read.
    assert states.most == 0


def test_the_reverse_pass_never_reads_a_frame_beside_two_others(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A frame with its passthrough layers is the largest thing in flight: the reverse
    pass reads frame ``t - 1`` only once the write of ``t + 1`` is done, so a read may
    overlap the write of ``t`` (the frame just filtered) but never an older one."""
    write_sequence(tmp_path / "seq", FRAMES)
    lock = threading.Lock()
    writing: set[int] = set()
    reads: list[tuple[int, set[int]]] = []

    def writer(config: RunConfig) -> Any:
        write = frame_writer(config)

        def slow_write(task: FrameTask, output: Any) -> Any:
            with lock:
                writing.add(task.frame)
            try:
                time.sleep(0.05)  # long enough for an ungated read to start meanwhile
                return write(task, output)
            finally:
                with lock:
                    writing.discard(task.frame)

        return slow_write

    def read(path: Path, mapping: Any, **kwargs: Any) -> Any:
        with lock:
            reads.append((int(Path(path).name.split(".")[1]), set(writing)))
        return default_reader(path, mapping, **kwargs)

    monkeypatch.setattr(bidirectional, "frame_writer", writer)
    _run_bidirectional(tmp_path, read)
    assert len(reads) == 2 * len(FRAMES)  # both passes read every frame
    assert all(written <= {frame + 1} for frame, written in reads), reads


def _resident_bytes() -> int:
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * 4096


@pytest.mark.skipif(not heap._glibc(), reason="the heap policy is glibc's")
def test_freed_frame_planes_go_back_to_the_system(tmp_path: Path) -> None:
    """After the CLI has run, a freed 1080p plane is unmapped at once, also where glibc
    alone would have kept it in the heap (its dynamic threshold raised by a larger block
    freed before, a live block after it)."""
    write_sequence(tmp_path / "seq", range(1, 3))
    assert exit_code(["denoise", tmp_path / "seq" / "in.####.exr", "-o",
                      tmp_path / "o.####.exr", "-q"]) == 0
    larger = np.ones(4 << 20, np.float32)  # 16 MB, freed: raises a dynamic threshold
    del larger
    planes = [np.ones((1080, 1920), np.float32) for _ in range(4)]
    guard = np.ones(16 << 10, np.float32)  # 64 KB, live: the planes are not the heap's top
    before = _resident_bytes()
    freed = sum(p.nbytes for p in planes)
    del planes
    assert before - _resident_bytes() > 0.9 * freed
    assert guard.sum() > 0
