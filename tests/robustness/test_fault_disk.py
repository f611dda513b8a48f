"""The disk fills up, or the output path cannot be written: exit 1 with one line naming the
output and the real cause; earlier outputs intact; no partial file under any output name."""

from __future__ import annotations

import json
import os
import resource
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from faults import assert_one_error_line, denoise, same_output
from test_cli_support import REPO

# Lists the folder from inside the child's mount namespace, where the small disk lives.
_LIST = (
    "import json, os, sys; d = sys.argv[1]; "
    "print(json.dumps({n: open(os.path.join(d, n), 'rb').read().hex() for n in os.listdir(d)}))"
)


def _run_on_small_disk(args: list[str], folder: Path, size: int) -> tuple[int, str, dict]:
    """`svgf ARGS` with ``folder`` a tmpfs of ``size`` bytes in a private mount namespace
    (unprivileged: a user namespace). Returns (exit code, stderr, folder contents)."""
    script = (
        f'mount -t tmpfs -o size={size} tmpfs "$1" || exit 99; shift; '
        f'"$0" -m svgf_cli "$@" 2>"$OUT_ERR"; code=$?; '
        f'"$0" -c "{_LIST}" "$OUT_DIR"; exit $code'
    )
    err_file = folder.parent / "svgf.err"
    env = dict(os.environ, OUT_ERR=str(err_file), OUT_DIR=str(folder))
    proc = subprocess.run(
        ["unshare", "--user", "--map-root-user", "--mount", "sh", "-c", script,
         sys.executable, str(folder), *map(str, args)],
        capture_output=True, text=True, cwd=REPO, env=env, timeout=300,
    )
    if proc.returncode == 99 or "unshare" in proc.stderr:
        pytest.skip(f"cannot mount a small filesystem without root here: {proc.stderr.strip()}")
    contents = json.loads(proc.stdout.strip().splitlines()[-1])
    return proc.returncode, err_file.read_text(), {k: bytes.fromhex(v) for k, v in contents.items()}


def test_disk_full_on_a_small_filesystem(
    clean_sequence: Path, clean_outputs: dict, tmp_path: Path
) -> None:
    if shutil.which("unshare") is None:
        pytest.skip("no unshare(1): cannot make a small filesystem without root")
    out = tmp_path / "disk"
    out.mkdir()
    first = len(clean_outputs["o.0001.exr"])
    size = (first * 3 // 2 + 4095) // 4096 * 4096  # room for frame 1, not for frame 2
    code, err, files = _run_on_small_disk(
        ["denoise", clean_sequence / "in.####.exr", "-o", out / "o.####.exr", "-q"], out, size
    )
    assert code == 1, err
    assert_one_error_line(err, out / "o.0002.exr", "No space left on device")
    assert sorted(files) == ["o.0001.exr"]  # no partial o.0002, no temporary
    assert files["o.0001.exr"] == clean_outputs["o.0001.exr"]


def test_file_size_limit_fails_the_write_cleanly(
    clean_sequence: Path, cold_outputs: dict, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The same failure through RLIMIT_FSIZE (works everywhere, no mount needed): frame 1
    is written by a first run, a second run's write of frame 2 fails part-way. Without the
    warm start, whose scratch files would meet the limit first."""
    out = tmp_path / "out"
    args = ["denoise", clean_sequence / "in.####.exr", "-o", out / "o.####.exr", "-q",
            "--warm-start", "0"]
    code, _, err = denoise([*args[1:], "--frames", "1", "--warmup", "all"], capsys)
    assert code == 0, err
    limit = 2048  # far below one output file

    def limited() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # fail the write, do not kill
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    proc = subprocess.run(
        [sys.executable, "-m", "svgf_cli", *map(str, args), "--frames", "2-3"],
        capture_output=True, text=True, cwd=REPO, preexec_fn=limited, timeout=300,
    )
    assert proc.returncode == 1, proc.stderr
    assert_one_error_line(proc.stderr, out / "o.0002.exr", "File too large")
    assert sorted(p.name for p in out.iterdir()) == ["o.0001.exr"]  # nothing partial
    assert same_output((out / "o.0001.exr").read_bytes(), cold_outputs["o.0001.exr"])


def test_output_path_problems_name_the_real_cause(
    clean_sequence: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    in_pattern = clean_sequence / "in.####.exr"
    blocker = tmp_path / "blocker"
    blocker.write_text("a file where a folder should be")
    code, _, err = denoise([in_pattern, "-o", blocker / "sub" / "o.####.exr", "-q"], capsys)
    assert code == 1
    assert_one_error_line(err, blocker / "sub", "cannot create the output folder")

    taken = tmp_path / "taken"
    taken.mkdir()
    (taken / "o.0002.exr").mkdir()  # a directory under an output name
    code, _, err = denoise(
        [in_pattern, "-o", taken / "o.####.exr", "-q", "--overwrite"], capsys
    )
    assert code == 1
    assert_one_error_line(err, taken / "o.0002.exr", "is a directory")
    assert sorted(p.name for p in taken.iterdir()) == ["o.0001.exr", "o.0002.exr"]
