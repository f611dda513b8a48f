"""Broken input files: truncated, not EXR, non-UTF-8 headers, byte-flip fuzz, real damaged
files. Every case ends in exit 0 (the damage was harmless) or 3 with one line naming the
file; no case crashes, prints a traceback, or leaves a partial output."""

from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from faults import (
    FRAMES,
    assert_one_error_line,
    assert_outputs_intact,
    copy_sequence,
    denoise,
)
from test_cli_support import REPO, run_cli

# -- the layout of a scanline EXR: header, offset table, chunks -----------------------------


def exr_layout(data: bytes) -> tuple[int, int]:
    """(end of header, end of offset table) of a single-part scanline file."""
    pos, chunk_lines = 8, 16  # magic + version; ZIP: 16 lines per chunk
    data_window = None
    while data[pos] != 0:
        name_end = data.index(b"\0", pos)
        type_end = data.index(b"\0", name_end + 1)
        name = data[pos:name_end]
        (size,) = struct.unpack_from("<i", data, type_end + 1)
        value = type_end + 5
        if name == b"dataWindow":
            data_window = struct.unpack_from("<4i", data, value)
        if name == b"compression":
            chunk_lines = {0: 1, 1: 1, 2: 1, 3: 16, 4: 32}.get(data[value], 16)
        pos = value + size
    header_end = pos + 1
    assert data_window is not None
    height = data_window[3] - data_window[1] + 1
    chunks = -(-height // chunk_lines)
    return header_end, header_end + 8 * chunks


# -- truncation -----------------------------------------------------------------------------


def cut_points(size: int, header_end: int, table_end: int) -> dict[str, int]:
    return {
        "magic only": 4,
        "mid header": header_end // 2,
        "header end": header_end - 1,
        "mid offset table": (header_end + table_end) // 2,
        "after offset table": table_end + 3,
        "mid chunks": (table_end + size) // 2,
        "last byte missing": size - 1,
    }


@pytest.mark.parametrize(
    "where",
    ["magic only", "mid header", "header end", "mid offset table", "after offset table",
     "mid chunks", "last byte missing"],
)
def test_truncated_frame_stops_cleanly(
    where: str,
    clean_sequence: Path,
    cold_outputs: dict,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    seq = copy_sequence(clean_sequence, tmp_path / "seq")
    bad = seq / "in.0002.exr"
    data = bad.read_bytes()
    bad.write_bytes(data[: cut_points(len(data), *exr_layout(data))[where]])
    out = tmp_path / "out"
    # Without the warm start, which would read the bad frame first (its own test:
    # tests/test_run_warm_start.py).
    code, _, err = denoise([seq / "in.####.exr", "-o", out / "o.####.exr", "-q",
                            "--warm-start", "0"], capsys)
    assert code == 3, err
    line = assert_one_error_line(err, bad)
    assert "cannot" in line or "not an OpenEXR" in line or "missing" in line
    assert_outputs_intact(out, cold_outputs, ["o.0001.exr"])


@pytest.mark.parametrize(
    ("content", "fragment"),
    [(b"", "not an OpenEXR file"), (b"hello, not an image\n", "not an OpenEXR file"),
     (b"v/1\x01\x02\x00\x00\x00", "cannot")],
    ids=["empty", "text", "magic and version only"],
)
def test_not_an_exr(
    content: bytes,
    fragment: str,
    clean_sequence: Path,
    cold_outputs: dict,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    seq = copy_sequence(clean_sequence, tmp_path / "seq")
    bad = seq / "in.0003.exr"
    bad.write_bytes(content)
    out = tmp_path / "out"
    code, _, err = denoise([seq / "in.####.exr", "-o", out / "o.####.exr", "-q",
                            "--warm-start", "0"], capsys)
    assert code == 3, err
    assert_one_error_line(err, bad, fragment)
    assert_outputs_intact(out, cold_outputs, ["o.0001.exr", "o.0002.exr"])


@pytest.mark.parametrize("where", ["attribute", "channel name"])
def test_non_utf8_header_bytes(
    where: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from test_cli_support import frame_channels

    from svgf_cli.io.exr import write_exr

    channels = frame_channels(1, 16, 12)
    attributes = {}
    if where == "attribute":
        attributes["note"] = "abcdef"
    else:
        channels["abcdef.X"] = channels["Z"]
    path = tmp_path / "in.0001.exr"
    write_exr(path, channels, attributes=attributes)
    path.write_bytes(path.read_bytes().replace(b"abcdef", b"ab\xff\xfeef"))
    for argv in (["denoise", path, "-o", tmp_path / "o.exr"], ["inspect", path, "--check"]):
        code, _, err = run_cli(argv, capsys)
        assert code == 3, err
        assert_one_error_line(err, path, "not UTF-8")
    assert not (tmp_path / "o.exr").exists()


def test_inspect_check_reads_every_chunk(
    clean_sequence: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "cut.exr"
    data = (clean_sequence / "in.0001.exr").read_bytes()
    _, table_end = exr_layout(data)
    bad.write_bytes(data[: (table_end + len(data)) // 2])
    code, out, err = run_cli(["inspect", bad], capsys)
    assert code == 0 and "ready for svgf denoise" in out  # the header alone looks fine
    code, _, err = run_cli(["inspect", bad, "--check"], capsys)
    assert code == 3
    assert_one_error_line(err, bad, "cannot read pixels")
    code, _, err = run_cli(["inspect", clean_sequence / "in.0001.exr", bad, "--check"], capsys)
    assert code == 3 and f"ERROR: {bad}: cannot read pixels" in err
    assert err.strip().endswith("check failed: 1 of 2 file(s) are not ready")


def test_check_only_preflights_the_whole_sequence(
    clean_sequence: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    seq = copy_sequence(clean_sequence, tmp_path / "seq")
    out = tmp_path / "out"
    args = [seq / "in.####.exr", "-o", out / "o.####.exr", "--check-only"]
    code, stdout, err = denoise(args, capsys)
    assert code == 0, err
    assert f"Check passed: {len(FRAMES)} input frame(s) read in full" in stdout
    data = (seq / "in.0002.exr").read_bytes()
    (seq / "in.0002.exr").write_bytes(data[: len(data) - 40])
    (seq / "in.0003.exr").write_text("junk")
    code, _, err = denoise(args, capsys)
    assert code == 3
    lines = err.strip().splitlines()
    assert lines[0].startswith(f"ERROR: {seq / 'in.0002.exr'}: cannot read pixels")
    assert lines[1].startswith(f"ERROR: {seq / 'in.0003.exr'}: not an OpenEXR file")
    assert lines[2] == "ERROR: check failed: 2 of 3 input frame(s) are bad"
    assert not out.exists()  # a pre-flight writes nothing


# -- byte-flip fuzz, in a child process (a crash in a C++ decoder must fail the test, not
# -- kill the test run) -------------------------------------------------------------------

FUZZ_SEED = 20240611
FUZZ_CASES = {"header": 40, "offset table": 20, "chunks": 40}

_PROBE = r"""
import io, json, sys
from contextlib import redirect_stderr
from svgf_cli.cli import main
from svgf_cli.errors import SvgfError
from svgf_cli.io.exr import read_frame
from svgf_cli.io.layers import build_mapping
mapping = build_mapping()
for path in sys.argv[1:]:
    print(json.dumps({"start": path}), flush=True)
    record = {"path": path}
    try:
        read_frame(path, mapping)
        record["read"] = "ok"
    except SvgfError as exc:
        record["read"] = "error"
        record["read_code"] = exc.exit_code
        record["read_message"] = str(exc)
    except Exception as exc:
        record["read"] = f"unexpected {type(exc).__name__}: {exc}"
    err = io.StringIO()
    try:
        with redirect_stderr(err):
            main(["inspect", "--check", path])
    except SystemExit as exc:
        record["check_code"] = exc.code
    record["check_err"] = err.getvalue()
    print(json.dumps(record), flush=True)
"""


def probe(paths: list[Path]) -> list[dict]:
    """read_frame and `svgf inspect --check` on each file, in a child process."""
    proc = subprocess.run(
        [sys.executable, "-c", _PROBE, *map(str, paths)],
        capture_output=True, text=True, cwd=REPO, timeout=300,
        env=dict(os.environ, PYTHONUNBUFFERED="1"),
    )
    lines = [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("{")]
    started = [line["start"] for line in lines if "start" in line]
    assert proc.returncode == 0, f"child died ({proc.returncode}) on {started[-1:]}: {proc.stderr}"
    return [line for line in lines if "start" not in line]


def fuzz_mutants(source: bytes, folder: Path) -> list[tuple[str, Path]]:
    header_end, table_end = exr_layout(source)
    regions = {"header": (8, header_end), "offset table": (header_end, table_end),
               "chunks": (table_end, len(source))}
    rng = np.random.default_rng(FUZZ_SEED)
    mutants = []
    for region, count in FUZZ_CASES.items():
        low, high = regions[region]
        for index in range(count):
            data = bytearray(source)
            for offset in rng.integers(low, high, rng.integers(1, 4)):
                data[offset] ^= 1 << int(rng.integers(0, 8))
            path = folder / f"fuzz.{region.replace(' ', '_')}.{index:03d}.exr"
            path.write_bytes(bytes(data))
            mutants.append((region, path))
    return mutants


def test_byte_flip_fuzz_never_crashes_and_errors_cleanly(
    clean_sequence: Path, tmp_path: Path
) -> None:
    mutants = fuzz_mutants((clean_sequence / "in.0002.exr").read_bytes(), tmp_path)
    records = {Path(r["path"]): r for r in probe([p for _, p in mutants])}
    assert len(records) == len(mutants)
    outcome: dict[str, dict[str, int]] = {}
    for region, path in mutants:
        record = records[path]
        assert record["read"] in ("ok", "error"), record
        assert record["check_code"] in (0, 3, None), record
        if record["read"] == "error":
            assert record["read_code"] == 3
            message = record["read_message"]
            assert message.startswith(f"{path}: ") and "\n" not in message, record
        if record["check_code"] == 3:
            errors = [x for x in record["check_err"].splitlines() if x.startswith("ERROR")]
            assert len(errors) == 1 and errors[0].startswith(f"ERROR: {path}: "), record
        key = "clean error" if record["read"] == "error" else "read fine"
        outcome.setdefault(region, {}).setdefault(key, 0)
        outcome[region][key] += 1
    # Flips in ZIP data or in the offset table are nearly always caught by the decoder.
    assert outcome["chunks"].get("clean error", 0) >= FUZZ_CASES["chunks"] // 2, outcome
    print("fuzz outcome:", outcome)


DAMAGED = os.environ.get("OPENEXR_IMAGES")


@pytest.mark.skipif(
    not DAMAGED or not (Path(DAMAGED) / "Damaged").is_dir(),
    reason="set OPENEXR_IMAGES to a checkout of AcademySoftwareFoundation/openexr-images",
)
def test_openexr_project_damaged_files() -> None:
    """The OpenEXR project's own fuzzer-found files: each is read or refused cleanly."""
    files = sorted(p for p in (Path(DAMAGED) / "Damaged").iterdir() if p.is_file()
                   and p.stat().st_size < 3_000_000 and not p.name.endswith(".rst"))
    for record in probe(files):
        assert record["read"] in ("ok", "error"), record
        assert record["check_code"] in (0, 3, None), record
