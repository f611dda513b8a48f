"""Helpers of the fault suite: the checks every fault case makes (clean exit code, one
``ERROR:`` line naming the file, no partial output, earlier outputs intact)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from test_cli_support import run_cli

FRAMES = (1, 2, 3)
WIDTH, HEIGHT = 16, 12


def copy_sequence(clean_sequence: Path, dest: Path) -> Path:
    shutil.copytree(clean_sequence, dest)
    return dest


def denoise(args: list, capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    return run_cli(["denoise", *args], capsys)


def assert_one_error_line(err: str, path: Path | str, *fragments: str) -> str:
    """stderr holds exactly one line (besides WARNING lines): ``ERROR: <path>: ...``."""
    errors = [line for line in err.splitlines() if not line.startswith("WARNING: ")]
    assert len(errors) == 1, err
    line = errors[0]
    assert line.startswith(f"ERROR: {path}: "), line
    assert "Traceback" not in err and "list index out of range" not in err
    for fragment in fragments:
        assert fragment in line, line
    return line


def same_output(data: bytes, reference: bytes) -> bool:
    """Equal files, but for the ``svgf/input`` attribute (the input's path differs when a
    case runs on a copy of the sequence): every pixel and every other attribute."""
    if data == reference:
        return True
    import tempfile

    from exr_fixtures import bits_equal, read_parts, same_value

    with tempfile.TemporaryDirectory() as tmp:
        a, b = Path(tmp) / "a.exr", Path(tmp) / "b.exr"
        a.write_bytes(data)
        b.write_bytes(reference)
        parts_a, parts_b = read_parts(a), read_parts(b)
    if len(parts_a) != len(parts_b):
        return False
    for (name_a, header_a, pixels_a), (name_b, header_b, pixels_b) in zip(
        parts_a, parts_b, strict=True
    ):
        keys = (set(header_a) | set(header_b)) - {"svgf/input", "channels"}
        if name_a != name_b or set(pixels_a) != set(pixels_b):
            return False
        if not all(same_value(header_a.get(k), header_b.get(k)) for k in keys):
            return False
        if not all(bits_equal(pixels_a[n], pixels_b[n]) for n in pixels_a):
            return False
    return True


def assert_outputs_intact(out: Path, reference: dict, expected: list[str]) -> None:
    """Exactly ``expected`` outputs exist, each equal to the clean run's, and no temporary
    is left behind."""
    visible = sorted(p.name for p in out.iterdir() if not p.name.startswith("."))
    assert visible == sorted(expected)
    for name in expected:
        assert same_output((out / name).read_bytes(), reference[name]), name
    hidden = [p.name for p in out.iterdir() if p.name.startswith(".")]
    assert hidden == [], hidden
