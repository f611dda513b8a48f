"""`svgf denoise --signals` and `svgf inspect --signals` end to end on real fixture frames:
the layer table, one warning per run for a failed light-pass check, gradient samples that
change the output."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from test_cli_support import run_cli
from test_io_signals import GLOSSY, METAL, cycles_copy

from svgf_cli.io.exr import read_rgb
from svgf_cli.io.layers import build_mapping


def _sequence(folder: Path, source: Path, frames: range) -> Path:
    folder.mkdir()
    for frame in frames:
        shutil.copy(source / f"in.{frame:04d}.exr", folder / f"in.{frame:04d}.exr")
    return folder


def _denoise(capsys: pytest.CaptureFixture[str], inputs: Path, out: Path,
             *options: str) -> str:
    """Run `svgf denoise`; return the start-up log and the warnings (stdout + stderr)."""
    code, log, err = run_cli(["denoise", str(inputs / "in.####.exr"), "-o",
                              str(out / "den.####.exr"), "--progress", "lines", *options],
                             capsys)
    assert code == 0, err
    return log + err


def _outputs(out: Path, frames: range, preset: str) -> list[np.ndarray]:
    mapping = build_mapping(preset)
    return [read_rgb(out / f"den.{f:04d}.exr", mapping)[0] for f in frames]


def test_gradient_samples_reach_the_filter_and_change_the_output(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    frames = range(1, 4)
    inputs = _sequence(tmp_path / "in", GLOSSY, frames)
    err = _denoise(capsys, inputs, tmp_path / "on", "--signals", "lobes")
    assert "signals: lobes (asked for lobes;" in err
    assert "glossy = (GlossDir + GlossInd) x GlossCol, demodulated by GlossCol; gradient " \
           "samples gradient.glossy" in err
    _denoise(capsys, inputs, tmp_path / "off", "--signals", "lobes", "--no-antilag-gradients")
    with_samples = _outputs(tmp_path / "on", frames, "svgf")
    without = _outputs(tmp_path / "off", frames, "svgf")
    # Frame 1 has no history to shorten; from frame 2 on the light has moved and the
    # samples say so.
    np.testing.assert_array_equal(with_samples[0], without[0])
    for a, b in zip(with_samples[1:], without[1:], strict=True):
        assert np.abs(a - b).max() > 1e-3


def test_failed_check_warns_once_and_filters_the_combined_colour(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    frames = range(5, 8)
    inputs = tmp_path / "in"
    inputs.mkdir()
    for frame in frames:  # no glossy passes: the light passes miss the reflections
        cycles_copy(METAL / f"in.{frame:04d}.exr", inputs / f"in.{frame:04d}.exr",
                    drop=("GlossDir", "GlossInd", "GlossCol"))
    err = _denoise(capsys, inputs, tmp_path / "auto", "--preset-aovs", "cycles")
    warnings = [line for line in err.splitlines() if "light passes" in line]
    assert len(warnings) == 1, warnings
    assert f"WARNING: {inputs / 'in.0005.exr'}: the light passes of signal set " \
           "lobes-split do not add up to the colour on" in warnings[0]
    assert "filtering the combined colour for the whole run" in warnings[0]
    assert "signals: combined (auto;" in err
    _denoise(capsys, inputs, tmp_path / "combined", "--preset-aovs", "cycles",
             "--signals", "combined")
    for a, b in zip(_outputs(tmp_path / "auto", frames, "cycles"),
                    _outputs(tmp_path / "combined", frames, "cycles"), strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_later_frame_failing_the_check_keeps_the_first_frames_set(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    inputs = _sequence(tmp_path / "in", METAL, range(4, 6))
    cycles_copy(METAL / "in.0006.exr", inputs / "in.0006.exr", scale={"DiffInd": 0.5})
    err = _denoise(capsys, inputs, tmp_path / "out", "--preset-aovs", "cycles")
    assert "signals: lobes-split (auto;" in err
    warnings = [line for line in err.splitlines() if "light passes" in line]
    assert len(warnings) == 1, warnings
    assert "in.0006.exr" in warnings[0] and "keeping lobes-split, chosen on the first " \
        "frame" in warnings[0]
    assert (tmp_path / "out" / "den.0006.exr").exists()


def test_inspect_shows_the_sets_and_checks_the_light_passes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    frame = METAL / "in.0006.exr"
    code, out, _ = run_cli(["inspect", str(frame), "--preset-aovs", "cycles", "--json"],
                           capsys)
    assert code == 0
    auto = json.loads(out)["files"][0]
    assert auto["signal_set"] == "lobes-split"
    assert auto["signals"] == ["diffuse_direct", "diffuse_indirect", "specular"]
    code, out, _ = run_cli(["inspect", str(frame), "--preset-aovs", "cycles", "--check",
                            "--signals", "direct-indirect", "--json"], capsys)
    assert code == 0
    report = json.loads(out)["files"][0]
    assert report["signal_set"] == "direct-indirect"
    assert report["signal_sets_offered"] == ["lobes-split", "direct-indirect", "lobes",
                                             "combined"]
    assert report["signals"] == ["direct", "indirect"]
    assert report["signal_plan"][0]["terms"] == [
        {"light": [f"{lobe}_direct"], "colour": f"{lobe}_color"}
        for lobe in ("diffuse", "glossy", "transmission")]
    assert report["signal_plan"][1]["albedo"] == ["diffuse_color", "glossy_color",
                                                  "transmission_color"]
    assert report["emission_roles"] == ["emission", "environment"]
    assert report["light_pass_check_result"]["failing"] == 0
    assert report["roles"]["environment"] == ["ViewLayer.Env.R", "ViewLayer.Env.G",
                                              "ViewLayer.Env.B"]
    broken = cycles_copy(frame, tmp_path / "b.exr", drop=("GlossDir", "GlossInd", "GlossCol"))
    code, out, _ = run_cli(["inspect", str(broken), "--preset-aovs", "cycles", "--check",
                            "--signals", "lobes-split"], capsys)
    assert code == 0
    assert "signals: lobes-split (asked for lobes-split;" in out
    assert "light-pass check (FAILED: svgf denoise filters the combined colour)" in out


def test_evaluate_reads_the_input_as_the_signal_set_asked_for(tmp_path: Path) -> None:
    from svgf_cli.evaluate.engine import EvaluationRequest, run_evaluation

    inputs = str(GLOSSY / "in.####.exr")
    for signals, used in (("auto", "lobes-split"), ("lobes", "lobes")):
        request = EvaluationRequest(output=inputs, reference=str(GLOSSY / "ref.####.exr"),
                                    input=inputs, frames=[1, 2], signals=signals)
        report, _ = run_evaluation(request)
        assert report.settings["signals"] == used
        # the raw input row is the signals plus the emission: the file's colour, up to the
        # half rounding of the stored passes
        methods = {m.name: m for m in report.methods}
        assert abs(methods["input"].mean("relmse") - methods["svgf"].mean("relmse")) < 1e-3
