"""`svgf evaluate` end to end on tiny synthetic sequences: outputs, errors, flags, OIDN."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest
from test_cli_support import run_cli

from svgf_cli.evaluate.synthetic import write_synthetic_sequence
from svgf_cli.io.exr import read_rgb, write_exr

FRAMES = 3
WIDTH, HEIGHT = 32, 24


def _write_rgb(path: Path, image: np.ndarray) -> None:
    write_exr(path, {"R": image[0], "G": image[1], "B": image[2]})


@pytest.fixture()
def seq(tmp_path: Path) -> dict[str, str]:
    """Input + reference sequence and a 'denoised' one that is the reference scaled by 1.05."""
    inputs, refs = write_synthetic_sequence(tmp_path / "seq", FRAMES, WIDTH, HEIGHT)
    out = tmp_path / "out"
    out.mkdir()
    for frame in range(1, FRAMES + 1):
        ref, _ = read_rgb(tmp_path / "seq" / f"ref.{frame:04d}.exr")
        _write_rgb(out / f"den.{frame:04d}.exr", ref * np.float32(1.05))
    return {
        "input": inputs,
        "reference": refs,
        "output": str(out / "den.####.exr"),
        "dir": str(tmp_path),
    }


def run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    return run_cli(["evaluate", "--quiet", *args], capsys)


def _png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    assert data[12:16] == b"IHDR"
    width, height = struct.unpack(">II", data[16:24])
    return width, height


def test_outputs_json_plot_sheet(seq: dict[str, str], capsys: pytest.CaptureFixture[str]) -> None:
    d = Path(seq["dir"])
    code, out, err = run(
        capsys,
        seq["output"],
        "--reference",
        seq["reference"],
        "--input",
        seq["input"],
        "--json",
        str(d / "r.json"),
        "--plot",
        str(d / "p.png"),
        "--contact-sheet",
        str(d / "s.png"),
        "--contact-frames",
        "2",
    )
    assert code == 0, err
    assert "svgf" in out and "input" in out and "relMSE" in out
    report = json.loads((d / "r.json").read_text())
    assert report["frames"] == [1, 2, 3]
    names = [m["name"] for m in report["methods"]]
    assert names == ["svgf", "input"]
    svgf = report["methods"][0]
    # A 5 % gain error on every pixel: relMSE = mean(0.05^2 r^2 / (r^2 + 0.01)) < 0.0025.
    assert 0.0 < svgf["mean"]["relmse"] < 0.0025
    assert svgf["frames"][0]["temporal"] is None and svgf["frames"][1]["temporal"] >= 0.0
    assert report["ranking"]["relmse"][0] == "svgf"
    assert report["ranking"]["overall"] == ["svgf", "input"]
    pw, ph = _png_size(d / "p.png")
    sw, sh = _png_size(d / "s.png")
    assert pw > 100 and ph > 100 and sw > 100 and sh > 50
    assert sw > 3 * sh, "one contact frame: a single row of input, svgf, reference, error"


def test_reports_are_deterministic(seq: dict[str, str], capsys: pytest.CaptureFixture[str]) -> None:
    d = Path(seq["dir"])
    texts = []
    for name in ("a.json", "b.json"):
        code, _, err = run(capsys, seq["output"], "-r", seq["reference"], "--json", str(d / name))
        assert code == 0, err
        texts.append((d / name).read_text())
    assert texts[0] == texts[1]


def test_compare_scores_more_denoised_sequences(
    seq: dict[str, str], capsys: pytest.CaptureFixture[str]
) -> None:
    d = Path(seq["dir"])
    other = d / "other"
    other.mkdir()
    for frame in range(1, FRAMES + 1):  # a worse 'denoiser': 20 % too bright
        ref, _ = read_rgb(d / "seq" / f"ref.{frame:04d}.exr")
        _write_rgb(other / f"den.{frame:04d}.exr", ref * np.float32(1.2))
    code, out, err = run(
        capsys, seq["output"], "-r", seq["reference"], "--compare",
        f"bright={other / 'den.####.exr'}", "--json", str(d / "c.json"),
    )
    assert code == 0, err
    report = json.loads((d / "c.json").read_text())
    assert [m["name"] for m in report["methods"]] == ["svgf", "bright"]
    assert report["ranking"]["relmse"] == ["svgf", "bright"]
    bright = report["methods"][1]
    # A 20 % gain: per pixel 0.04 r^2 / (r^2 + 0.01), 16x the 5 % gain's error.
    svgf_relmse = report["methods"][0]["mean"]["relmse"]
    assert bright["mean"]["relmse"] == pytest.approx(16 * svgf_relmse, rel=1e-3)
    assert "bright" in out
    code, _, err = run(capsys, seq["output"], "-r", seq["reference"], "--compare", "svgf=x")
    assert code == 2 and "reserved" in err
    code, _, err = run(capsys, seq["output"], "-r", seq["reference"], "--compare", "nopattern")
    assert code == 2 and "NAME=PATTERN" in err
    missing = f"gone={d / 'nowhere' / 'den.####.exr'}"
    code, _, err = run(capsys, seq["output"], "-r", seq["reference"], "--compare", missing)
    assert code == 3 and "gone output for frame 1 not found" in err


def test_missing_reference_frame_is_an_input_error(
    seq: dict[str, str], capsys: pytest.CaptureFixture[str]
) -> None:
    missing = Path(seq["dir"]) / "seq" / "ref.0002.exr"
    missing.unlink()
    code, _, err = run(capsys, seq["output"], "--reference", seq["reference"])
    assert code == 3
    assert err.startswith("ERROR: ") and "ref.0002.exr" in err and "reference" in err
    assert len(err.strip().splitlines()) == 1


def test_mismatched_resolution_is_an_input_error(
    seq: dict[str, str], capsys: pytest.CaptureFixture[str]
) -> None:
    small = Path(seq["dir"]) / "out" / "den.0003.exr"
    _write_rgb(small, np.ones((3, HEIGHT // 2, WIDTH // 2), np.float32))
    code, _, err = run(capsys, seq["output"], "--reference", seq["reference"])
    assert code == 3
    assert "den.0003.exr" in err and "16x12" in err and f"{WIDTH}x{HEIGHT}" in err


def test_nan_output_is_flagged_not_averaged(
    seq: dict[str, str], capsys: pytest.CaptureFixture[str]
) -> None:
    d = Path(seq["dir"])
    path = d / "out" / "den.0002.exr"
    image, _ = read_rgb(path)
    image[1, 5, 7] = np.nan
    image[0, 0, 0] = np.inf
    _write_rgb(path, image)
    code, out, err = run(capsys, seq["output"], "-r", seq["reference"], "--json", str(d / "r.json"))
    assert code == 3
    assert "den.0002.exr" in err and "2 pixel(s)" in err
    assert "svgf [FLAGGED]" in out and "FLAGGED: svgf:" in out
    report = json.loads((d / "r.json").read_text())  # still written, for the record
    svgf = report["methods"][0]
    assert svgf["flagged"] is True
    assert svgf["frames"][1]["nonfinite_pixels"] == 2
    assert svgf["frames"][1]["rmse"] is None
    assert svgf["mean"]["rmse"] is None and svgf["rank"]["overall"] is None
    assert svgf["frames"][0]["rmse"] is not None  # the healthy frames keep their scores


def test_baseline_needs_input(seq: dict[str, str], capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run(capsys, seq["output"], "-r", seq["reference"], "--baseline", "oidn")
    assert code == 2 and "--input" in err


def test_frames_option_and_missing_output_frame(
    seq: dict[str, str], capsys: pytest.CaptureFixture[str]
) -> None:
    d = Path(seq["dir"])
    code, _, err = run(
        capsys,
        seq["output"],
        "-r",
        seq["reference"],
        "--frames",
        "2-3",
        "--json",
        str(d / "r.json"),
    )
    assert code == 0, err
    assert json.loads((d / "r.json").read_text())["frames"] == [2, 3]
    code, _, err = run(capsys, seq["output"], "-r", seq["reference"], "--frames", "3-4")
    assert code == 3 and "den.0004.exr" in err


def test_oidn_baseline_runs_and_beats_the_input(
    seq: dict[str, str], capsys: pytest.CaptureFixture[str]
) -> None:
    d = Path(seq["dir"])
    code, out, err = run(
        capsys,
        seq["output"],
        "-r",
        seq["reference"],
        "-i",
        seq["input"],
        "--baseline",
        "oidn",
        "--json",
        str(d / "r.json"),
    )
    assert code == 0, err
    report = json.loads((d / "r.json").read_text())
    means = {m["name"]: m["mean"] for m in report["methods"]}
    assert set(means) == {"svgf", "oidn", "input"}
    assert report["settings"]["oidn"]["clean_aux"] is True
    # OIDN removes most of the synthetic Gamma noise (measured ~0.007 vs ~0.23 at 64x48).
    assert means["oidn"]["relmse"] < 0.2 * means["input"]["relmse"]
    assert means["oidn"]["ssim"] > means["input"]["ssim"]


def test_oidn_missing_is_a_usage_error(
    seq: dict[str, str], capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    import sys

    monkeypatch.setitem(sys.modules, "pyoidn", None)  # makes `import pyoidn` raise ImportError
    code, _, err = run(
        capsys, seq["output"], "-r", seq["reference"], "-i", seq["input"], "--baseline", "oidn"
    )
    assert code == 2
    assert "pip install 'svgf[oidn]'" in err and len(err.strip().splitlines()) == 1
