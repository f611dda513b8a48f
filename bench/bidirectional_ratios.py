"""Forward-only against bidirectional SVGF on the bundled sequences, in memory (fast).

For every sequence the causal Denoiser (``Denoiser.process`` frame by frame) and
``two_pass.denoise_bidirectional`` with the same parameters (the default preset) over the
frames read as ``svgf denoise`` reads them; references ``ref.####.exr`` next to the inputs
(``seq_box``: testdata/seq's inputs against testdata/seq_box's box-filtered references).
Prints per sequence the mean over frames of trimmed relMSE, FLIP and temporal error for
both and their ratio (bidirectional / forward), the ratios of RMSE and untrimmed relMSE,
the PSNR and SSIM differences, which metrics are worse than forward-only, and the worst of
the first four frames' trimmed relMSE over the sequence mean (forward / bidirectional), and
the cold start with the content held fixed: runs started at every frame from the third to
the fourth-last (no warm-up), their first four frames' mean trimmed relMSE over the same
frames' in the run over the whole sequence, averaged over the starts (forward /
bidirectional; 1.00: no cold start). The "first 4" column mixes the cold start with how
hard the first frames are; this one does not. "steady" is the relMSE ratio over the frames
where both passes are warm (at least ``warm_frames`` from either end: a long causal history's
effective sample count within 10 %); a sequence of 16 frames or fewer has none, and its mean
ratio is mostly the gain of the first frames (a long shot's mean tends to this column).
``bench/bidirectional_eval.py`` measures the same through the CLI (slower).

Run: ``.venv/bin/python bench/bidirectional_ratios.py [--consistency-sigma K] [SEQUENCE ...]``
(``--consistency-sigma`` overrides the consistency test's threshold, e.g. 1e9 to measure the
run without it; ``--set NAME=VALUE`` overrides a parameter of the default preset for both
runs, e.g. ``--set temporal_albedo=True``, ``--set-bidirectional NAME=VALUE`` for the
bidirectional run only). A SEQUENCE is a bundled name or a folder of ``in.####.exr`` and
``ref.####.exr`` (renders not committed), ``FOLDER:cycles`` for Blender's passes.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import OpenImageIO as oiio

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from overrides import parse_overrides  # noqa: E402  (bench/, the script's folder)

from svgf_cli.evaluate.metrics import (  # noqa: E402
    flip,
    psnr,
    relmse,
    relmse_trimmed,
    rmse,
    ssim,
    temporal_error,
    tone_map,
)
from svgf_cli.filters import denoiser as denoiser_module  # noqa: E402
from svgf_cli.filters.bidirectional import effective_counts  # noqa: E402
from svgf_cli.filters.denoiser import Denoiser  # noqa: E402
from svgf_cli.filters.params import resolve_params  # noqa: E402
from svgf_cli.filters.two_pass import denoise_bidirectional  # noqa: E402
from svgf_cli.io.exr import read_frame  # noqa: E402
from svgf_cli.io.layers import build_mapping  # noqa: E402

SEQUENCES = {
    "seq": "svgf", "lag/camera": "svgf", "lag/shadow": "svgf", "lag/light_step": "svgf",
    "lag/light_slide_dim": "svgf", "lag/glossy": "svgf", "cycles/roll": "cycles",
    "cycles/metal": "cycles", "seq_box": "svgf",
}
# Sequences whose references are another sequence's inputs filtered otherwise: testdata/seq's
# inputs against references box-filtered over 4x4 sub-pixel samples (testdata/seq_box).
INPUTS_OF = {"seq_box": "seq"}
LOWER_IS_BETTER = ("relmse_trimmed", "flip", "temporal", "rmse", "relmse")


def read_sequence(name: str, aovs: str) -> tuple[list, list[np.ndarray]]:
    if name in SEQUENCES:
        folder = REPO / "testdata" / INPUTS_OF.get(name, name)
        reference_folder = REPO / "testdata" / name
    else:
        folder = reference_folder = Path(name)
    mapping = build_mapping(aovs, None, None, "auto")
    frames, references = [], []
    index = 1
    while (folder / f"in.{index:04d}.exr").exists():
        frames.append(read_frame(folder / f"in.{index:04d}.exr", mapping).frame)
        reference = reference_folder / f"ref.{index:04d}.exr"
        pixels = oiio.ImageBuf(str(reference)).get_pixels(oiio.FLOAT)
        references.append(np.ascontiguousarray(pixels[..., :3].transpose(2, 0, 1)))
        index += 1
    return frames, references


def metrics(outputs: list[np.ndarray], references: list[np.ndarray]) -> dict[str, Any]:
    per: dict[str, list[float]] = {k: [] for k in (*LOWER_IS_BETTER, "psnr", "ssim")}
    previous = None
    for x, r in zip(outputs, references, strict=True):
        per["relmse_trimmed"].append(relmse_trimmed(x, r))
        per["relmse"].append(relmse(x, r))
        per["rmse"].append(rmse(x, r))
        xd, rd = tone_map(x), tone_map(r)
        per["flip"].append(flip(xd, rd)[0])
        per["psnr"].append(psnr(xd, rd))
        per["ssim"].append(ssim(xd, rd))
        if previous is not None:
            per["temporal"].append(temporal_error(xd, previous[0], rd, previous[1]))
        previous = (xd, rd)
    means: dict[str, Any] = {k: float(np.mean(v)) for k, v in per.items()}
    means["first4"] = max(per["relmse_trimmed"][:4]) / means["relmse_trimmed"]
    means["per_frame"] = per["relmse_trimmed"]
    return means


def warm_frames(alpha: float, cap: int) -> int:
    """Frames a history needs before its effective sample count is within 10 % of a long
    history's (10 at alpha 0.2)."""
    counts = effective_counts(alpha, cap)
    return int(np.argmax(counts >= 0.9 * counts[-1]))


def steady_ratio(forward: list[float], both: list[float], warm: int) -> float | None:
    """Bidirectional's mean per-frame relMSE over forward-only's, both over the frames at
    least ``warm`` from either end (None: the sequence has no such frame)."""
    frames = slice(warm, len(forward) - warm)
    if frames.start >= frames.stop:
        return None
    return float(np.mean(both[frames]) / np.mean(forward[frames]))


def cold_start(frames: list, references: list[np.ndarray], whole: list[float],
               denoise: Callable[[list], list[np.ndarray]]) -> float:
    """Mean trimmed relMSE of the first four frames of a run started at frame ``a`` (no
    warm-up) over the same frames' in the run over the whole sequence (``whole``: its
    per-frame trimmed relMSE), averaged over ``a`` = 2 .. n - 4 (0-based)."""
    ratios = []
    for start in range(2, len(frames) - 3):
        outputs = denoise(frames[start:])[:4]
        chunk = [relmse_trimmed(x, r)
                 for x, r in zip(outputs, references[start:start + 4], strict=True)]
        ratios.append(np.mean(chunk) / np.mean(whole[start:start + 4]))
    return float(np.mean(ratios))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("sequences", nargs="*", default=list(SEQUENCES))
    parser.add_argument("--consistency-sigma", type=float, default=None)
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="override a default-preset parameter (Python literal), e.g."
                        " temporal_albedo=True; repeatable")
    parser.add_argument("--set-bidirectional", action="append", default=[],
                        metavar="NAME=VALUE", help="as --set, for the bidirectional run only")
    args = parser.parse_args()
    if args.consistency_sigma is not None:
        denoiser_module.CONSISTENCY_SIGMA = args.consistency_sigma
    overrides = parse_overrides(args.set)
    params = resolve_params("default", **overrides)
    bidirectional_params = resolve_params(
        "default", **{**overrides, **parse_overrides(args.set_bidirectional)})
    print("| sequence | relMSE (trimmed) fwd / bidir (ratio) | FLIP | temporal | RMSE ratio "
          "| relMSE ratio | PSNR diff | SSIM diff | worse than forward | first 4 / mean "
          "| cold start | steady |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    warm = warm_frames(params.alpha, params.history_cap)

    def causal_run(chunk: list) -> list[np.ndarray]:
        causal = Denoiser(params)
        return [np.ascontiguousarray(causal.process(f).color[:3]) for f in chunk]

    def bidirectional_run(chunk: list) -> list[np.ndarray]:
        outputs = denoise_bidirectional(chunk, bidirectional_params)
        return [np.ascontiguousarray(o.color[:3]) for o in outputs]

    for name in args.sequences:
        path, _, aovs = name.partition(":")
        frames, references = read_sequence(path, SEQUENCES.get(path, aovs or "svgf"))
        forward = metrics(causal_run(frames), references)
        both = metrics(bidirectional_run(frames), references)
        cold = [cold_start(frames, references, run_metrics["per_frame"], run)
                for run_metrics, run in ((forward, causal_run), (both, bidirectional_run))]
        ratio = {k: both[k] / forward[k] for k in LOWER_IS_BETTER}
        worse = [k for k in LOWER_IS_BETTER if both[k] > forward[k]]
        worse += [k for k in ("psnr", "ssim") if both[k] < forward[k]]
        cells = [f"{forward[k]:.4g} / {both[k]:.4g} ({ratio[k]:.2f})"
                 for k in ("relmse_trimmed", "flip", "temporal")]
        print(f"| `{name}` | " + " | ".join(cells)
              + f" | {ratio['rmse']:.2f} | {ratio['relmse']:.2f}"
              + f" | {both['psnr'] - forward['psnr']:+.2f} | {both['ssim'] - forward['ssim']:+.4f}"
              + f" | {', '.join(worse) or '-'}"
              + f" | {forward['first4']:.2f} / {both['first4']:.2f}"
              + f" | {cold[0]:.2f} / {cold[1]:.2f}"
              + f" | {_ratio(steady_ratio(forward['per_frame'], both['per_frame'], warm))} |",
              flush=True)


def _ratio(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"


if __name__ == "__main__":
    main()
