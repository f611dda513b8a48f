"""Real processes: SIGKILL mid-run then resume (identical outputs, dead temporaries
cleaned), and two writers of the same frames (two farm nodes) that never expose a partial
file under an output name."""

from __future__ import annotations

import json
import os
import threading
import time
from pathlib import Path

import pytest
from faults import FRAMES
from test_cli_support import outputs, run_cli, svgf_subprocess

from svgf_cli.io import atomic


def test_sigkill_then_resume_is_identical_and_cleans_dead_temporaries(
    clean_sequence: Path,
    clean_outputs: dict,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    out = tmp_path / "out"
    args = ["denoise", clean_sequence / "in.####.exr", "-o", out / "o.####.exr"]
    # Paused before its third frame is filtered (frame 2's write may be under way), so the
    # kill lands mid-run however fast the machine is.
    proc = svgf_subprocess([*args, "--progress", "json"], pause_before=2)
    assert proc.stdout is not None
    for line in proc.stdout:
        if json.loads(line).get("event") == "paused":
            proc.kill()
            break
    proc.communicate(timeout=600)
    assert proc.returncode == -9
    done = [p.name for p in outputs(out, "o")]
    assert done in (["o.0001.exr"], ["o.0001.exr", "o.0002.exr"])
    for name in done:  # whatever was renamed into place is complete
        assert (out / name).read_bytes() == clean_outputs[name]
    # What a kill inside a write leaves behind: our host, a dead PID. And a live writer's
    # temporary (this process) that must survive.
    here = f"{atomic._host()}_{atomic._pid_namespace()}"
    dead = out / f".o.0003.exr.{here}.{proc.pid}.00c0ffee.tmp.exr"
    dead.write_bytes(b"partial")
    alive = out / f".o.0002.exr.{here}.{os.getpid()}.0badf00d.tmp.exr"
    alive.write_bytes(b"being written")

    # The kill may also have landed inside a write, leaving the killed run's own temporary.
    stale = atomic.stale_temporaries([out / f"o.{f:04d}.exr" for f in FRAMES])
    assert dead in stale and alive not in stale
    code, stdout, err = run_cli([*args, "--skip-existing"], capsys)
    assert code == 0, err
    assert f"Removed {len(stale)} temporary file(s) left by dead runs" in stdout
    assert not dead.exists() and alive.exists()
    alive.unlink()
    assert {p.name: p.read_bytes() for p in outputs(out, "o")} == clean_outputs
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == []


def test_two_writers_of_the_same_frames_never_expose_a_partial_file(
    clean_sequence: Path, clean_outputs: dict, tmp_path: Path
) -> None:
    """Two processes (as two farm nodes retrying one task) write the same outputs while a
    reader keeps opening them: every file it sees is complete."""
    out = tmp_path / "out"
    out.mkdir()
    args = ["denoise", clean_sequence / "in.####.exr", "-o", out / "o.####.exr", "-q",
            "--overwrite"]
    seen: list[tuple[str, bool]] = []
    stop = threading.Event()

    def watch() -> None:
        while not stop.is_set():
            for path in out.glob("o.*.exr"):
                try:
                    data = path.read_bytes()
                except FileNotFoundError:
                    continue
                seen.append((path.name, data == clean_outputs[path.name]))
            time.sleep(0.001)

    watcher = threading.Thread(target=watch)
    watcher.start()
    try:
        writers = [svgf_subprocess(args) for _ in range(2)]
        results = [w.communicate(timeout=300) for w in writers]
    finally:
        stop.set()
        watcher.join()
    for writer, (_, err) in zip(writers, results, strict=True):
        assert writer.returncode == 0, err
    assert seen, "the watcher saw no output at all"
    partial = [name for name, complete in seen if not complete]
    assert partial == [], f"{len(partial)} partial reads of {len(seen)}: {partial[:5]}"
    assert {p.name: p.read_bytes() for p in outputs(out, "o")} == clean_outputs
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == []
