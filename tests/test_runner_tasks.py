"""The runner's task-list helpers and its interruption error (no EXR, no numba)."""

from __future__ import annotations

import pickle
import signal
from pathlib import Path

import pytest

from svgf_cli.errors import EXIT_SIGINT, EXIT_SIGTERM
from svgf_cli.runner import FrameTask, Interrupted, trim_tail


def _tasks(written: list[bool]) -> list[FrameTask]:
    return [FrameTask(f, Path(f"in.{f}.exr"), Path(f"out.{f}.exr") if w else None)
            for f, w in enumerate(written, 1)]


@pytest.mark.parametrize(
    ("written", "kept"),
    [([False, True, False, False], 2), ([True, False, True], 3), ([False, False, False], 0),
     ([], 0)],
)
def test_trim_tail_keeps_frames_up_to_the_last_written_one(written, kept) -> None:
    # History-only frames after the last output are never needed: reading them is waste.
    tasks = _tasks(written)
    assert trim_tail(tasks) == tasks[:kept]


@pytest.mark.parametrize(("signum", "code"),
                         [(signal.SIGINT, EXIT_SIGINT), (signal.SIGTERM, EXIT_SIGTERM)])
def test_interrupted_keeps_its_exit_code_through_pickling(signum, code) -> None:
    # Dask ships a chunk's Interrupted back to the client by pickling it: the exit code the
    # farm sees must stay the signal's.
    error = Interrupted(signum, "stopped after frame 3")
    again = pickle.loads(pickle.dumps(error))
    assert (error.exit_code, again.exit_code) == (code, code)
    assert again.signum == signum and str(again) == str(error)
