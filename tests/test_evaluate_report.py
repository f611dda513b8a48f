"""Means, ranking, flagged frames and the JSON schema of the evaluation report."""

from __future__ import annotations

import json
import math

from svgf_cli.evaluate.metrics import METRIC_KEYS
from svgf_cli.evaluate.report import (
    SCHEMA,
    EvaluationReport,
    FrameScore,
    MethodResult,
    competition_ranks,
)


def _scores(frame: int, scale: float, temporal: float | None = None) -> FrameScore:
    values = {
        "rmse": 0.1 * scale,
        "relmse": 0.01 * scale,
        "relmse_trimmed": 0.009 * scale,
        "psnr": 30.0 / scale,
        "ssim": 1.0 - 0.1 * scale,
        "flip": 0.05 * scale,
        "temporal": temporal,
        "hot_max": 1.5 * scale,
        "hot_share": 0.001 * scale,
    }
    return FrameScore(frame, values, file=f"f.{frame}.exr")


def _report() -> EvaluationReport:
    good = MethodResult("svgf", "den", [_scores(1, 1.0), _scores(2, 1.0, 0.01)])
    worse = MethodResult("input", "in", [_scores(1, 3.0), _scores(2, 3.0, 0.09)])
    broken = MethodResult(
        "atrous",
        "baseline",
        [_scores(1, 0.5), FrameScore(2, dict.fromkeys(METRIC_KEYS), nonfinite_pixels=7)],
    )
    return EvaluationReport([1, 2], [good, broken, worse], {"output": "den"}, {"x": 1})


def test_competition_ranks_share_ties_and_skip_undefined() -> None:
    ranks = competition_ranks({"a": 2.0, "b": 1.0, "c": 2.0, "d": None, "e": 5.0}, False)
    assert ranks == {"b": 1, "a": 2, "c": 2, "e": 4, "d": None}
    high = competition_ranks({"a": 2.0, "b": 1.0}, higher_is_better=True)
    assert high == {"a": 1, "b": 2}


def test_mean_skips_undefined_temporal_but_not_flagged_frames() -> None:
    report = _report()
    svgf = report.method("svgf")
    assert svgf.mean("rmse") == 0.1
    assert svgf.mean("temporal") == 0.01  # frame 1 has no temporal error
    broken = report.method("atrous")
    assert broken.flagged
    # Frame 1 of atrous is the best of all, but its NaN frame 2 must not be averaged away.
    assert all(broken.mean(key) is None for key in METRIC_KEYS)


def test_ranking_puts_flagged_method_unranked() -> None:
    report = _report()
    for key in METRIC_KEYS:
        ranks = report.ranks(key)
        assert ranks["svgf"] == 1 and ranks["input"] == 2 and ranks["atrous"] is None
    assert report.overall_ranks() == {"svgf": 1, "atrous": None, "input": 2}


def test_json_schema_and_strictness() -> None:
    report = _report()
    report.method("svgf").frames[0].values["psnr"] = math.inf
    text = report.to_json()
    data = json.loads(text)
    assert data["schema"] == SCHEMA
    assert data["frames"] == [1, 2]
    assert [m["key"] for m in data["metrics"]] == list(METRIC_KEYS)
    assert {m["name"] for m in data["methods"]} == {"svgf", "atrous", "input"}
    svgf = next(m for m in data["methods"] if m["name"] == "svgf")
    assert set(svgf) == {"name", "source", "flagged", "mean", "summary", "rank", "frames"}
    assert set(svgf["mean"]) == set(METRIC_KEYS) == set(svgf["summary"])
    assert {m["key"]: m["summary"] for m in data["metrics"]}["hot_max"] == "max"
    assert set(svgf["rank"]) == {*METRIC_KEYS, "overall"}
    assert svgf["frames"][0]["psnr"] == "inf"  # JSON has no infinity
    assert svgf["frames"][0]["temporal"] is None
    assert svgf["mean"]["psnr"] == "inf"
    atrous = next(m for m in data["methods"] if m["name"] == "atrous")
    assert atrous["flagged"] is True
    assert atrous["frames"][1]["nonfinite_pixels"] == 7
    assert atrous["mean"]["rmse"] is None
    assert data["ranking"]["relmse"] == ["svgf", "input", "atrous"]
    assert data["ranking"]["overall"] == ["svgf", "input", "atrous"]
    assert "NaN" not in text and "Infinity" not in text
    assert report.to_json() == text, "the same report must serialise identically"


def test_table_names_every_method_and_the_flagged_frame() -> None:
    table = _report().format_table(per_frame=True)
    assert "atrous [FLAGGED]" in table
    assert "FLAGGED: atrous: frame 2: 7 pixel(s) are NaN or infinite" in table
    lines = table.splitlines()
    # Best overall first: svgf's row comes before input's.
    first_rows = [line.split()[0] for line in lines[3:6]]
    assert first_rows == ["svgf", "input", "atrous"]
    assert "svgf per frame" in table


def test_hot_max_is_summarised_by_its_worst_frame_and_stays_out_of_the_overall_rank() -> None:
    def frame(n: int, hot: float, relmse: float) -> FrameScore:
        values = dict.fromkeys(METRIC_KEYS, 1.0)
        values.update(hot_max=hot, relmse=relmse, temporal=None)
        return FrameScore(n, values)

    # "a" has one very hot frame but the better relMSE; "b" is lukewarm on both frames.
    a = MethodResult("a", "a", [frame(1, 1.0, 0.01), frame(2, 9.0, 0.01)])
    b = MethodResult("b", "b", [frame(1, 4.0, 0.02), frame(2, 4.0, 0.02)])
    report = EvaluationReport([1, 2], [a, b], {}, {})
    assert a.mean("hot_max") == 5.0 and a.summary("hot_max") == 9.0
    assert b.summary("hot_max") == 4.0
    assert report.ranks("hot_max") == {"b": 1, "a": 2}, "ranked on the worst frame"
    # Overall: only the overall metrics count (relMSE decides; every other one ties).
    assert report.overall_ranks() == {"a": 1, "b": 2}
    assert a.summary("relmse") == a.mean("relmse")
