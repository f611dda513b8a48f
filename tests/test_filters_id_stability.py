"""Object ids renumbered from frame to frame (``filters.id_stability``, ``run.filter.IdCheck``):
the share of pixels that see the same surface in two frames and changed id tells them, and
a run lets such ids go from the first frame that shows it, with one warning."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from exr_fixtures import read_exr
from test_cli_support import run_cli

from svgf_cli.filters.id_stability import (
    MAX_DEPTH_CHANGE,
    MIN_NORMAL_DOT,
    ROW_STEP,
    id_change_share,
    ids_unstable,
    sampled_rows,
    without_ids,
)
from svgf_cli.io.exr import write_exr

ROOT = Path(__file__).resolve().parents[1]
JITTERED = ROOT / "testdata" / "seq_jit"


def _reference_share(prev: tuple[np.ndarray, ...], now: tuple[np.ndarray, ...]
                     ) -> tuple[float, float]:
    """The test in float64 numpy over every ROW_STEP-th row."""
    (id0, d0, n0), (id1, d1, n1) = prev, now
    rows = slice(None, None, ROW_STEP)
    id0, d0, n0 = id0[rows], d0[rows].astype(np.float64), n0[:, rows].astype(np.float64)
    id1, d1, n1 = id1[rows], d1[rows].astype(np.float64), n1[:, rows].astype(np.float64)
    same = ((d0 > 0) & (d1 > 0) & (np.abs(d1 - d0) <= MAX_DEPTH_CHANGE * d1)
            & ((n0 * n1).sum(axis=0) >= MIN_NORMAL_DOT))
    if not same.any():
        return 0.0, 0.0
    return float((id0 != id1)[same].mean()), float(same.mean())


def _random_frame(rng: np.random.Generator, h: int = 37, w: int = 29) -> tuple[np.ndarray, ...]:
    depth = rng.choice([0.0, 2.0, 2.01, 2.03, 5.0], size=(h, w)).astype(np.float32)
    normal = np.zeros((3, h, w), np.float32)
    axis = rng.integers(0, 3, size=(h, w))
    for k in range(3):
        normal[k][axis == k] = 1.0
    return rng.integers(0, 3, size=(h, w)).astype(np.int32), depth, normal


def test_share_matches_a_float64_reference() -> None:
    rng = np.random.default_rng(4)
    for _ in range(5):
        prev, now = _random_frame(rng), _random_frame(rng)
        got = id_change_share(sampled_rows(*prev), *now)
        assert got == pytest.approx(_reference_share(prev, now), abs=1e-12)
        assert got[1] > 0  # some pixels compared: the test is not vacuous


def test_renumbered_ids_are_unstable_and_kept_ones_are_not() -> None:
    """A pan over two walls: the same numbers are stable; swapped numbers, or an outline
    crossing a few pixels, are told apart."""
    h, w = 40, 64
    depth = np.full((h, w), 3.0, np.float32)
    normal = np.zeros((3, h, w), np.float32)
    normal[2] = 1.0
    ids = np.where(np.arange(w) < 32, 1, 2).astype(np.int32)[None, :].repeat(h, 0)
    shifted = np.where(np.arange(w) < 33, 1, 2).astype(np.int32)[None, :].repeat(h, 0)
    previous = sampled_rows(ids, depth, normal)
    changed, compared = id_change_share(previous, shifted, depth, normal)
    assert changed == pytest.approx(1 / 64) and compared == 1.0
    assert not ids_unstable(changed, compared)
    changed, compared = id_change_share(previous, 3 - ids, depth, normal)
    assert changed == 1.0 and ids_unstable(changed, compared)
    # Another shot (depth and normals elsewhere): nothing compared, nothing called unstable.
    other_normal = np.roll(normal, 1, axis=0)
    assert id_change_share(previous, 3 - ids, depth * 2, other_normal) == (0.0, 0.0)
    assert not ids_unstable(1.0, MIN_SHARE_BELOW)


MIN_SHARE_BELOW = 0.05  # under MIN_COMPARED_SHARE: too few pixels to judge


def test_without_ids_is_what_a_file_without_ids_reads_as() -> None:
    depth = np.array([[0.0, 1.0], [-1.0, 2.5]], np.float32)
    assert without_ids(depth).tolist() == [[-1, 0], [-1, 0]]


def _write_with_ids(src: Path, dest: Path, ids_of: dict[int, np.ndarray | None]) -> None:
    dest.mkdir()
    for frame, ids in ids_of.items():
        image = read_exr(src / f"in.{frame:04d}.exr")
        channels = dict(image.channels)
        if ids is not None:
            channels["id"] = ids
        write_exr(dest / f"in.{frame:04d}.exr", channels)


def test_a_run_lets_renumbered_ids_go_from_the_first_frame_that_shows_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Frames 3+ with their objects renumbered are filtered exactly as frames 3+ with no
    ids at all (0 on surfaces), and the run says so once, naming frame 3. (Without the
    warm start: its reverse pass meets frames 5, 4, 3 first, whose renumbered ids agree with
    each other, as ids of zero do not.)"""
    frames = range(1, 6)
    original = {f: read_exr(JITTERED / f"in.{f:04d}.exr").channels["id"] for f in frames}
    renumbered = {f: (np.where(ids >= 0, 7 - ids, ids) if f >= 3 else ids)
                  for f, ids in original.items()}
    no_ids = {f: (np.where(ids >= 0, 0, -1).astype(np.float32) if f >= 3 else ids)
              for f, ids in original.items()}
    outputs = {}
    for name, ids_of in (("renumbered", renumbered), ("none", no_ids)):
        _write_with_ids(JITTERED, tmp_path / name, ids_of)
        code, _, err = run_cli(["denoise", tmp_path / name / "in.####.exr", "-o",
                                tmp_path / f"out_{name}" / "o.####.exr", "--float",
                                "--colour-only", "--warm-start", "0"], capsys)
        assert code == 0, err
        warnings = [line for line in err.splitlines() if "ids ignored" in line]
        assert len(warnings) == 1 and "in.0003.exr" in warnings[0]
        outputs[name] = [read_exr(tmp_path / f"out_{name}" / f"o.{f:04d}.exr").rgb()
                         for f in frames]
    for a, b in zip(outputs["renumbered"], outputs["none"], strict=True):
        assert np.array_equal(a, b)


def test_a_run_with_stable_ids_keeps_them(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_cli(["denoise", JITTERED / "in.####.exr", "--frames", "1-4", "-o",
                            tmp_path / "o.####.exr", "--colour-only"], capsys)
    assert code == 0, err
    assert "ids ignored" not in err
