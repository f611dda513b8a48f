"""Real processes: SIGKILL midway then --skip-existing resume; SIGINT/SIGTERM exit codes.

Each run is paused before it filters its third frame (``svgf_subprocess(pause_before=2)``)
and signalled there, so where it stops does not depend on the machine's speed.
"""

from __future__ import annotations

import json
import signal
import threading
from pathlib import Path

import pytest
from test_cli_support import reference_run, run_cli, sequence_folder, svgf_subprocess

FRAMES = range(1, 13)
WIDTH, HEIGHT = 96, 72
PAUSE_BEFORE = 2  # frames filtered before the signal: 1 and 2; frame 3 is in flight


@pytest.fixture(scope="module")
def sequence(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return sequence_folder(tmp_path_factory, FRAMES, WIDTH, HEIGHT)


@pytest.fixture(scope="module")
def reference(sequence: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    """An uninterrupted run: file name -> file bytes."""
    return {p.name: p.read_bytes() for p in reference_run(tmp_path_factory, sequence).values()}


def start_and_signal_paused(args: list[str], signum: int) -> tuple[int, str]:
    """Run svgf paused before its frame ``PAUSE_BEFORE``; send ``signum`` there."""
    proc = svgf_subprocess([*args, "--progress", "json"], pause_before=PAUSE_BEFORE)
    # Only a hang guard: nothing below waits for a time, only for the child's lines.
    watchdog = threading.Timer(600, proc.kill)
    watchdog.start()
    try:
        assert proc.stdout is not None
        paused = False
        for line in proc.stdout:
            if json.loads(line).get("event") == "paused":
                paused = True
                proc.send_signal(signum)
                break
        proc.stdout.read()
        _, err = proc.communicate()
    finally:
        watchdog.cancel()
    assert paused, err
    return proc.returncode, err


def assert_no_partial_files(folder: Path, reference: dict[str, bytes]) -> list[str]:
    """Every visible output is complete and equal to the reference; returns their names."""
    names = []
    for path in folder.iterdir():
        if path.name.startswith("."):
            continue  # a killed writer's hidden temporary: never matches the output pattern
        # Compare as a bool: pytest's diff of two ~100 kB byte strings takes minutes.
        same = path.read_bytes() == reference[path.name]
        assert same, f"{path.name} differs from the uninterrupted run"
        names.append(path.name)
    return sorted(names)


def test_sigkill_midway_then_resume_equals_uninterrupted_run(
    sequence: Path,
    tmp_path: Path,
    reference: dict[str, bytes],
    capsys: pytest.CaptureFixture[str],
) -> None:
    out = tmp_path / "out"
    args = ["denoise", str(sequence / "in.####.exr"), "-o", str(out / "o.####.exr")]
    code, _ = start_and_signal_paused(args, signal.SIGKILL)
    assert code == -signal.SIGKILL
    done = assert_no_partial_files(out, reference)
    # Frame 1 was written before frame 2 was filtered; frame 2's write may have been in
    # flight when the kill came (its hidden temporary is then left behind).
    assert done in (["o.0001.exr"], ["o.0001.exr", "o.0002.exr"])

    code, stdout, err = run_cli([*args, "--skip-existing"], capsys)
    assert code == 0, err
    assert f"{len(done)} existing skipped" in stdout
    assert assert_no_partial_files(out, reference) == sorted(reference)


@pytest.mark.parametrize(("signum", "expected"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_signal_finishes_frame_in_flight_and_exits(
    sequence: Path, tmp_path: Path, reference: dict[str, bytes], signum: int, expected: int
) -> None:
    out = tmp_path / "out"
    args = ["denoise", str(sequence / "in.####.exr"), "-o", str(out / "o.####.exr")]
    code, err = start_and_signal_paused(args, signum)
    assert code == expected, err
    name = signal.Signals(signum).name
    # Frame 3 was in flight: it is finished, written and named; nothing after it.
    assert f"ERROR: interrupted by {name}; frame 3 was the last one finished" in err
    done = assert_no_partial_files(out, reference)
    assert done == ["o.0001.exr", "o.0002.exr", "o.0003.exr"]
    assert not [p for p in out.iterdir() if p.name.startswith(".")]
