"""Split the denoised output's error into bias and variance, forward-only and bidirectional.

A denoiser's relMSE against a converged reference is, per pixel, the square of its bias (the
mean output over all noise realisations minus the reference: blur, lag, clamped energy) plus
its variance (how much the output moves with the noise). One render shows only their sum;
several renders of the same frames with other seeds (``svgf trace --seed``) separate them.
With ``K`` realisations ``o_k`` of a pixel, mean ``m`` and unbiased sample variance ``s^2``:

* variance: ``s^2 / (r^2 + eps)``;
* bias squared: ``(m - r)^2 / (r^2 + eps) - s^2 / (K (r^2 + eps))`` (the mean still holds
  ``1/K`` of the variance; subtracted, the estimate is unbiased, so it can be slightly
  negative where the bias is nil). The reference's own noise counts as bias.

Both are averaged over channels, pixels and the chosen frames (untrimmed relMSE, ``eps`` as in
``svgf evaluate``) and reported for the whole image, for pixels next to a geometric edge
(depth jump above 5 % or another mesh in the 3x3 neighbourhood: where reprojection and the
a-trous stop at edges) and for the rest. ``docs/bidirectional.md`` has the numbers.

Run (renders the lag sequence ``camera`` at 256x144 with five seeds first, references at
2048 samples for seed 0 only; several CPU minutes):
``.venv/bin/python bench/bias_variance.py --render camera --resolution 256x144 --seeds 5
--out /tmp/bv``; on renders you made: ``.venv/bin/python bench/bias_variance.py --reference
DIR --inputs DIR DIR ... [--aovs svgf] [--frames 5-12] [--set NAME=VALUE]`` (each input
folder holds ``in.####.exr``, the reference folder ``ref.####.exr``, numbered alike). For
the Blender renders: ``testdata/cycles/render.py --what inputs --input-seed N --out DIR`` for
a few N, then ``--aovs cycles --reference testdata/cycles/roll --inputs testdata/cycles/roll
DIR1/roll ...``.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "testdata"))

from overrides import parse_overrides  # noqa: E402  (bench/, the script's folder)

from svgf_cli.evaluate.metrics import RELMSE_EPSILON  # noqa: E402
from svgf_cli.filters.denoiser import Denoiser  # noqa: E402
from svgf_cli.filters.params import SVGFParams, resolve_params  # noqa: E402
from svgf_cli.filters.two_pass import denoise_bidirectional  # noqa: E402
from svgf_cli.frame import Frame  # noqa: E402
from svgf_cli.io.exr import read_frame  # noqa: E402
from svgf_cli.io.layers import build_mapping  # noqa: E402

# A neighbour this much farther than the pixel (or nearer) marks a depth edge.
DEPTH_JUMP = 1.05


def render(name: str, resolution: str, seeds: int, out: Path) -> tuple[Path, list[Path]]:
    """Render the lag sequence ``name`` with seeds 0 .. seeds-1 under ``out`` (testdata/
    make_lag.py's command; the reference with seed 0 only). Returns the reference folder and
    the input folders."""
    from make_lag import trace_command

    svgf = str(Path(sys.executable).with_name("svgf"))
    folders = []
    for seed in range(seeds):
        root = out / f"seed{seed}"
        (root / name).mkdir(parents=True, exist_ok=True)
        command = trace_command(name, svgf, resolution, root.resolve(), seed=seed,
                                reference=seed == 0)
        print(" ".join(command), flush=True)
        subprocess.run(["nice", "-n", "10", *command], check=True, cwd=REPO)
        folders.append(root / name)
    return folders[0], folders


def numbered(folder: Path, prefix: str) -> dict[int, Path]:
    """``prefix.####.exr`` files of ``folder`` by frame number."""
    files = {}
    for path in folder.glob(f"{prefix}.*.exr"):
        number = path.name[len(prefix) + 1:-4]
        if number.isdigit():
            files[int(number)] = path
    return files


def edge_mask(frame: Frame) -> np.ndarray:
    """Surface pixels whose 3x3 neighbourhood holds a depth jump, another mesh or the
    background (depth 0)."""
    height, width = frame.depth.shape
    depth = np.pad(frame.depth, 1, mode="edge")
    mesh = np.pad(frame.mesh_id, 1, mode="edge")
    centre_depth, centre_mesh = frame.depth, frame.mesh_id
    edge = np.zeros((height, width), dtype=bool)
    for dy in (0, 1, 2):
        for dx in (0, 1, 2):
            other = depth[dy:dy + height, dx:dx + width]
            with np.errstate(invalid="ignore", divide="ignore"):
                ratio = np.maximum(other, centre_depth) / np.minimum(other, centre_depth)
            edge |= ~(ratio <= DEPTH_JUMP)  # a background neighbour: inf, an edge
            edge |= mesh[dy:dy + height, dx:dx + width] != centre_mesh
    return edge & (centre_depth > 0)


def split(outputs: np.ndarray, reference: np.ndarray,
          masks: np.ndarray) -> dict[str, tuple[float, float]]:
    """(bias squared, variance) per region; outputs (K, T, 3, H, W), reference (T, 3, H, W),
    masks (T, H, W) of edge pixels."""
    count = outputs.shape[0]
    weight = 1.0 / (reference * reference + RELMSE_EPSILON)
    mean = outputs.mean(axis=0)
    variance = (outputs.var(axis=0, ddof=1) * weight).mean(axis=1)
    bias = ((mean - reference) ** 2 * weight).mean(axis=1) - variance / count
    regions = {"all": np.ones_like(masks), "edges": masks, "rest": ~masks}
    # Each region's share of the image-wide mean (the three columns add up).
    return {name: (float(bias[m].sum() / m.size), float(variance[m].sum() / m.size))
            for name, m in regions.items()}


def run_all(folders: list[Path], numbers: list[int], aovs: str,
            denoise: Callable[[list[Frame]], list[np.ndarray]]) -> np.ndarray:
    mapping = build_mapping(aovs, None, None, "auto")
    outputs = []
    for folder in folders:
        inputs = numbered(folder, "in")
        frames = [read_frame(inputs[n], mapping).frame for n in numbers]
        outputs.append(np.stack(denoise(frames)).astype(np.float64))
    return np.stack(outputs)


def forward(params: SVGFParams) -> Callable[[list[Frame]], list[np.ndarray]]:
    def run(frames: list[Frame]) -> list[np.ndarray]:
        denoiser = Denoiser(params)
        return [denoiser.process(frame).color[:3].copy() for frame in frames]
    return run


def bidirectional(params: SVGFParams) -> Callable[[list[Frame]], list[np.ndarray]]:
    def run(frames: list[Frame]) -> list[np.ndarray]:
        return [out.color[:3].copy() for out in denoise_bidirectional(frames, params)]
    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--reference", type=Path, help="folder of ref.####.exr")
    parser.add_argument("--inputs", type=Path, nargs="*", default=[],
                        help="folders of in.####.exr, one per noise realisation (at least 2)")
    parser.add_argument("--render", metavar="NAME", help="a testdata/make_lag.py sequence")
    parser.add_argument("--resolution", default="256x144")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--out", type=Path, default=Path("/tmp/svgf_bias_variance"))
    parser.add_argument("--aovs", default="svgf")
    parser.add_argument("--frames", default=None, metavar="A-B",
                        help="frames to average over (default: all but the first 4 and the last "
                             "4, where the sequence's ends dominate)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="override a default-preset parameter (Python literal); repeatable")
    parser.add_argument("--runs", default="forward,bidirectional",
                        help="comma-separated runs to split: forward, bidirectional")
    args = parser.parse_args()
    if args.render:
        reference, inputs = render(args.render, args.resolution, args.seeds, args.out)
    elif args.reference is not None and len(args.inputs) >= 2:
        reference, inputs = args.reference, args.inputs
    else:
        parser.error("give --render NAME, or --reference DIR and two or more --inputs DIR")
    references = numbered(reference, "ref")
    # Every run covers all common frames (history before the measured ones), then is cut.
    everything = sorted(set(references).intersection(*(numbered(f, "in") for f in inputs)))
    numbers = everything
    if args.frames:
        first, _, last = args.frames.partition("-")
        numbers = [n for n in numbers if int(first) <= n <= int(last or first)]
    elif len(numbers) > 12:
        numbers = numbers[4:-4]
    params = resolve_params("default", **parse_overrides(args.set))
    mapping = build_mapping(args.aovs, None, None, "auto")
    masks = np.stack([edge_mask(read_frame(numbered(inputs[0], "in")[n], mapping).frame)
                      for n in numbers])
    truth = np.stack([oiio.ImageBuf(str(references[n])).get_pixels(oiio.FLOAT)[..., :3]
                      .transpose(2, 0, 1).astype(np.float64) for n in numbers])
    print(f"{len(inputs)} realisations, frames {numbers[0]}-{numbers[-1]}, "
          f"edge pixels {masks.mean():.1%}; relMSE = bias^2 + variance")
    print("| run | all: bias^2 + variance | edges: bias^2 + variance | rest: bias^2 + variance |")
    print("|---|---|---|---|")
    runs = {"forward": ("forward-only", forward), "bidirectional": ("bidirectional", bidirectional)}
    chosen = [name.strip() for name in args.runs.split(",") if name.strip()]
    if not chosen or any(name not in runs for name in chosen):
        parser.error(f"--runs takes a comma-separated list of {', '.join(runs)}")
    for label, make in (runs[name] for name in chosen):
        outputs = run_all(inputs, everything, args.aovs, make(params))
        keep = [everything.index(n) for n in numbers]
        parts = split(outputs[:, keep], truth, masks)
        cells = [f"{b + v:.3g} = {b:.3g} + {v:.3g}" for b, v in parts.values()]
        print(f"| {label} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
