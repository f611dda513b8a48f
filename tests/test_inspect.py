"""`svgf inspect`: text and JSON reports, overrides, exit codes."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_cli_support import run_cli

from svgf_cli.io.exr import write_exr

H, W = 4, 5


def _write(path: Path, names: list[str]) -> Path:
    write_exr(
        path,
        {name: np.full((H, W), 0.5, np.float32) for name in names},
        half={"R": True, "G": True, "B": True},
        attributes={"worldToCamera": np.eye(4, dtype=np.float32)},
        compression="piz",
    )
    return path


SVGF = ["R", "G", "B", "albedo.R", "albedo.G", "albedo.B", "N.X", "N.Y", "N.Z", "Z"]
SVGF += ["motion.X", "motion.Y"]


def test_text_report(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _write(tmp_path / "f.0001.exr", SVGF)
    code, out, _ = run_cli(["inspect", str(path)], capsys)
    assert code == 0
    assert f"resolution {W}x{H}, 1 part(s), compression piz" in out
    assert "R                            half" in out
    assert "motion.Y                     float" in out
    assert "normal: N.X, N.Y, N.Z" in out
    assert "signals: combined (auto; offered in auto order: combined)" in out
    assert "color = R,G,B, demodulated by albedo" in out
    assert "missing: nothing" in out
    assert "worldToCamera" in out


def test_json_report_with_cycles_override(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    names = [n for n in SVGF if not n.startswith("motion")] + ["Vector.X", "Vector.Y"]
    path = _write(tmp_path / "c.exr", names)
    argv = ["inspect", str(path), "--json", "--aov", "motion=Vector.X,Vector.Y"]
    code, out, _ = run_cli([*argv, "--motion-convention", "cycles"], capsys)
    assert code == 0
    report = json.loads(out)["files"][0]
    assert report["width"] == W and report["height"] == H
    assert report["roles"]["motion"] == ["Vector.X", "Vector.Y"]
    assert report["roles"]["id"] is None
    assert report["motion_convention"] == "cycles"
    assert report["missing"] == {}
    channel_types = {c["name"]: c["type"] for c in report["parts"][0]["channels"]}
    assert channel_types["R"] == "half" and channel_types["Vector.X"] == "float"
    assert report["attributes"]["worldToCamera"][0] == [1.0, 0.0, 0.0, 0.0]


def test_missing_roles_reported_and_check_exits_3(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _write(tmp_path / "beauty.exr", ["R", "G", "B"])
    code, out, _ = run_cli(["inspect", str(path), "--json"], capsys)
    assert code == 0
    missing = json.loads(out)["files"][0]["missing"]
    assert set(missing) == {"albedo", "normal", "depth", "motion"}
    assert "N.X,N.Y,N.Z or N.R,N.G,N.B" in missing["normal"]
    code, out, err = run_cli(["inspect", str(path), "--check"], capsys)
    assert code == 3
    assert "MISSING" in out
    assert err.strip() == f"ERROR: {path}: missing channel(s) for albedo, normal, depth, motion"


def test_unreadable_file_exits_3(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bogus = tmp_path / "bogus.exr"
    bogus.write_text("hello")
    code, _, err = run_cli(["inspect", str(bogus)], capsys)
    assert code == 3
    assert err.startswith(f"ERROR: {bogus}: not an OpenEXR file")
    code, _, err = run_cli(["inspect", str(tmp_path / "absent.exr")], capsys)
    assert code == 3 and "file not found" in err


def test_bad_override_is_a_usage_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _write(tmp_path / "f.exr", SVGF)
    code, _, err = run_cli(["inspect", str(path), "--aov", "wobble=a"], capsys)
    assert code == 2 and "unknown role" in err


def test_luminance_weights_windows_and_views_are_reported(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from exr_fixtures import PartSpec, box, gbuffer, write_parts

    acescg = (0.713, 0.293, 0.165, 0.830, 0.128, 0.044, 0.32168, 0.33767)
    header = {"chromaticities": acescg, "dataWindow": box(-2, -1, 12, 8),
              "displayWindow": box(0, 0, 8, 6)}
    path = write_parts(tmp_path / "aces.exr", [PartSpec(gbuffer(), header=header)])
    code, out, _ = run_cli(["inspect", str(path)], capsys)
    assert code == 0
    assert "luminance weights R 0.2722, G 0.6741, B 0.0537 (from chromaticities ACEScg" in out
    assert "display window 8x6+0+0" in out and "data window 12x8+-2+-1" in out
    assert "denoised colour written as: R, G, B" in out
    code, out, _ = run_cli(["inspect", str(path), "--json"], capsys)
    report = json.loads(out)["files"][0]
    assert np.allclose(report["luminance_weights"], (0.2722, 0.6741, 0.0537), atol=1e-4)
    assert report["views"] == [] and report["display_window"] == [0, 0, 8, 6]

    stereo = write_parts(
        tmp_path / "stereo.exr", [PartSpec(gbuffer(), header={"multiView": ["left", "right"]})]
    )
    code, out, _ = run_cli(["inspect", str(stereo)], capsys)
    assert code == 0 and "views: left, right (multi-view: svgf denoise refuses it)" in out


def test_a_centre_sampled_frame_is_named(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Cycles' header at 1 spp: the report says the default preset's pixel filter applies."""
    centre = tmp_path / "c.0001.exr"
    write_exr(centre, {name: np.full((H, W), 0.5, np.float32) for name in SVGF},
              attributes={"cycles.ViewLayer.samples": "1"})
    code, out, _ = run_cli(["inspect", str(centre)], capsys)
    assert code == 0 and "samples: one through the pixel centre" in out
    code, out, _ = run_cli(["inspect", str(_write(tmp_path / "j.0001.exr", SVGF))], capsys)
    assert code == 0 and "samples:" not in out
    four = tmp_path / "f.0001.exr"
    write_exr(four, {name: np.full((H, W), 0.5, np.float32) for name in SVGF},
              attributes={"cycles.ViewLayer.samples": "4"})
    code, out, _ = run_cli(["inspect", str(four)], capsys)
    assert code == 0 and "samples: 4 per pixel (header)" in out
    assert "pixel centre" not in out


def test_check_reports_noisy_outlines(capsys: pytest.CaptureFixture[str]) -> None:
    """A defocused Cycles frame (testdata/cycles/dof) has a region whose G-buffer changes
    object from pixel to pixel; the same shot in focus (roll) has none."""
    cycles = Path(__file__).resolve().parent.parent / "testdata" / "cycles"
    code, out, _ = run_cli(["inspect", str(cycles / "dof" / "in.0003.exr"), "--preset-aovs",
                            "cycles", "--check"], capsys)
    assert code == 0
    line = next(x for x in out.splitlines() if "noisy outlines:" in x)
    assert float(line.split("noisy outlines:")[1].split("%")[0]) > 5.0
    code, out, _ = run_cli(["inspect", str(cycles / "roll" / "in.0003.exr"), "--preset-aovs",
                            "cycles", "--check"], capsys)
    assert code == 0 and "noisy outlines" not in out
    code, out, _ = run_cli(["inspect", str(cycles / "dof" / "in.0003.exr"), "--preset-aovs",
                            "cycles", "--check", "--json"], capsys)
    assert json.loads(out)["files"][0]["noisy_outline_pixels"] > 0.05


def test_check_reports_jittered_samples(capsys: pytest.CaptureFixture[str]) -> None:
    """seq_jit (svgf trace --jitter) is named jittered, seq (pixel centres) and the
    depth-of-field shot (its header says centre-sampled) are not; --json says the same."""
    data = Path(__file__).resolve().parent.parent / "testdata"
    for folder, aovs, jittered in (("seq_jit", "svgf", True), ("seq", "svgf", False),
                                   ("cycles/dof", "cycles", False)):
        args = ["inspect", str(data / folder / "in.0002.exr"), "--preset-aovs", aovs, "--check"]
        code, out, _ = run_cli(args, capsys)
        assert code == 0 and ("jittered samples:" in out) == jittered, folder
        code, out, _ = run_cli([*args, "--json"], capsys)
        assert json.loads(out)["files"][0]["jittered_samples"] is jittered
