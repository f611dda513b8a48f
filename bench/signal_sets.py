"""Measure the signal sets (`svgf denoise --signals`) on the committed renderer fixtures.

For each sequence (Blender Cycles `testdata/cycles/roll` and `metal`, `--preset-aovs
cycles`; the tracer's `testdata/lag/glossy`, `--preset-aovs svgf`) this runs

    svgf denoise 'SEQ/in.####.exr' -o 'OUT/den.####.exr' --preset-aovs P --signals S -q
    svgf evaluate 'OUT/den.####.exr' -r 'SEQ/ref.####.exr' -i 'SEQ/in.####.exr' \\
        --preset-aovs P --signals S [--baseline oidn]

for every signal set S (default filter preset), plus the variants named in VARIANTS, and
prints one Markdown table per sequence: relMSE, FLIP and temporal error (means over the
frames, from `svgf evaluate`), and the hot-pixel figures of `metrics.peak_ratio` (largest
output over the reference's local 5x5 maximum, worst frame; share of pixels above 3x it,
worst frame). The raw input and OIDN rows come from the same evaluation.

Run: ``nice -n 10 .venv/bin/python bench/signal_sets.py [roll metal glossy]`` (outputs under
bench/out/signals/). The commands run in-process (one numba JIT for all).
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from svgf_cli.cli import main as svgf
from svgf_cli.evaluate import metrics
from svgf_cli.evaluate.baselines import InputMethod, OidnMethod
from svgf_cli.evaluate.engine import EvaluationRequest, run_evaluation
from svgf_cli.io import signals as signal_module
from svgf_cli.io.exr import fix_signal_set, read_frame, read_rgb
from svgf_cli.io.layers import SIGNAL_SETS, build_mapping
from svgf_cli.io.patterns import SequencePattern

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "bench" / "out" / "signals"

SEQUENCES = {
    "roll": ("testdata/cycles/roll", "cycles"),
    "metal": ("testdata/cycles/metal", "cycles"),
    "glossy": ("testdata/lag/glossy", "svgf"),
}


@dataclass
class Variant:
    """One denoise run: a signal set, extra options, and an optional in-process patch."""

    label: str
    signals: str
    options: list[str] = field(default_factory=list)
    patch: Callable[[], Callable[[], None]] | None = None


def _albedo_role_for_direct_indirect() -> Callable[[], None]:
    before = dict(signal_module.DIRECT_INDIRECT_ALBEDO)
    signal_module.DIRECT_INDIRECT_ALBEDO["cycles"] = "albedo"

    def undo() -> None:
        signal_module.DIRECT_INDIRECT_ALBEDO.update(before)

    return undo


def variants(preset: str) -> list[Variant]:
    runs = [Variant(name, name) for name in SIGNAL_SETS]
    if preset == "cycles":
        runs.append(Variant("direct-indirect, by Denoising Albedo", "direct-indirect",
                            patch=_albedo_role_for_direct_indirect))
    else:
        runs += [Variant(f"{name}, no gradient samples", name, ["--no-antilag-gradients"])
                 for name in ("lobes", "direct-indirect")]
    return runs


def peak(pattern: str, reference: SequencePattern, frames: list[int],
         image: Callable[[int], np.ndarray]) -> tuple[float, float]:
    """Worst frame's peak ratio and worst frame's share of hot pixels."""
    worst, share = 0.0, 0.0
    for frame in frames:
        ref, _ = read_rgb(reference.path(frame))
        ratio, hot = metrics.peak_ratio(image(frame), ref)
        worst, share = max(worst, ratio), max(share, hot)
    return worst, share


def row(label: str, method: object, peaks: tuple[float, float]) -> str:
    relmse, flip, temporal = (method.mean(k) for k in ("relmse", "flip", "temporal"))  # type: ignore[attr-defined]
    return (f"| {label} | {relmse:.4f} | {flip:.4f} | {temporal:.4f} | {peaks[0]:.2f} | "
            f"{peaks[1]:.3%} |")


def measure(name: str) -> list[str]:
    folder, preset = SEQUENCES[name]
    inputs = str(ROOT / folder / "in.####.exr")
    reference = SequencePattern.parse(str(ROOT / folder / "ref.####.exr"))
    lines = [f"### `{folder}` (`--preset-aovs {preset}`)", "",
             "| method | relMSE | FLIP | temporal | max / local ref max | pixels > 3x |",
             "|---|---|---|---|---|---|"]
    baseline_rows: list[str] = []
    for index, variant in enumerate(variants(preset)):
        undo = variant.patch() if variant.patch else None
        try:
            out = OUT / name / variant.label.replace(", ", "_").replace(" ", "-")
            out.mkdir(parents=True, exist_ok=True)
            pattern = str(out / "den.####.exr")
            argv = ["denoise", inputs, "-o", pattern, "--preset-aovs", preset,
                    "--signals", variant.signals, "-q", "--overwrite", *variant.options]
            try:
                svgf(argv)
            except SystemExit as exc:
                if exc.code:
                    raise RuntimeError(f"svgf {' '.join(argv)} exited {exc.code}") from None
            request = EvaluationRequest(
                output=pattern, reference=str(ROOT / folder / "ref.####.exr"),
                input=inputs, baselines=("oidn",) if index == 0 else (), layers=preset,
                signals=variant.signals,
            )
            report, _ = run_evaluation(request)
            frames = report.frames
            mapping = build_mapping(preset)
            methods = {m.name: m for m in report.methods}
            peaks = peak(pattern, reference, frames,
                         lambda f, p=pattern, m=mapping: read_rgb(
                             p.replace("####", f"{f:04d}"), m)[0])
            lines.append(row(f"svgf `{variant.label}`", methods["svgf"], peaks))
            print(lines[-1], flush=True)
            if index == 0:
                baseline_rows = _baselines(inputs, preset, variant.signals, reference, frames,
                                           methods)
        finally:
            if undo:
                undo()
    return [*lines[:4], *baseline_rows, *lines[4:], ""]


def _baselines(inputs: str, preset: str, signals: str, reference: SequencePattern,
               frames: list[int], methods: dict) -> list[str]:
    """Raw input and OIDN rows (their images recomputed here, as `svgf evaluate` makes them,
    for the peak figures)."""
    pattern = SequencePattern.parse(inputs)
    mapping, _ = fix_signal_set(pattern.path(frames[0]), build_mapping(preset, signals=signals))
    oidn = OidnMethod()
    rows = []
    for label, method, key in (("raw 1 spp input", InputMethod(), "input"),
                               ("OIDN (per frame)", oidn, "oidn")):
        peaks = peak(inputs, reference, frames,
                     lambda f, m=method: m.process(read_frame(pattern.path(f), mapping).frame))
        rows.append(row(label, methods[key], peaks))
        print(rows[-1], flush=True)
    return rows


def main(argv: list[str]) -> int:
    names = argv or list(SEQUENCES)
    out = []
    for name in names:
        out += measure(name)
    print("\n".join(out))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
