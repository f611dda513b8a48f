"""Real processes: SIGKILL midway then --skip-existing resume; SIGINT/SIGTERM exit codes."""

from __future__ import annotations

import json
import signal
import threading
from pathlib import Path

import pytest
from test_cli_support import outputs, run_cli, svgf_subprocess, write_sequence

FRAMES = range(1, 13)
WIDTH, HEIGHT = 96, 72


@pytest.fixture(scope="module")
def sequence(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("seq12")
    write_sequence(folder, FRAMES, width=WIDTH, height=HEIGHT)
    return folder


@pytest.fixture(scope="module")
def reference(sequence: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    """An uninterrupted run: file name -> file bytes."""
    out = tmp_path_factory.mktemp("ref12")
    from svgf_cli.cli import main

    with pytest.raises(SystemExit) as exited:
        main(["denoise", str(sequence / "in.####.exr"), "-o", str(out / "o.####.exr"), "-q"])
    assert exited.value.code == 0
    return {p.name: p.read_bytes() for p in outputs(out, "o")}


def start_and_signal_after(args: list[str], frames_done: int, signum: int) -> tuple[int, str]:
    """Run svgf with JSON progress; send ``signum`` once ``frames_done`` frames are written."""
    proc = svgf_subprocess([*args, "--progress", "json"])
    watchdog = threading.Timer(120, proc.kill)
    watchdog.start()
    try:
        assert proc.stdout is not None
        done = 0
        for line in proc.stdout:
            if json.loads(line).get("event") == "frame_done":
                done += 1
                if done == frames_done:
                    proc.send_signal(signum)
                    break
        proc.stdout.read()
        _, err = proc.communicate()
    finally:
        watchdog.cancel()
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
    code, _ = start_and_signal_after(args, 2, signal.SIGKILL)
    assert code == -signal.SIGKILL
    done = assert_no_partial_files(out, reference)
    assert 2 <= len(done) < len(FRAMES)

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
    code, err = start_and_signal_after(args, 2, signum)
    assert code == expected, err
    name = signal.Signals(signum).name
    assert f"ERROR: interrupted by {name}; frame " in err
    done = assert_no_partial_files(out, reference)
    assert 2 <= len(done) < len(FRAMES)
    # The last finished frame named in the message is on disk and complete.
    last = int(err.split("interrupted by")[1].split("frame ")[1].split(" ")[0])
    assert f"o.{last:04d}.exr" in done
    assert not [p for p in out.iterdir() if p.name.startswith(".")]
