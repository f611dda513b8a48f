"""`make results`: regenerate ``docs/results.md`` from the bundled test sequence(s).

For every bundled sequence (a ``testdata/*/`` folder holding ``in.####.exr`` and
``ref.####.exr``): run ``svgf denoise`` into a temporary folder, then evaluate it against the
reference with every baseline (OIDN, accumulate, a-trous) and the raw input, and write the
table, the per-frame plot, the contact sheet and the JSON report under ``docs/results/``.
When no sequence is bundled, a small synthetic one is generated instead (and said so).

Run: ``python -m svgf_cli.results [--docs DIR] [--preset paper] [SEQUENCE_DIR ...]``
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from svgf_cli.evaluate.contact import default_contact_frames, write_contact_sheet
from svgf_cli.evaluate.engine import EvaluationRequest, resolve_frames, run_evaluation
from svgf_cli.evaluate.metrics import METRICS
from svgf_cli.evaluate.plot import write_plot
from svgf_cli.evaluate.report import EvaluationReport
from svgf_cli.evaluate.synthetic import write_synthetic_sequence
from svgf_cli.filters.params import DEFAULT_PRESET, resolve_params
from svgf_cli.io.patterns import SequencePattern

REPO = Path(__file__).resolve().parent.parent
PACKAGES = ("numpy", "numba", "OpenImageIO", "pyoidn", "flip-evaluator", "matplotlib", "click")


def bundled_sequences(root: Path) -> list[Path]:
    """``testdata/*`` folders with both ``in.0001.exr``-style inputs and references."""
    found = []
    for folder in sorted(p for p in (root / "testdata").glob("*") if p.is_dir()):
        if any(folder.glob("in.*.exr")) and any(folder.glob("ref.*.exr")):
            found.append(folder)
    return found


def machine_description() -> str:
    """CPU model, logical cores and OS, for the results header."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} logical cores, {platform.system()} {platform.release()}"


def package_versions() -> str:
    parts = [f"Python {platform.python_version()}"]
    for name in PACKAGES:
        try:
            parts.append(f"{name} {version(name)}")
        except PackageNotFoundError:
            parts.append(f"{name} (not installed)")
    return ", ".join(parts)


def denoise(inputs: str, output: str, preset: str) -> float:
    """Run the real `svgf denoise` command (float output); returns its wall seconds."""
    command = [sys.executable, "-m", "svgf_cli", "denoise", inputs, "-o", output]
    command += ["--preset", preset, "--float", "--quiet"]
    start = time.perf_counter()
    subprocess.run(command, check=True)
    return time.perf_counter() - start


def markdown_table(report: EvaluationReport) -> str:
    """Mean of each metric per method, rank in parentheses, best value in bold."""
    overall = report.overall_ranks()
    order = sorted(report.methods, key=lambda m: (overall[m.name] is None, overall[m.name] or 0))
    head = ["method", *(f"{i.label} {'↑' if i.higher_is_better else '↓'}" for i in METRICS)]
    lines = [
        "| " + " | ".join([*head, "overall rank"]) + " |",
        "|" + "---|" * (len(head) + 1),
    ]
    for method in order:
        cells = [f"`{method.name}`" + (" (FLAGGED: NaN)" if method.flagged else "")]
        for info in METRICS:
            value = method.mean(info.key)
            rank = report.ranks(info.key)[method.name]
            text = _number(value, info.key)
            if rank == 1:
                text = f"**{text}**"
            cells.append(f"{text} ({rank})" if rank else text)
        cells.append(str(overall[method.name] or "-"))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def per_frame_table(report: EvaluationReport, key: str) -> str:
    names = [m.name for m in report.methods]
    lines = ["| frame | " + " | ".join(names) + " |", "|" + "---|" * (len(names) + 1)]
    for index, frame in enumerate(report.frames):
        cells = [_number(m.frames[index].values.get(key), key) for m in report.methods]
        lines.append(f"| {frame} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _number(value: float | None, key: str) -> str:
    if value is None:
        return "–"
    if math.isinf(value):
        return "∞"
    if key == "psnr":
        return f"{value:.2f}"
    if key == "ssim":
        return f"{value:.4f}"
    return f"{value:.4g}"


def evaluate_sequence(
    folder: Path, name: str, docs: Path, work: Path, preset: str, label: str
) -> tuple[str, EvaluationReport]:
    """Denoise, evaluate and draw one sequence; returns its Markdown section."""
    inputs, refs = str(folder / "in.####.exr"), str(folder / "ref.####.exr")
    output_dir = work / "denoised" / name
    output_dir.mkdir(parents=True)
    output = str(output_dir / "den.####.exr")
    seconds = denoise(inputs, output, preset)
    frames = resolve_frames(SequencePattern.parse(output), output, None)
    request = EvaluationRequest(
        output=output,
        reference=refs,
        input=inputs,
        baselines=("oidn", "accumulate", "atrous"),
        params=resolve_params(preset),
        preset=preset,
        contact_frames=default_contact_frames(frames),
    )
    report, contacts = run_evaluation(request)
    images = docs / "results"
    images.mkdir(parents=True, exist_ok=True)
    write_plot(report, images / f"{name}_errors.png")
    write_contact_sheet(report, contacts, images / f"{name}_contact.png")
    # Paths in the published JSON are relative to the repository, not this temp dir.
    report.inputs = {
        "output": f"(svgf denoise --preset {preset} output)",
        "reference": _relative(refs),
        "input": _relative(inputs),
    }
    for method in report.methods:
        for score in method.frames:
            score.file = _relative(score.file) if method.name == "input" else None
    (images / f"{name}.json").write_text(report.to_json(), encoding="utf-8")

    ref0 = next(folder.glob("ref.*.exr"))
    from svgf_cli.io.exr import read_info

    info = read_info(ref0)
    section = [
        f"## `{label}`",
        "",
        f"{len(report.frames)} frames at {info.width}x{info.height}; `svgf denoise --preset "
        f"{preset}` took {seconds:.1f} s wall for the sequence (including start-up and JIT).",
        "",
        markdown_table(report),
        "",
        "Mean over frames; (rank) per metric, 1 = best; the temporal error is averaged from "
        "the second frame on. Overall rank = order of the average per-metric rank.",
        "",
        "### relMSE per frame",
        "",
        per_frame_table(report, "relmse"),
        "",
        "### Temporal error per frame",
        "",
        per_frame_table(report, "temporal"),
        "",
        f"![per-frame errors](results/{name}_errors.png)",
        "",
        f"![contact sheet](results/{name}_contact.png)",
        "",
        f"Full report: [`results/{name}.json`](results/{name}.json).",
        "",
    ]
    return "\n".join(section), report


def _relative(path: str | None) -> str | None:
    if path is None:
        return None
    try:
        return str(Path(path).resolve().relative_to(REPO))
    except ValueError:
        return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sequences", nargs="*", type=Path, help="sequence folders")
    parser.add_argument("--docs", type=Path, default=REPO / "docs")
    parser.add_argument("--preset", default=DEFAULT_PRESET)
    args = parser.parse_args(argv)

    sections = []
    with tempfile.TemporaryDirectory(prefix="svgf-results-") as tmp:
        work = Path(tmp)
        folders = args.sequences or bundled_sequences(REPO)
        note = ""
        if not folders:
            folder = work / "inputs" / "synthetic"
            write_synthetic_sequence(folder, frames=10, width=128, height=72)
            folders = [folder]
            note = (
                "> No bundled sequence was found under `testdata/`, so these numbers are for "
                "the synthetic sequence of `svgf_cli/evaluate/synthetic.py` (128x72, 10 "
                "frames).\n\n"
            )
        for folder in folders:
            name = folder.name
            print(f"results: {name}: denoise + evaluate", flush=True)
            label = "synthetic" if note else str(_relative(str(folder)))
            section, _ = evaluate_sequence(folder, name, args.docs, work, args.preset, label)
            sections.append(section)

    text = "\n".join(
        [
            "# Results",
            "",
            "Generated by `make results` (`python -m svgf_cli.results`); do not edit by hand.",
            "Metric definitions, the tone map and the ranking rule: see "
            "[evaluate.md](evaluate.md).",
            "",
            f"- Machine: {machine_description()}",
            f"- Versions: {package_versions()}",
            f"- SVGF preset: `{args.preset}`; baselines: Intel OIDN (RT, HDR, clean albedo + "
            "normal, quality high, per frame), `accumulate` (temporal accumulation only), "
            "`atrous` (a-trous without temporal reuse), and the raw `input`.",
            "",
            note + "\n".join(sections),
        ]
    )
    args.docs.mkdir(parents=True, exist_ok=True)
    (args.docs / "results.md").write_text(text.rstrip() + "\n", encoding="utf-8")
    print(f"results: wrote {args.docs / 'results.md'}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
