"""The Mitsuba 3 fixture (``testdata/mitsuba/seq``, rendered by ``testdata/mitsuba/render.py``):
what Mitsuba's one-sample frames are like, read and denoised as a user's would be."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from exr_fixtures import read_exr
from test_cli_support import run_cli

from svgf_cli.filters.jitter import jittered_frame
from svgf_cli.io.exr import read_frame
from svgf_cli.io.layers import build_mapping

ROOT = Path(__file__).resolve().parents[1]
MITSUBA = ROOT / "testdata" / "mitsuba" / "seq"


def test_its_frames_read_as_jittered_colour_only_frames_without_ids() -> None:
    result = read_frame(MITSUBA / "in.0004.exr", build_mapping("svgf"))
    frame = result.frame
    assert [s.name for s in frame.signals] == ["color"]  # the combined set: one signal
    assert frame.emission is not None and frame.emission.max() > 10  # the light, seen
    assert set(np.unique(frame.mesh_id)) == {-1, 0}  # no id channel: 0 on surfaces
    assert not frame.centre_sampled
    assert jittered_frame(frame.centre_sampled, frame.depth, frame.normal, frame.mesh_id)


def test_it_denoises_well_below_its_inputs_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, _, err = run_cli(["denoise", MITSUBA / "in.####.exr", "--frames", "1-4", "-o",
                            tmp_path / "o.####.exr", "--colour-only", "--float"], capsys)
    assert code == 0, err
    assert "WARNING" not in err
    for frame in (1, 4):
        ref = read_exr(MITSUBA / f"ref.{frame:04d}.exr").rgb().astype(np.float64)
        noisy = read_exr(MITSUBA / f"in.{frame:04d}.exr").rgb().astype(np.float64)
        out = read_exr(tmp_path / f"o.{frame:04d}.exr").rgb().astype(np.float64)
        assert _rel_mse(out, ref) < 0.15 * _rel_mse(noisy, ref), frame


def _rel_mse(image: np.ndarray, ref: np.ndarray) -> float:
    return float(np.mean((image - ref) ** 2 / (ref ** 2 + 1e-2)))
