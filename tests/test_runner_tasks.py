"""The runner's task-list helpers and its interruption error (no EXR, no numba)."""

from __future__ import annotations

import pickle
import signal
from pathlib import Path

import pytest

from svgf_cli.errors import EXIT_SIGINT, EXIT_SIGTERM
from svgf_cli.run.stop import Interrupted, stop_on_signals
from svgf_cli.run.tasks import FrameTask, trim_tail


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


def test_first_signal_asks_to_stop_and_a_second_one_stops_at_once() -> None:
    # A render-farm kill sends SIGTERM: the frame in flight is finished (the flag is polled
    # between frames); a second signal means "now".
    with stop_on_signals() as stop:
        signal.raise_signal(signal.SIGTERM)
        assert stop and stop.signum == signal.SIGTERM
        with pytest.raises(Interrupted) as raised:
            signal.raise_signal(signal.SIGINT)
    assert raised.value.exit_code == EXIT_SIGINT


def test_immediate_mode_stops_at_the_first_signal() -> None:
    # Distributed runs (Dask) cannot finish a frame in flight on the client: stop at once.
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    with pytest.raises(Interrupted) as raised, stop_on_signals(immediate=True) as stop:
        signal.raise_signal(signal.SIGTERM)
    assert raised.value.exit_code == EXIT_SIGTERM and not stop
    assert {s: signal.getsignal(s) for s in before} == before  # handlers given back
