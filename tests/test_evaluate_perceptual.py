"""Issue 29: ColorVideoVDP input shaping (fake metric without torch, a real tiny call with it),
the OIDN aux prefilter on a noisy-aux Cycles frame, the animation and the JOD checks."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from test_cli_support import REPO
from test_results_checks import flat, run_of

from svgf_cli.evaluate import metrics
from svgf_cli.evaluate.animation import LABEL_HEIGHT, Panel, write_animation
from svgf_cli.evaluate.perceptual import JodScore, as_video, jod_scores
from svgf_cli.results import perceptual as results_jod
from svgf_cli.results.run import jod_available

HAS_JOD = jod_available()
HAS_OIDN = importlib.util.find_spec("pyoidn") is not None


class FakeMetric:
    """Records what it is given; JOD = 10 - 10 * mean absolute difference."""

    def __init__(self) -> None:
        self.calls: list[tuple[tuple[int, ...], str, float | None]] = []

    def predict(self, test, reference, dim_order="BCFHW", frames_per_second=0.0):  # noqa: ANN001, ANN201
        t, r = np.asarray(test), np.asarray(reference)
        self.calls.append((t.shape, dim_order, frames_per_second or None))
        assert t.dtype == np.float32 and t.min() >= 0.0 and t.max() <= 1.0
        return 10.0 - 10.0 * float(np.mean(np.abs(t - r))), {}


def test_tone_map_is_reinhard_then_srgb() -> None:
    linear = np.array([0.0, 0.001, 1.0, 1e6, -1.0], np.float32).reshape(1, 1, 5)
    display = metrics.tone_map(linear)[0, 0]
    assert display[0] == 0.0 and display[4] == 0.0  # negatives clamp to black
    v = 0.001 / 1.001
    assert display[1] == pytest.approx(12.92 * v, rel=1e-5)  # the linear toe of sRGB
    assert display[2] == pytest.approx(1.055 * 0.5 ** (1 / 2.4) - 0.055, rel=1e-5)
    assert 0.999 < display[3] <= 1.0  # bright emitters stay below white, not clipped


def test_as_video_shapes_frames_h_w_3_in_unit_range() -> None:
    frames = [np.full((3, 4, 6), value, np.float32) for value in (-0.5, 0.5, 2.0)]
    video = as_video(frames)
    assert video.shape == (3, 4, 6, 3) and video.dtype == np.float32
    assert video.min() == 0.0 and video.max() == 1.0 and video[1, 0, 0, 0] == 0.5
    assert as_video([np.zeros((4, 6, 3))]).shape == (1, 4, 6, 3)  # HWC passes through
    with pytest.raises(ValueError, match="NaN"):
        as_video([np.full((3, 4, 6), np.nan)])


def test_jod_scores_video_then_each_still_with_a_fake_metric() -> None:
    reference = [np.full((3, 8, 8), 0.5, np.float32) for _ in range(4)]
    test = [r + 0.1 * i for i, r in enumerate(reference)]
    metric = FakeMetric()
    score = jod_scores(test, reference, metric, fps=30.0)
    assert metric.calls[0] == ((4, 8, 8, 3), "FHWC", 30.0)
    assert [c[:2] for c in metric.calls[1:]] == [((8, 8, 3), "HWC")] * 4
    assert score.still_frames == pytest.approx([10.0, 9.0, 8.0, 7.0], abs=1e-5)
    assert score.still == pytest.approx(8.5, abs=1e-5)
    with pytest.raises(ValueError, match="shape"):
        jod_scores(test[:3], reference, metric)


@pytest.mark.skipif(not HAS_JOD, reason="cvvdp/torch not installed (svgf[perceptual])")
def test_real_colorvideovdp_identical_is_10_noisy_lower() -> None:
    from svgf_cli.evaluate.perceptual import load_metric

    rng = np.random.default_rng(0)
    reference = [(0.4 + 0.2 * rng.random((3, 32, 32))).astype(np.float32) for _ in range(4)]
    noisy = [np.clip(r + rng.normal(0.0, 0.1, r.shape), 0, 1) for r in reference]
    metric = load_metric()
    same = jod_scores(reference, reference, metric)
    worse = jod_scores(noisy, reference, metric)
    assert same.video == pytest.approx(10.0, abs=1e-3) and same.still == pytest.approx(10.0)
    assert worse.video < 9.0 and worse.still < 9.5


@pytest.mark.skipif(not HAS_OIDN, reason="pyoidn not installed (svgf[oidn])")
def test_oidn_prefilter_beats_raw_noisy_aux_on_a_cycles_frame() -> None:
    from svgf_cli.evaluate.baselines import OidnMethod, make_method
    from svgf_cli.filters.params import PRESETS
    from svgf_cli.io.exr import read_frame, read_rgb
    from svgf_cli.io.layers import build_mapping

    folder = REPO / "testdata" / "cycles" / "roll"
    mapping = build_mapping("cycles")
    frame = read_frame(folder / "in.0003.exr", mapping).frame
    reference, _ = read_rgb(folder / "ref.0003.exr", mapping)
    chosen = make_method("oidn", PRESETS["default"], layers="cycles")
    assert isinstance(chosen, OidnMethod) and chosen.prefilter  # noisy aux: prefiltered
    assert not make_method("oidn", PRESETS["default"], layers="svgf").prefilter  # type: ignore[attr-defined]
    pre = chosen.process(frame)
    raw = OidnMethod(prefilter=False).process(frame)
    assert not np.array_equal(pre, raw)
    assert metrics.relmse_trimmed(pre, reference) < 0.95 * metrics.relmse_trimmed(raw, reference)


def test_animation_has_every_frame_and_four_labelled_panels(tmp_path: Path) -> None:
    from PIL import Image

    frames = [[np.full((3, 6, 8), (p + 1) / 5 + f / 50, np.float32) for f in range(3)]
              for p in range(4)]  # fmt: skip
    panels = [Panel(name, f) for name, f in zip(("input", "svgf", "OIDN", "ref"), frames,
                                                strict=True)]  # fmt: skip
    for suffix in ("webp", "gif"):
        path = tmp_path / f"a.{suffix}"
        assert write_animation(panels, path, scale=2) == 3
        with Image.open(path) as image:
            assert image.n_frames == 3 and image.info.get("loop") == 0
            assert image.size == (4 * 16 + 3 * 2, 12 + LABEL_HEIGHT)
            image.seek(1)
            rgb = np.asarray(image.convert("RGB"), np.float32) / 255.0
        row = rgb[LABEL_HEIGHT + 6]
        centres = [row[p * 18 + 8].mean() for p in range(4)]
        assert centres == sorted(centres)  # panels left to right in the given order
        assert abs(centres[1] - (2 / 5 + 1 / 50)) < 0.03  # panel 2's second frame
    with pytest.raises(ValueError, match="same"):
        write_animation([panels[0], Panel("short", frames[1][:2])], tmp_path / "x.webp")


def _jod_run(name: str, svgf: float, oidn: float, relmse: tuple[float, float]):  # noqa: ANN202
    run = run_of(name, set(), {"svgf": {"relmse_trimmed": flat(relmse[0])},
                               "oidn": {"relmse_trimmed": flat(relmse[1])}})  # fmt: skip
    run.report.jod = {"svgf": JodScore(svgf, [svgf + 0.2]), "oidn": JodScore(oidn, [oidn])}
    return run


def test_jod_checks_margin_and_relmse_against_oidn() -> None:
    good = _jod_run("a", 9.5, 9.1, (0.01, 0.02))
    close = _jod_run("b", 9.3, 9.1, (0.03, 0.02))
    margin, relmse = results_jod.jod_checks([good])
    assert (margin.status, relmse.status) == ("PASS", "PASS")
    margin, relmse = results_jod.jod_checks([good, close])
    assert (margin.status, relmse.status) == ("FAIL", "FAIL")
    assert "b svgf 9.30 vs OIDN 9.10" in margin.numbers
    table = results_jod.jod_table([good, close])
    assert "9.50 / 9.70" in table and "no (+0.20)" in table and "yes (0.50x)" in table
    bare = run_of("c", set(), {"svgf": {}})
    assert results_jod.jod_checks([bare])[0].status == "SKIP"


def test_load_metric_without_torch_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    import sys

    from svgf_cli.errors import UsageError
    from svgf_cli.evaluate.perceptual import load_metric

    monkeypatch.setitem(sys.modules, "torch", None)  # import torch -> ImportError
    with pytest.raises(UsageError, match=r"svgf\[perceptual\]"):
        load_metric()
    assert not jod_available()


SEQ = REPO / "testdata" / "seq"


def _evaluate(capsys: pytest.CaptureFixture[str], *extra: str) -> tuple[int, str, str]:
    from test_cli_support import run_cli

    args = ["evaluate", str(SEQ / "in.####.exr"), "-r", str(SEQ / "ref.####.exr"),
            "--frames", "1-3", "-q", *extra]  # fmt: skip
    return run_cli(args, capsys)


def test_evaluate_jod_without_torch_exits_2(monkeypatch: pytest.MonkeyPatch,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    import sys

    monkeypatch.setitem(sys.modules, "torch", None)
    code, _out, err = _evaluate(capsys, "--jod")
    assert code == 2 and "svgf[perceptual]" in err


@pytest.mark.skipif(not HAS_JOD, reason="cvvdp/torch not installed (svgf[perceptual])")
def test_evaluate_jod_table_json_and_map(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    import json

    from PIL import Image

    report, heat = tmp_path / "r.json", tmp_path / "map.png"
    code, out, err = _evaluate(capsys, "--jod-methods", "svgf", "--json", str(report),
                               "--jod-map", str(heat))  # fmt: skip
    assert code == 0, err
    assert "ColorVideoVDP (JOD" in out
    jod = json.loads(report.read_text())["jod"]
    assert set(jod) == {"svgf"} and len(jod["svgf"]["still_frames"]) == 3
    assert 0.0 < jod["svgf"]["video"] < 10.0  # the noisy input scored as "svgf"
    with Image.open(heat) as image:
        assert image.size == (256, 144)
