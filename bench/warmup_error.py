"""How far is a chunk with a bounded warm-up from the sequential run (`--warmup all`)?

For every possible chunk start ``a`` whose warm-up of ``N`` frames does not reach back to the
first frame (so history really is cut), run the Denoiser over frames ``a-N .. a`` and compare
frame ``a``, the first output frame of such a chunk (where the seam is largest), with the same
frame of one sequential run. Differences are on the float32 output colour, before any
half-float rounding.

Prints, per warm-up N: the number of chunk starts measured, the largest absolute difference of
any pixel channel, and the mean absolute difference relative to the mean absolute output
(mean over starts and the worst start).

Run: ``.venv/bin/python bench/warmup_error.py 'testdata/seq/in.####.exr' [more patterns]
[--warmup 4 8 16 24] [--preset paper]``.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from svgf_cli.filters.denoiser import Denoiser
from svgf_cli.filters.params import resolve_params
from svgf_cli.io.exr import read_frame
from svgf_cli.io.layers import build_mapping
from svgf_cli.io.patterns import expand_inputs


def measure(pattern: str, warmups: list[int], preset: str) -> list[str]:
    params = resolve_params(preset)
    mapping = build_mapping("svgf")
    frames = [read_frame(path, mapping).frame for _, path in expand_inputs([pattern])]
    sequential_denoiser = Denoiser(params)
    sequential = [sequential_denoiser.process(f).color.copy() for f in frames]
    rows = [f"{pattern}: {len(frames)} frames, preset {preset}"]
    rows.append("| warm-up N | chunk starts | max abs diff | mean rel diff | worst rel diff |")
    rows.append("|---|---|---|---|---|")
    for warmup in warmups:
        max_abs, rel = 0.0, []
        for start in range(warmup + 1, len(frames)):
            denoiser = Denoiser(params)
            for frame in frames[start - warmup : start]:
                denoiser.process(frame)
            chunk = denoiser.process(frames[start]).color
            diff = np.abs(chunk.astype(np.float64) - sequential[start])
            max_abs = max(max_abs, float(diff.max()))
            rel.append(float(diff.mean() / max(np.abs(sequential[start]).mean(), 1e-12)))
        if not rel:
            rows.append(f"| {warmup} | 0 (the warm-up reaches the first frame) | 0 | 0 | 0 |")
            continue
        rows.append(
            f"| {warmup} | {len(rel)} | {max_abs:.3g} | {100 * np.mean(rel):.3g} % "
            f"| {100 * max(rel):.3g} % |"
        )
    return rows


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("patterns", nargs="+")
    parser.add_argument("--warmup", type=int, nargs="+", default=[4, 8, 16, 24])
    parser.add_argument("--preset", default="paper")
    args = parser.parse_args(argv)
    for pattern in args.patterns:
        print("\n".join(measure(pattern, args.warmup, args.preset)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
