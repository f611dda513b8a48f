"""The issue targets that the numbers of `make results` can answer, as pass/fail checks.

Every check reads only the per-sequence reports (so it can be tested on synthetic numbers)
and returns a :class:`Check`: PASS, FAIL, or SKIP when a method or sequence it needs is not
there (e.g. an option another branch is still adding). "relMSE" in a target means the
trimmed relMSE, the metric the hidden evaluation reports; the plain one is in the tables.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from svgf_cli.evaluate.metrics import HOT_THRESHOLD, METRIC_INFO, METRICS
from svgf_cli.evaluate.report import EvaluationReport
from svgf_cli.results.run import SequenceRun
from svgf_cli.results.table import (
    BIDIRECTIONAL,
    COMBINED,
    LOBES,
    PAPER,
    SPATIAL,
    SVGF,
    Event,
)

RELMSE = "relmse_trimmed"
PASS, FAIL, SKIP = "PASS", "FAIL", "SKIP"


@dataclass(frozen=True)
class Check:
    issue: int
    target: str
    status: str
    numbers: str

    def line(self) -> str:
        return f"[{self.status}] #{self.issue} {self.target}: {self.numbers}"


def _verdict(ok: Sequence[bool]) -> str:
    return PASS if all(ok) else FAIL


def _has(run: SequenceRun, *names: str) -> bool:
    return all(name in run.names for name in names)


def _summary(run: SequenceRun, name: str, key: str) -> float | None:
    return run.report.method(name).summary(key)


def _ratio(a: float | None, b: float | None) -> float | None:
    if a is None or b is None or math.isinf(a) or math.isinf(b):
        return None
    if b == 0.0:
        return 1.0 if a == 0.0 else math.inf
    return a / b


def _fmt(value: float | None) -> str:
    return "-" if value is None else f"{value:.3g}"


def _x(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}x"


def _better(a: float | None, b: float | None, key: str) -> bool:
    """``a`` strictly better than ``b`` on ``key`` (undefined is never better)."""
    if a is None or b is None:
        return False
    return a > b if METRIC_INFO[key].higher_is_better else a < b


def per_frame(report: EvaluationReport, name: str, key: str) -> dict[int, float | None]:
    return {f.frame: f.values.get(key) for f in report.method(name).frames}


def recovery_frames(
    values: Sequence[float | None], baseline: Sequence[float | None], factor: float = 2.0
) -> int | None:
    """Frames after a step until ``values`` is within ``factor`` x ``baseline`` for good.

    ``values[0]`` is the first frame with the new lighting; the result is the smallest
    ``k`` such that ``values[i] <= factor * baseline[i]`` for every ``i >= k`` (up to the next
    step or the end), so 0 = never worse than ``factor`` x; None when even the last frame is
    not within it (or a value is undefined).
    """
    k = len(values)
    for i in range(len(values) - 1, -1, -1):
        v, b = values[i], baseline[i]
        if v is None or b is None or v > factor * b:
            break
        k = i
    return k if k < len(values) else None


def step_segments(run: SequenceRun) -> list[tuple[Event, list[int]]]:
    """Each lighting step of the sequence with its evaluated frames, up to the next step."""
    frames = run.report.frames
    steps = sorted((e for e in run.spec.events if e.lighting_step), key=lambda e: e.frame)
    segments = []
    for i, event in enumerate(steps):
        end = steps[i + 1].frame if i + 1 < len(steps) else math.inf
        segment = [f for f in frames if event.frame <= f < end]
        if segment and segment[0] == event.frame:
            segments.append((event, segment))
    return segments


def recovery(run: SequenceRun, method: str, key: str = RELMSE) -> list[tuple[Event, int | None]]:
    """Per lighting step: :func:`recovery_frames` of ``method`` against spatial-only."""
    mine = per_frame(run.report, method, key)
    spatial = per_frame(run.report, SPATIAL, key)
    return [
        (event, recovery_frames([mine[f] for f in seg], [spatial[f] for f in seg]))
        for event, seg in step_segments(run)
    ]


def frames_text(k: int | None) -> str:
    return "never" if k is None else f"{k} frame" + ("" if k == 1 else "s")


def check_lighting_recovery(runs: Sequence[SequenceRun], limit: int = 2) -> Check:
    target = (
        f"after a lighting step svgf's per-frame relMSE is back within 2x of "
        f"spatial-only's in <= {limit} frames"
    )
    items, ok = [], []
    for run in runs:
        if not _has(run, SVGF, SPATIAL):
            continue
        for event, k in recovery(run, SVGF):
            items.append(f"{run.spec.name} at frame {event.frame}: {frames_text(k)}")
            ok.append(k is not None and k <= limit)
    if not items:
        return Check(10, target, SKIP, "no lighting step with svgf and svgf-no-temporal")
    return Check(10, target, _verdict(ok), "; ".join(items))


def check_beats_spatial(runs: Sequence[SequenceRun]) -> Check:
    target = "on every lag sequence temporal reuse (svgf) beats --no-temporal on relMSE and FLIP"
    items, ok = [], []
    for run in runs:
        if not run.spec.has("lag") or not _has(run, SVGF, SPATIAL):
            continue
        parts = []
        for key in (RELMSE, "flip"):
            a, b = _summary(run, SVGF, key), _summary(run, SPATIAL, key)
            ok.append(_better(a, b, key))
            parts.append(f"{METRIC_INFO[key].label.split(' ')[0]} {_x(_ratio(a, b))}")
        items.append(f"{run.spec.name} " + " ".join(parts))
    if not items:
        return Check(10, target, SKIP, "no lag sequence with svgf and svgf-no-temporal")
    return Check(10, target, _verdict(ok), "svgf / spatial-only: " + "; ".join(items))


def check_static_cost(runs: Sequence[SequenceRun], tolerance: float = 0.05) -> Check:
    target = (
        f"on static-lighting sequences svgf's relMSE, FLIP and temporal error are "
        f"within +{tolerance:.0%} of the paper preset's"
    )
    items, ok = [], []
    for run in runs:
        if not run.spec.has("static-lighting") or not _has(run, SVGF, PAPER):
            continue
        parts = []
        for key in (RELMSE, "flip", "temporal"):
            r = _ratio(_summary(run, SVGF, key), _summary(run, PAPER, key))
            ok.append(r is not None and r <= 1.0 + tolerance)
            parts.append(f"{METRIC_INFO[key].label.split(' ')[0]} {_x(r)}")
        items.append(f"{run.spec.name} " + " ".join(parts))
    if not items:
        return Check(10, target, SKIP, "no static-lighting sequence with svgf and svgf-paper")
    return Check(10, target, _verdict(ok), "svgf / paper: " + "; ".join(items))


def preset_ranks(run: SequenceRun, names: Sequence[str]) -> dict[str, int | None]:
    """Overall ranks among ``names`` only (the other methods left out of the ranking)."""
    chosen = [m for m in run.report.methods if m.name in names]
    sub = EvaluationReport(run.report.frames, chosen, run.report.inputs, run.report.settings)
    return sub.overall_ranks()


def check_default_wins(runs: Sequence[SequenceRun]) -> Check:
    target = (
        "the default preset wins overall among the svgf presets (default, paper, "
        "no-temporal): lowest mean overall rank over the sequences"
    )
    presets = (SVGF, PAPER, SPATIAL)
    totals: dict[str, list[int]] = {name: [] for name in presets}
    items = []
    for run in runs:
        if not _has(run, *presets):
            continue
        ranks = preset_ranks(run, presets)
        for name in presets:
            if ranks[name] is not None:
                totals[name].append(ranks[name])  # type: ignore[arg-type]
        items.append(f"{run.spec.name} {ranks[SVGF]}")
    if not items or not totals[SVGF]:
        return Check(10, target, SKIP, "no sequence with all three presets")
    means = {n: math.fsum(v) / len(v) for n, v in totals.items() if v}
    best = min(means.values())
    status = PASS if means[SVGF] == best else FAIL
    mean_text = ", ".join(f"{n} {means[n]:.2f}" for n in presets if n in means)
    return Check(
        10, target, status, f"mean rank {mean_text}; svgf's rank per sequence: " + ", ".join(items)
    )


def check_hot_pixels(runs: Sequence[SequenceRun], method: str = SVGF) -> Check:
    target = (
        f"no {method} output pixel above {HOT_THRESHOLD:g}x the reference's local 5x5 "
        "maximum on any frame"
    )
    items, ok = [], []
    for run in runs:
        if not _has(run, method):
            continue
        frames = run.report.method(method).frames
        known = [(f.values.get("hot_max"), f.frame) for f in frames]
        known = [(v, frame) for v, frame in known if v is not None]
        if not known:
            ok.append(False)
            items.append(f"{run.spec.name} undefined")
            continue
        worst, frame = max(known)
        ok.append(worst <= HOT_THRESHOLD)
        items.append(f"{run.spec.name} {worst:.3g}x (frame {frame})")
    if not items:
        return Check(14, target, SKIP, f"no sequence with {method}")
    return Check(14, target, _verdict(ok), "worst frame: " + ", ".join(items))


def check_lobes_beat_combined(runs: Sequence[SequenceRun]) -> Check:
    target = (
        f"lobe signals ({LOBES}) beat the combined signal ({COMBINED}) on relMSE and FLIP "
        "on every Cycles fixture"
    )
    cycles = [run for run in runs if run.spec.has("cycles")]
    usable = [run for run in cycles if _has(run, LOBES, COMBINED)]
    if not cycles or len(usable) < len(cycles):
        return Check(
            14,
            target,
            SKIP,
            f"{LOBES} or {COMBINED} missing (needs `--signals`; "
            "merge the lobes branch and re-run make results)",
        )
    items, ok = [], []
    for run in usable:
        parts = []
        for key in (RELMSE, "flip"):
            a, b = _summary(run, LOBES, key), _summary(run, COMBINED, key)
            ok.append(_better(a, b, key))
            parts.append(f"{METRIC_INFO[key].label.split(' ')[0]} {_x(_ratio(a, b))}")
        items.append(f"{run.spec.name} " + " ".join(parts))
    return Check(14, target, _verdict(ok), "lobes / combined: " + "; ".join(items))


def _bidir_missing(runs: Sequence[SequenceRun]) -> bool:
    return not any(_has(run, BIDIRECTIONAL, SVGF) for run in runs)


_BIDIR_SKIP = (
    f"{BIDIRECTIONAL} missing (needs `--bidirectional`; merge the bidir branch and "
    "re-run make results)"
)


def check_bidirectional_gain(runs: Sequence[SequenceRun]) -> Check:
    target = (
        "bidirectional relMSE <= 0.7x and temporal error <= 0.8x of forward-only on "
        "sequences with camera motion or moving objects"
    )
    if _bidir_missing(runs):
        return Check(13, target, SKIP, _BIDIR_SKIP)
    items, ok = [], []
    for run in runs:
        moving = run.spec.has("camera-motion") or run.spec.has("moving-objects")
        if not moving or not _has(run, BIDIRECTIONAL, SVGF):
            continue
        r = _ratio(_summary(run, BIDIRECTIONAL, RELMSE), _summary(run, SVGF, RELMSE))
        t = _ratio(_summary(run, BIDIRECTIONAL, "temporal"), _summary(run, SVGF, "temporal"))
        ok.append(r is not None and r <= 0.7 and t is not None and t <= 0.8)
        items.append(f"{run.spec.name} relMSE {_x(r)} temporal {_x(t)}")
    if not items:
        return Check(13, target, SKIP, "no moving sequence with both")
    return Check(13, target, _verdict(ok), "bidirectional / forward: " + "; ".join(items))


def check_bidirectional_never_worse(runs: Sequence[SequenceRun]) -> Check:
    target = "bidirectional is worse than forward-only on no metric of any sequence"
    if _bidir_missing(runs):
        return Check(13, target, SKIP, _BIDIR_SKIP)
    keys = [m.key for m in METRICS if m.overall] + [RELMSE]
    worse = []
    count = 0
    for run in runs:
        if not _has(run, BIDIRECTIONAL, SVGF):
            continue
        count += 1
        for key in keys:
            if _better(_summary(run, SVGF, key), _summary(run, BIDIRECTIONAL, key), key):
                worse.append(f"{run.spec.name} {METRIC_INFO[key].label}")
    status = PASS if not worse else FAIL
    text = "worse on: " + ", ".join(worse) if worse else f"not worse anywhere ({count} sequences)"
    return Check(13, target, status, text)


def cold_start(report: EvaluationReport, name: str, first: int = 4) -> float | None:
    """Worst of the first ``first`` frames' relMSE over the sequence's mean relMSE."""
    values = [f.values.get(RELMSE) for f in report.method(name).frames]
    mean = report.method(name).mean(RELMSE)
    head = [v for v in values[:first] if v is not None]
    if not head or mean is None or mean == 0.0:
        return None
    return max(head) / mean


def check_bidirectional_cold_start(runs: Sequence[SequenceRun], limit: float = 1.3) -> Check:
    target = f"bidirectional: the first 4 frames within {limit}x of the sequence's mean relMSE"
    if _bidir_missing(runs):
        return Check(13, target, SKIP, _BIDIR_SKIP)
    items, ok = [], []
    for run in runs:
        if not _has(run, BIDIRECTIONAL, SVGF):
            continue
        mine, forward = cold_start(run.report, BIDIRECTIONAL), cold_start(run.report, SVGF)
        ok.append(mine is not None and mine <= limit)
        items.append(f"{run.spec.name} {_x(mine)} (forward {_x(forward)})")
    return Check(13, target, _verdict(ok), "worst first-4 frame / mean: " + "; ".join(items))


def all_checks(runs: Sequence[SequenceRun]) -> list[Check]:
    """Every target, in issue order (10, 14, 13)."""
    return [
        check_lighting_recovery(runs),
        check_beats_spatial(runs),
        check_static_cost(runs),
        check_default_wins(runs),
        check_hot_pixels(runs),
        check_lobes_beat_combined(runs),
        check_bidirectional_gain(runs),
        check_bidirectional_never_worse(runs),
        check_bidirectional_cold_start(runs),
    ]
