"""Extreme and non-finite values at every boundary: read (scrubbed, counted), output
conversion (non-finite -> 0, half clamped to +-65504, counted), and the filter history (one
bad frame must not ruin the frames after it)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from exr_fixtures import read_parts
from faults import denoise
from test_cli_support import frame_channels

from svgf_cli.io.exr import write_exr

FRAMES = range(1, 5)


def write_frames(folder: Path, edit, *, half_colour: bool = False) -> Path:
    """Four frames of the shared scene; ``edit(frame, channels)`` plants the fault."""
    folder.mkdir(parents=True, exist_ok=True)
    for frame in FRAMES:
        channels = frame_channels(frame, 16, 12)
        channels.update({c: channels[f"direct.{c}"] + channels[f"indirect.{c}"] for c in "RGB"})
        edit(frame, channels)
        half = {c: half_colour for c in "RGB"}
        write_exr(folder / f"in.{frame:04d}.exr", channels, half=half)
    return folder


def colour(path: Path) -> np.ndarray:
    (_, _, pixels), = read_parts(path)
    return np.stack([pixels[c].astype(np.float32) for c in "RGB"])


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf], ids=["nan", "inf", "-inf"])
def test_non_finite_input_is_counted_and_never_written(
    value: float, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    def plant(frame: int, channels: dict) -> None:
        if frame == 2:
            channels["direct.G"][2:4, 3:8] = value

    seq = write_frames(tmp_path / "seq", plant)
    code, _, err = denoise([seq / "in.####.exr", "-o", tmp_path / "o.####.exr", "-q"], capsys)
    assert code == 0, err
    assert f"WARNING: {seq / 'in.0002.exr'}: 10 NaN/Inf values in direct scrubbed to 0" in err
    for frame in FRAMES:
        assert np.isfinite(colour(tmp_path / f"o.{frame:04d}.exr")).all()


def test_half_output_clamps_to_largest_finite_half(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A sun or emitter above 65504 must not become Inf in a half output."""

    def plant(frame: int, channels: dict) -> None:
        channels["emission.R"] = np.zeros((12, 16), np.float32)
        channels["emission.G"] = np.zeros((12, 16), np.float32)
        channels["emission.B"] = np.zeros((12, 16), np.float32)
        channels["emission.R"][0, :4] = 70000.0  # a lamp seen directly: noise-free...
        channels["direct.R"][0, :4] += 70000.0  # ...and part of the direct light

    seq = write_frames(tmp_path / "seq", plant, half_colour=True)
    code, _, err = denoise([seq / "in.####.exr", "-o", tmp_path / "h.####.exr", "-q"], capsys)
    assert code == 0, err
    assert (
        f"WARNING: {seq / 'in.0001.exr'}: 4 output value(s) beyond the half-float range "
        "clamped to +-65504 (--float keeps them)" in err
    )
    out = colour(tmp_path / "h.0003.exr")
    assert np.isfinite(out).all() and out.max() == 65504.0
    (_, _, pixels), = read_parts(tmp_path / "h.0003.exr")
    assert pixels["R"].dtype == np.float16
    code, _, err = denoise(
        [seq / "in.####.exr", "-o", tmp_path / "f.####.exr", "-q", "--float"], capsys
    )
    assert code == 0 and "clamped" not in err
    assert colour(tmp_path / "f.0003.exr").max() >= 70000.0


def test_nan_depth_is_counted(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    def plant(frame: int, channels: dict) -> None:
        channels["Z"][0, :3] = np.nan
        channels["Z"][1, :2] = np.inf  # a background convention: silent
        channels["Z"][2, :2] = 1e10  # Cycles' background: silent

    seq = write_frames(tmp_path / "seq", plant)
    code, _, err = denoise([seq / "in.####.exr", "-o", tmp_path / "o.####.exr", "-q"], capsys)
    assert code == 0, err
    assert f"WARNING: {seq / 'in.0001.exr'}: 3 NaN values in depth treated as background" in err
    assert len(err.splitlines()) == len(FRAMES)  # one line a frame; Inf and 1e10 are silent


def test_one_extreme_frame_does_not_blacken_the_shot(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    def plant(frame: int, channels: dict) -> None:
        if frame == 2:
            channels["direct.G"].flat[:40] = 1e20

    seq = write_frames(tmp_path / "seq", plant)
    clean = write_frames(tmp_path / "clean", lambda f, c: None)
    code, _, err = denoise([seq / "in.####.exr", "-o", tmp_path / "o.####.exr", "-q"], capsys)
    assert code == 0, err
    code, _, _ = denoise([clean / "in.####.exr", "-o", tmp_path / "c.####.exr", "-q"], capsys)
    for frame in (3, 4):
        hit, reference = colour(tmp_path / f"o.{frame:04d}.exr"), colour(
            tmp_path / f"c.{frame:04d}.exr"
        )
        assert np.isfinite(hit).all()
        # Later frames look like the clean run's, not black.
        assert (hit == 0).mean() < 0.05
        assert abs(hit.mean() - reference.mean()) < 0.1 * reference.mean()
