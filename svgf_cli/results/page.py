"""docs/results.md and docs/results/: tables, computed findings, plots and contact sheets.

Everything on the page is computed from the reports: the same reports give the same bytes
(no timings, no dates, no temporary paths). PNGs are re-encoded with a fixed palette
(Pillow, median cut, no dither) to keep the committed images small.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path

from svgf_cli.evaluate.contact import write_contact_sheet
from svgf_cli.evaluate.metrics import HOT_THRESHOLD, METRIC_INFO, METRICS
from svgf_cli.evaluate.plot import write_curves
from svgf_cli.evaluate.report import EvaluationReport
from svgf_cli.results.checks import RELMSE, Check, cold_start, frames_text, recovery
from svgf_cli.results.machine import machine_description, package_versions
from svgf_cli.results.perceptual import jod_table
from svgf_cli.results.run import MethodNote, SequenceRun, identical_methods
from svgf_cli.results.table import BIDIRECTIONAL, INPUT, PAPER, SPATIAL, SVGF, MethodSpec

CURVE_KEYS = ("relmse_trimmed", "flip", "temporal")
CONTACT_CELL_INCHES = 1.6
CONTACT_DPI = 100.0


def number(value: float | None, key: str) -> str:
    """A metric value as the page shows it."""
    if value is None:
        return "–"
    if math.isinf(value):
        return "∞"
    if key == "psnr":
        return f"{value:.2f}"
    if key == "ssim":
        return f"{value:.4f}"
    if key == "hot_share":
        return f"{100.0 * value:.3g} %"
    if key == "hot_max":
        return f"{value:.3g}x"
    return f"{value:.4g}"


def _header(key: str) -> str:
    info = METRIC_INFO[key]
    label = "Hot px > 3x" if key == "hot_share" else info.label
    return f"{label} {'↑' if info.higher_is_better else '↓'}"


def summary_table(report: EvaluationReport) -> str:
    """Every method (best overall first) x every metric; rank 1 in bold."""
    overall = report.overall_ranks()
    order = sorted(report.methods, key=lambda m: (overall[m.name] is None, overall[m.name] or 0))
    keys = [info.key for info in METRICS]
    ranks = {key: report.ranks(key) for key in keys}
    lines = [
        "| method | " + " | ".join(_header(k) for k in keys) + " | overall |",
        "|---" * (len(keys) + 2) + "|",
    ]
    for method in order:
        cells = [f"`{method.name}`" + (" (FLAGGED: NaN)" if method.flagged else "")]
        for key in keys:
            text = number(method.summary(key), key)
            cells.append(f"**{text}**" if ranks[key][method.name] == 1 else text)
        cells.append(str(overall[method.name] or "–"))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def per_frame_table(report: EvaluationReport, key: str) -> str:
    names = [m.name for m in report.methods]
    lines = [
        "| frame | " + " | ".join(f"`{n}`" for n in names) + " |",
        "|---" * (len(names) + 1) + "|",
    ]
    for index, frame in enumerate(report.frames):
        values = [m.frames[index].values.get(key) for m in report.methods]
        known = [v for v in values if v is not None]
        best = min(known) if known else None
        cells = [
            f"**{number(v, key)}**" if v is not None and v == best else number(v, key)
            for v in values
        ]
        lines.append(f"| {frame} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def overview_table(runs: Sequence[SequenceRun], names: Sequence[str], key: str) -> str:
    """One row per sequence, one column per method: the metric's summary, best in bold."""
    info = METRIC_INFO[key]
    lines = [
        "| sequence | " + " | ".join(f"`{n}`" for n in names) + " |",
        "|---" * (len(names) + 1) + "|",
    ]
    for run in runs:
        values = [run.report.method(n).summary(key) if n in run.names else None for n in names]
        known = [v for v in values if v is not None]
        best = (max(known) if info.higher_is_better else min(known)) if known else None
        cells = [
            f"**{number(v, key)}**" if v is not None and v == best else number(v, key)
            for v in values
        ]
        lines.append(
            f"| [{run.spec.folder}](#{_anchor(run.spec.folder)}) | " + " | ".join(cells) + " |"
        )
    return "\n".join(lines)


def _anchor(folder: str) -> str:
    """GitHub's heading anchor of ``## `folder` ``: lower case, punctuation but - and _
    dropped, spaces to -."""
    return "".join(c for c in folder.lower() if c.isalnum() or c in "-_ ").replace(" ", "-")


def _ratio_text(a: float | None, b: float | None) -> str:
    if a is None or b is None or b == 0.0 or math.isinf(a) or math.isinf(b):
        return "–"
    return f"{a / b:.2f}x"


def findings(run: SequenceRun) -> list[str]:
    """Short computed statements of what the numbers of one sequence show."""
    report = run.report
    out = [*_ranking_finding(report), *_comparison_findings(run), *_recovery_findings(run)]
    out.append(_hot_pixel_finding(run))
    ratio = cold_start(report, SVGF)
    if ratio is not None:
        out.append(
            f"Cold start: `svgf`'s worst relMSE (trimmed) in the first 4 frames is "
            f"{ratio:.2f}x its sequence mean."
        )
    same = identical_methods(report)
    if same:
        out.append(
            "Identical numbers (the same filter reached two ways): "
            + ", ".join(f"`{a}` = `{b}`" for a, b in same)
            + "."
        )
    return out


def _ranking_finding(report: EvaluationReport) -> list[str]:
    """Which method has the lowest relMSE (trimmed), and where `svgf` ranks (none when no
    method has one)."""
    svgf = report.method(SVGF)
    ranks = report.ranks(RELMSE)
    best = min(
        (m for m in report.methods if ranks[m.name] is not None),
        key=lambda m: ranks[m.name] or 0,
        default=None,
    )
    if best is None:
        return []
    return [
        f"Lowest relMSE (trimmed): `{best.name}` ({number(best.summary(RELMSE), RELMSE)}); "
        f"`svgf` is {ranks[SVGF]} of {sum(r is not None for r in ranks.values())} "
        f"({number(svgf.summary(RELMSE), RELMSE)}); overall rank of `svgf`: "
        f"{report.overall_ranks()[SVGF]}."
    ]


def _comparison_findings(run: SequenceRun) -> list[str]:
    """`svgf`'s summary metrics as ratios to each reference method that was run."""
    report, names = run.report, run.names
    svgf = report.method(SVGF)
    out = []
    for other, what in (
        (SPATIAL, "spatial-only (`svgf-no-temporal`)"),
        (PAPER, "the paper preset (`svgf-paper`)"),
        ("oidn", "OIDN"),
        (BIDIRECTIONAL, "`svgf-bidirectional`"),
    ):
        if other not in names:
            continue
        o = report.method(other)
        parts = ", ".join(
            f"{METRIC_INFO[k].label.split(' ')[0]} {_ratio_text(svgf.summary(k), o.summary(k))}"
            for k in (RELMSE, "flip", "temporal")
        )
        out.append(f"`svgf` against {what}: {parts} (below 1 = `svgf` better).")
    return out


def _recovery_findings(run: SequenceRun) -> list[str]:
    """How soon `svgf` is back within 2x of spatial-only after each step of the scene."""
    names = run.names
    if SPATIAL not in names:
        return []
    out = []
    for event, k in recovery(run, SVGF):
        paper = dict(recovery(run, PAPER)).get(event) if PAPER in names else None
        peak = _peak_ratio(run, event.frame)
        text = (
            f"After the step at frame {event.frame} ({event.text}) `svgf`'s per-frame "
            f"relMSE (trimmed) is "
            + (
                "within 2x of spatial-only's from the step frame on"
                if k == 0
                else f"back within 2x of spatial-only's after {frames_text(k)}"
                if k is not None
                else "not back within 2x of spatial-only's before the next step or the end"
            )
        )
        if PAPER in names:
            text += f" (paper preset: {frames_text(paper)})"
        text += f"; at the step it is {peak} spatial-only's."
        out.append(text)
    return out


def _hot_pixel_finding(run: SequenceRun) -> str:
    """`svgf`'s brightest pixel against the reference, and which denoisers go over the limit."""
    report = run.report
    svgf = report.method(SVGF)
    hot = [
        (m.summary("hot_max"), m.name)
        for m in report.methods
        if m.name != INPUT and m.summary("hot_max") is not None
    ]
    over = sorted(name for value, name in hot if value is not None and value > HOT_THRESHOLD)
    worst = number(svgf.summary("hot_max"), "hot_max")
    pixels = run.size[0] * run.size[1]
    shares = [f.values.get("hot_share") for f in svgf.frames]
    count = round(sum(v for v in shares if v is not None) * pixels)
    return (
        f"Hot pixels: `svgf`'s brightest output pixel is {worst} the reference's local 5x5 "
        f"maximum (worst frame); {count} `svgf` pixel(s) above {HOT_THRESHOLD:g}x over all "
        f"{len(svgf.frames)} frames; "
        + (
            f"above {HOT_THRESHOLD:g}x: {', '.join(f'`{n}`' for n in over)}."
            if over
            else f"no denoiser goes above {HOT_THRESHOLD:g}x."
        )
    )


def _peak_ratio(run: SequenceRun, frame: int) -> str:
    a = next(f for f in run.report.method(SVGF).frames if f.frame == frame).values.get(RELMSE)
    b = next(f for f in run.report.method(SPATIAL).frames if f.frame == frame).values.get(RELMSE)
    return _ratio_text(a, b)


def palette_png(path: Path, colours: int = 256) -> None:
    """Re-encode a PNG with an adaptive palette (median cut, no dither; deterministic)."""
    from PIL import Image

    with Image.open(path) as image:
        rgb = image.convert("RGB")
    small = rgb.quantize(colors=colours, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp.png")
    try:
        small.save(tmp, format="PNG", optimize=True)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_images(run: SequenceRun, methods: Sequence[MethodSpec], images: Path) -> list[str]:
    """The curve plot, the contact sheet (when the sequence names frames) and the JSON."""
    written = []
    name = run.spec.name
    marks = {e.frame: e.text for e in run.spec.events if e.frame in run.report.frames}
    curves = images / f"{name}_curves.png"
    write_curves(run.report, curves, CURVE_KEYS, marks=marks, title=run.spec.folder, dpi=72.0)
    palette_png(curves, 48)
    written.append(curves.name)
    if run.contacts:
        columns = [m.name for m in methods if m.contact] + [INPUT]
        sheet = images / f"{name}_contact.png"
        write_contact_sheet(
            run.report,
            run.contacts,
            sheet,
            methods=columns,
            cell_inches=CONTACT_CELL_INCHES,
            title_size=6.5,
            dpi=CONTACT_DPI,
        )
        palette_png(sheet, 256)
        written.append(sheet.name)
    from svgf_cli.results.perceptual import write_animation

    animation = write_animation(run, images)
    if animation is not None:
        written.append(animation)
    report_json = images / f"{name}.json"
    report_json.write_text(run.report.to_json(), encoding="utf-8")
    written.append(report_json.name)
    return written


def sequence_section(run: SequenceRun, images_dir: str) -> str:
    spec, report = run.spec, run.report
    name = spec.name
    width_height = f" at {run.size[0]}x{run.size[1]}" if run.size[0] else ""
    aovs = f" with `--preset-aovs {spec.aovs}`" if spec.aovs != "svgf" else ""
    lines = [
        f"## `{spec.folder}`",
        "",
        spec.about,
        "",
        f"{len(report.frames)} frames{width_height}, evaluated{aovs}; tags: "
        + ", ".join(f"`{t}`" for t in sorted(spec.tags))
        + ".",
        "",
        "What this shows:",
        "",
        *(f"- {line}" for line in findings(run)),
        "",
        summary_table(report),
        "",
        f"![per-frame relMSE (trimmed), FLIP and temporal error of every method]"
        f"({images_dir}/{name}_curves.png)",
        "",
    ]
    if run.report.displays:
        lines += [
            "Animation, every evaluated frame at 8 fps (input | svgf | OIDN | reference, "
            "tone-mapped as the stills; flicker shows here, not in the stills):",
            "",
            f"![input, svgf, OIDN and reference as an animation]({images_dir}/{name}_anim.webp)",
            "",
        ]
    if run.contacts:
        frames = ", ".join(str(c.frame) for c in run.contacts)
        lines += [
            f"Contact sheet, frame(s) {frames} (tone-mapped as the metrics see them; last "
            "column: FLIP error of `svgf`):",
            "",
            f"![contact sheet]({images_dir}/{name}_contact.png)",
            "",
        ]
    notes = [n for n in run.notes if n.status != "warned"]
    warned = [n for n in run.notes if n.status == "warned"]
    for note in notes:
        lines.append(f"- `{note.method}` {note.status}: {note.text}")
    for note in warned:
        lines.append(f"- `{note.method}` warned: {note.text}")
    if run.notes:
        lines.append("")
    lines += [
        "<details><summary>relMSE (trimmed) per frame</summary>",
        "",
        per_frame_table(report, RELMSE),
        "",
        "</details>",
        "",
        f"Full report (every metric, every frame): [`{images_dir}/{name}.json`]"
        f"({images_dir}/{name}.json).",
        "",
    ]
    return "\n".join(lines)


def methods_table(
    methods: Sequence[MethodSpec], skipped: dict[str, str], notes: Sequence[MethodNote]
) -> str:
    lines = ["| method | made by | what it is | status |", "|---|---|---|---|"]
    problems = {n.method: n for n in notes if n.status in ("skipped", "failed")}
    for method in methods:
        if method.name in skipped:
            status = f"skipped: {skipped[method.name]}"
        elif method.name in problems:
            status = f"{problems[method.name].status} on some sequence (see below)"
        else:
            status = "ran" + (f" (sequences tagged `{method.needs}`)" if method.needs else "")
            status += f" (not on sequences tagged `{method.unless}`)" if method.unless else ""
        lines.append(f"| `{method.name}` | `{method.command}` | {method.about} | {status} |")
    lines.append("| `input` | the noisy 1-spp input itself | raw radiance | ran |")
    return "\n".join(lines)


def checks_table(checks: Sequence[Check]) -> str:
    lines = ["| issue | target | result | numbers |", "|---|---|---|---|"]
    for check in checks:
        lines.append(f"| #{check.issue} | {check.target} | **{check.status}** | {check.numbers} |")
    return "\n".join(lines)


def page(
    runs: Sequence[SequenceRun],
    methods: Sequence[MethodSpec],
    skipped: dict[str, str],
    checks: Sequence[Check],
    images_dir: str = "results",
) -> str:
    notes = [n for run in runs for n in run.notes]
    present = [m.name for m in methods if any(m.name in run.names for run in runs)] + [INPUT]
    text = [
        "# Results",
        "",
        "Generated by `make results` (`python -m svgf_cli.results`); do not edit by hand. "
        "Metric definitions, the tone map and the ranking rule: [evaluate.md](evaluate.md). "
        "What is run and how to add a sequence or a method: `svgf_cli/results/table.py`.",
        "",
        f"- Machine: {machine_description()}",
        f"- Versions: {package_versions()}",
        "- Each `svgf denoise` method runs as the installed command on the sequence (with "
        "`--float --colour-only`, plus the sequence's `--preset-aovs`), then one `svgf "
        "evaluate` pass scores every method against the references; the in-memory baselines "
        "use the default preset's parameters.",
        "- Tables: mean over frames (temporal error from the second frame on; hot max: the "
        "worst frame), best in bold; overall = order of the average rank over RMSE, relMSE, "
        "PSNR, SSIM, FLIP and temporal error. relMSE (trimmed) drops the largest 0.1 % of "
        "per-pixel errors; hot max is the brightest output pixel over the reference's local "
        "5x5 maximum (see [evaluate.md](evaluate.md#metrics)).",
        "",
        "## Methods",
        "",
        methods_table(methods, skipped, notes),
        "",
        "## Issue targets",
        "",
        "Checked automatically from the numbers below (relMSE = relMSE (trimmed)); `make "
        "results` prints the same list.",
        "",
        checks_table(checks),
        "",
        "## All sequences",
        "",
        "ColorVideoVDP, JOD (10 = no visible difference; video: the sequence as one 24 fps "
        "video, still: mean over frames of each frame alone; [evaluate.md](evaluate.md#"
        "colorvideovdp-jod)):",
        "",
        jod_table(runs),
        "",
        "relMSE (trimmed), mean over frames:",
        "",
        overview_table(runs, present, RELMSE),
        "",
        "FLIP, mean over frames:",
        "",
        overview_table(runs, present, "flip"),
        "",
        "Temporal error, mean over frames:",
        "",
        overview_table(runs, present, "temporal"),
        "",
    ]
    for run in runs:
        text.append(sequence_section(run, images_dir))
    return "\n".join(text).rstrip() + "\n"
