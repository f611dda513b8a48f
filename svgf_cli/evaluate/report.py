"""The evaluation report: per-frame scores, means, rankings, and its JSON and text forms.

Conventions:

* a metric value is a float, ``math.inf`` (PSNR of identical images) or None (not defined:
  the temporal error of a method's first frame, or any metric of a flagged frame);
* a *flagged* frame is one whose output holds NaN or infinite pixels. Its metrics are None,
  and the method's mean of every metric is None too: a broken frame is never averaged away;
* the mean of a metric is the arithmetic mean of its per-frame values over the frames where
  it is defined (the temporal error from the second frame on);
* the summary of a metric is what the tables show and the ranks use: the mean, or for a
  metric summarised by its worst frame (the hot-pixel ratio) the maximum;
* ranking (per metric): methods with a summary are sorted best first (lower is better except
  PSNR and SSIM); equal values share a rank (1, 2, 2, 4); methods without one are unranked.
  The overall rank orders methods by their average rank over the overall metrics (RMSE,
  relMSE, PSNR, SSIM, FLIP, temporal) every ranked method has; a flagged method is never
  ranked.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any

from svgf_cli.evaluate.metrics import METRIC_INFO, METRIC_KEYS, METRICS, MetricInfo

SCHEMA = "svgf-evaluate/1"

Value = float | None


@dataclass
class FrameScore:
    """One method's scores on one frame."""

    frame: int
    values: dict[str, Value]
    nonfinite_pixels: int = 0
    file: str | None = None

    @property
    def flagged(self) -> bool:
        return self.nonfinite_pixels > 0


@dataclass
class MethodResult:
    """Everything measured for one method over the evaluated frames."""

    name: str
    source: str
    frames: list[FrameScore] = field(default_factory=list)

    @property
    def flagged_frames(self) -> list[FrameScore]:
        return [f for f in self.frames if f.flagged]

    @property
    def flagged(self) -> bool:
        return any(f.flagged for f in self.frames)

    def mean(self, key: str) -> Value:
        """Arithmetic mean over frames where defined; None when flagged or never defined."""
        if self.flagged:
            return None
        values = [f.values[key] for f in self.frames if f.values.get(key) is not None]
        if not values:
            return None
        if any(math.isinf(v) for v in values):
            return math.inf
        return math.fsum(values) / len(values)

    def means(self) -> dict[str, Value]:
        return {key: self.mean(key) for key in METRIC_KEYS}

    def summary(self, key: str) -> Value:
        """The metric over all frames as tables and ranks use it: the mean, or the worst
        (largest) frame for a metric whose ``summary`` is ``"max"``; None as for the mean."""
        if METRIC_INFO[key].summary != "max":
            return self.mean(key)
        if self.flagged:
            return None
        values = [f.values[key] for f in self.frames if f.values.get(key) is not None]
        return max(values) if values else None

    def summaries(self) -> dict[str, Value]:
        return {key: self.summary(key) for key in METRIC_KEYS}


@dataclass
class EvaluationReport:
    """The scores of every method on the same frames, plus how they were measured."""

    frames: list[int]
    methods: list[MethodResult]
    inputs: dict[str, str | None]
    settings: dict[str, Any]
    # ColorVideoVDP per method (svgf_cli.evaluate.perceptual.JodScore), when measured.
    jod: dict[str, Any] = field(default_factory=dict)
    # Display frames kept on request (EvaluationRequest.keep_displays); not in the JSON.
    displays: dict[str, list[Any]] = field(default_factory=dict)

    def method(self, name: str) -> MethodResult:
        for m in self.methods:
            if m.name == name:
                return m
        raise KeyError(name)

    def ranks(self, key: str) -> dict[str, int | None]:
        """Competition ranks of the methods' summaries on one metric (1 = best)."""
        info = _metric(key)
        return competition_ranks(
            {m.name: m.summary(key) for m in self.methods}, info.higher_is_better
        )

    def overall_ranks(self) -> dict[str, int | None]:
        """Rank by average per-metric rank, over the overall metrics every unflagged method
        has."""
        keys = [info.key for info in METRICS if info.overall]
        per_metric = {key: self.ranks(key) for key in keys}
        candidates = [m.name for m in self.methods if not m.flagged]
        usable = [
            key
            for key in keys
            if candidates and all(per_metric[key][n] is not None for n in candidates)
        ]
        if not usable:
            return {m.name: None for m in self.methods}
        average = {
            n: math.fsum(per_metric[key][n] for key in usable) / len(usable)  # type: ignore[misc]
            for n in candidates
        }
        ranks = competition_ranks(average, higher_is_better=False)
        return {m.name: ranks.get(m.name) for m in self.methods}

    @property
    def flagged(self) -> list[tuple[str, FrameScore]]:
        return [(m.name, f) for m in self.methods for f in m.flagged_frames]

    # -- JSON ---------------------------------------------------------------------------

    def to_dict(self) -> dict[str, Any]:
        """Plain data for ``json``: see ``docs/evaluate.md`` for the schema."""
        overall = self.overall_ranks()
        return {
            "schema": SCHEMA,
            "inputs": dict(self.inputs),
            "settings": self.settings,
            "frames": list(self.frames),
            "metrics": [
                {
                    "key": m.key,
                    "label": m.label,
                    "better": "higher" if m.higher_is_better else "lower",
                    "unit": m.unit,
                    "formula": m.formula,
                    "summary": m.summary,
                    "overall": m.overall,
                }
                for m in METRICS
            ],
            "methods": [
                {
                    "name": m.name,
                    "source": m.source,
                    "flagged": m.flagged,
                    "mean": {k: _json_value(v) for k, v in m.means().items()},
                    "summary": {k: _json_value(v) for k, v in m.summaries().items()},
                    "rank": {key: self.ranks(key)[m.name] for key in METRIC_KEYS}
                    | {"overall": overall[m.name]},
                    "frames": [
                        {
                            "frame": f.frame,
                            "file": f.file,
                            "nonfinite_pixels": f.nonfinite_pixels,
                            **{k: _json_value(f.values.get(k)) for k in METRIC_KEYS},
                        }
                        for f in m.frames
                    ],
                }
                for m in self.methods
            ],
            "ranking": {key: _ordered(self.ranks(key)) for key in METRIC_KEYS}
            | {"overall": _ordered(overall)},
        } | ({"jod": self._jod_dict()} if self.jod else {})

    def _jod_dict(self) -> dict[str, Any]:
        return {
            name: {"video": s.video, "still": s.still, "still_frames": list(s.still_frames)}
            for name, s in self.jod.items()
        }

    def format_jod(self) -> list[str]:
        """Lines of the ColorVideoVDP table (best video JOD first); none when not measured."""
        if not self.jod:
            return []
        order = sorted(self.jod.items(), key=lambda item: -item[1].video)
        rows = [[name, f"{s.video:.3f}", f"{s.still:.3f}"] for name, s in order]
        return ["", "ColorVideoVDP (JOD, 10 = no visible difference)",
                *_grid(["method", "video JOD ^", "still JOD ^"], rows)]  # fmt: skip

    def to_json(self) -> str:
        """Deterministic JSON text (stable key order, no timestamps), newline-terminated."""
        return json.dumps(self.to_dict(), indent=2, allow_nan=False) + "\n"

    # -- text -----------------------------------------------------------------------------

    def format_table(self, per_frame: bool = False) -> str:
        """The terminal summary: mean of every metric with its rank, best first overall."""
        overall = self.overall_ranks()
        order = sorted(
            self.methods,
            key=lambda m: (overall[m.name] is None, overall[m.name] or 0),
        )
        ranks = {key: self.ranks(key) for key in METRIC_KEYS}
        header = ["method", *(_header(info) for info in METRICS), "overall"]
        rows = []
        for m in order:
            cells = [m.name + (" [FLAGGED]" if m.flagged else "")]
            for info in METRICS:
                value = m.summary(info.key)
                rank = ranks[info.key][m.name]
                cells.append(_format_value(value, info) + (f" ({rank})" if rank else ""))
            cells.append(str(overall[m.name]) if overall[m.name] is not None else "-")
            rows.append(cells)
        lines = [
            f"{len(self.frames)} frame(s) {_frames_text(self.frames)}; mean over frames "
            "(hot max: worst frame), (rank) per metric, 1 = best",
            *_grid(header, rows),
        ]
        if per_frame:
            for m in self.methods:
                lines.append("")
                lines.append(f"{m.name} per frame ({m.source})")
                frame_rows = [
                    [
                        str(f.frame),
                        *(_format_value(f.values.get(i.key), i) for i in METRICS),
                        f"NaN/Inf pixels: {f.nonfinite_pixels}" if f.flagged else "",
                    ]
                    for f in m.frames
                ]
                lines.extend(_grid(["frame", *(_header(i) for i in METRICS), ""], frame_rows))
        lines.extend(self.format_jod())
        for name, f in self.flagged:
            where = f.file or f"frame {f.frame}"
            lines.append(
                f"FLAGGED: {name}: {where}: {f.nonfinite_pixels} pixel(s) are NaN or infinite; "
                "its metrics and means are left undefined"
            )
        return "\n".join(lines)


def competition_ranks(values: dict[str, Value], higher_is_better: bool) -> dict[str, int | None]:
    """``{name: rank}`` with ties sharing the best rank (1, 2, 2, 4); None values unranked."""
    known = [(name, v) for name, v in values.items() if v is not None and not math.isnan(v)]
    sign = -1.0 if higher_is_better else 1.0
    known.sort(key=lambda item: sign * item[1])
    ranks: dict[str, int | None] = {name: None for name in values}
    for position, (name, value) in enumerate(known):
        if position > 0 and value == known[position - 1][1]:
            ranks[name] = ranks[known[position - 1][0]]
        else:
            ranks[name] = position + 1
    return ranks


def _metric(key: str) -> MetricInfo:
    for info in METRICS:
        if info.key == key:
            return info
    raise KeyError(key)


def _ordered(ranks: dict[str, int | None]) -> list[str]:
    """Method names best first; unranked ones last, in report order."""
    ranked = sorted((r, i, n) for i, (n, r) in enumerate(ranks.items()) if r is not None)
    return [n for _, _, n in ranked] + [n for n, r in ranks.items() if r is None]


def _json_value(value: Value) -> float | str | None:
    """JSON has no infinity: +inf is written as the string ``"inf"``, undefined as null."""
    if value is None or math.isnan(value):
        return None
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    return value


def _header(info: MetricInfo) -> str:
    arrow = "^" if info.higher_is_better else "v"
    unit = f" {info.unit}" if info.unit else ""
    return f"{info.label}{unit} {arrow}"


def _format_value(value: Value, info: MetricInfo) -> str:
    if value is None:
        return "-"
    if math.isinf(value):
        return "inf"
    if info.key == "psnr":
        return f"{value:.2f}"
    if info.key == "ssim":
        return f"{value:.4f}"
    return f"{value:.4g}"


def _frames_text(frames: list[int]) -> str:
    from svgf_cli.io.patterns import format_frame_spec

    return format_frame_spec(frames) if frames else ""


def _grid(header: list[str], rows: list[list[str]]) -> list[str]:
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]

    def line(cells: list[str]) -> str:
        first = cells[0].ljust(widths[0])
        rest = [c.rjust(w) for c, w in zip(cells[1:], widths[1:], strict=True)]
        return "  ".join([first, *rest]).rstrip()

    return [line(header), line(["-" * w for w in widths]), *(line(r) for r in rows)]
