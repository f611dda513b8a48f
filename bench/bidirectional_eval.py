"""Forward-only against bidirectional SVGF on the bundled sequences (docs/bidirectional.md).

For every sequence: `svgf denoise` (causal, float) into a temporary folder, then
`svgf evaluate` of it with `--baseline bidirectional` (the real bidirectional driver), the
same SVGF parameters (the default preset). Prints per sequence the mean of every metric for
both, their ratio, the first four frames' relMSE against the sequence mean, and the
per-frame relMSE; and the error the half-float spill adds (in-memory run with float32
histories against the half-float ones). Writes the JSON reports to --out when given.

Run: ``.venv/bin/python bench/bidirectional_eval.py [--out DIR] [SEQUENCE ...]``
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

SEQUENCES = {
    "seq": "svgf", "lag/camera": "svgf", "lag/shadow": "svgf", "lag/light_step": "svgf",
    "lag/light_slide_dim": "svgf", "lag/glossy": "svgf", "cycles/roll": "cycles",
    "cycles/metal": "cycles",
}
METRICS = ("relmse", "rmse", "psnr", "ssim", "flip", "temporal")


def evaluate(name: str, aovs: str, work: Path) -> dict:
    folder = REPO / "testdata" / name
    out = work / name.replace("/", "_")
    subprocess.run([sys.executable, "-m", "svgf_cli", "denoise", str(folder / "in.####.exr"),
                    "-o", str(out / "o.####.exr"), "--float", "-q", "--preset-aovs", aovs,
                    "--overwrite"], check=True)
    report = work / f"{out.name}.json"
    subprocess.run([sys.executable, "-m", "svgf_cli", "evaluate", str(out / "o.####.exr"),
                    "-r", str(folder / "ref.####.exr"), "-i", str(folder / "in.####.exr"),
                    "--preset-aovs", aovs, "--baseline", "bidirectional", "-q",
                    "--json", str(report)], check=True, stdout=subprocess.DEVNULL)
    return json.loads(report.read_text())


def spill_error(name: str, aovs: str) -> tuple[float, float]:
    """(mean, max) |half - float32 spill| / mean |output| over a sequence's outputs."""
    from svgf_cli.filters.params import resolve_params
    from svgf_cli.filters.two_pass import denoise_bidirectional
    from svgf_cli.io.exr import read_frame
    from svgf_cli.io.layers import build_mapping

    mapping = build_mapping(aovs)
    files = sorted((REPO / "testdata" / name).glob("in.*.exr"))
    frames = [read_frame(f, mapping).frame for f in files]
    params = resolve_params("default", bidirectional=True)
    exact = denoise_bidirectional(frames, params)
    half = denoise_bidirectional(frames, params, half=True)
    scale = np.mean([np.abs(o.color).mean() for o in exact])
    diffs = [np.abs(a.color - b.color) for a, b in zip(exact, half, strict=True)]
    return (float(np.mean([d.mean() for d in diffs]) / scale),
            float(max(d.max() for d in diffs) / scale))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sequences", nargs="*", default=list(SEQUENCES))
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="svgf-bidir-eval-") as tmp:
        work = args.out or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        print("| sequence | " + " | ".join(f"{m} fw / bi (ratio)" for m in METRICS)
              + " | first 4 relMSE / mean fw, bi | spill error mean, max |")
        print("|---" * (len(METRICS) + 3) + "|")
        curves = []
        for name in args.sequences:
            aovs = SEQUENCES.get(name, "svgf")
            report = evaluate(name, aovs, work)
            methods = {m["name"]: m for m in report["methods"]}
            fw, bi = methods["svgf"], methods["bidirectional"]
            cells = []
            for key in METRICS:
                a, b = fw["mean"][key], bi["mean"][key]
                cells.append(f"{a:.4g} / {b:.4g} ({b / a:.2f})")
            rel_fw = [f["relmse"] for f in fw["frames"]]
            rel_bi = [f["relmse"] for f in bi["frames"]]
            first = (f"{np.mean(rel_fw[:4]) / np.mean(rel_fw):.2f} (max "
                     f"{max(rel_fw[:4]) / np.mean(rel_fw):.2f}), "
                     f"{np.mean(rel_bi[:4]) / np.mean(rel_bi):.2f} (max "
                     f"{max(rel_bi[:4]) / np.mean(rel_bi):.2f})")
            mean_err, max_err = spill_error(name, aovs)
            print(f"| {name} | " + " | ".join(cells) + f" | {first} | "
                  f"{mean_err:.1e}, {max_err:.1e} |", flush=True)
            curves.append((name, rel_fw, rel_bi))
        print("\nper-frame relMSE (forward / bidirectional):")
        for name, rel_fw, rel_bi in curves:
            print(f"{name}: " + " ".join(f"{a:.4g}/{b:.4g}" for a, b in
                                         zip(rel_fw, rel_bi, strict=True)))
    print(f"({time.perf_counter() - started:.0f} s wall)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
