"""The light groups against OIDN run per layer: each group of an input sequence denoised by
OIDN frame by frame ('high', its noisy albedo and normal prefiltered, as Blender's Denoise
node does), against svgf's output of the same sequence, both scored against the reference's
same group (relMSE trimmed per frame and its mean; temporal error from the second frame).

    .venv/bin/python bench/light_layers_oidn.py SEQ SVGF_OUTPUT

``SEQ`` holds ``in.####.exr`` and ``ref.####.exr`` (Cycles light groups ``Combined_<name>``);
``SVGF_OUTPUT`` holds svgf's outputs under the same names (`svgf denoise SEQ/in.####.exr -o
OUT/in.####.exr --preset-aovs cycles`). OIDN's groups do not add up to its beauty.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np
import OpenEXR

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from svgf_cli.evaluate.baselines import OidnMethod  # noqa: E402
from svgf_cli.evaluate.metrics import relmse_trimmed, temporal_error, tone_map  # noqa: E402
from svgf_cli.frame import Signal  # noqa: E402
from svgf_cli.io.exr import fix_signal_set, read_frame  # noqa: E402
from svgf_cli.io.layers import build_mapping  # noqa: E402

METHODS = ("input", "svgf", "oidn")


def layer(path: Path, name: str) -> np.ndarray:
    """The (3, H, W) float32 layer ``name`` (``<view>.<name>.R/G/B``), non-finite as 0."""
    channels = OpenEXR.File(str(path), separate_channels=True).parts[0].channels
    prefix = next(c for c in channels if c.endswith(f".{name}.R"))[:-2]
    plane = np.stack([channels[f"{prefix}.{c}"].pixels.astype(np.float32) for c in "RGB"])
    return np.nan_to_num(plane, nan=0.0, posinf=0.0, neginf=0.0)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sequence", type=Path)
    parser.add_argument("output", type=Path)
    args = parser.parse_args(argv)
    paths = sorted(args.sequence.glob("in.*.exr"))
    mapping, _ = fix_signal_set(paths[0], build_mapping("cycles"))
    names = ["Combined"] + sorted(
        c.rsplit(".", 2)[-2] for c in OpenEXR.File(str(paths[0]), separate_channels=True)
        .parts[0].channels if c.endswith(".R") and ".Combined_" in c)
    oidn = OidnMethod(prefilter=True)
    scores: dict[str, list[list[float]]] = {n: [] for n in names}
    flicker: dict[str, list[list[float]]] = {n: [] for n in names}
    previous: dict[str, list[np.ndarray]] = {}
    for path in paths:
        frame = read_frame(path, mapping).frame
        reference = path.with_name(path.name.replace("in.", "ref.", 1))
        for name in names:
            noisy, truth = layer(path, name), layer(reference, name)
            alone = dataclasses.replace(frame, signals=[Signal("layer", noisy, frame.albedo)],
                                        emission=None, final_colour=None, light=None)
            results = (noisy, layer(args.output / path.name, name), oidn.process(alone))
            scores[name].append([relmse_trimmed(x, truth) for x in results])
            shown = [tone_map(x) for x in (*results, truth)]
            if name in previous:
                before = previous[name]
                flicker[name].append([temporal_error(shown[i], before[i], shown[3], before[3])
                                      for i in range(len(METHODS))])
            previous[name] = shown
    print("layer            " + "".join(f"{m:>9}" for m in METHODS) + "  temporal:"
          + "".join(f"{m:>9}" for m in METHODS))
    for name in names:
        means, temporal = np.mean(scores[name], axis=0), np.mean(flicker[name], axis=0)
        print(f"{name:16} " + "".join(f"{v:9.4f}" for v in means) + "           "
              + "".join(f"{v:9.4f}" for v in temporal))
        for i, method in enumerate(METHODS[1:], start=1):
            curve = " ".join(f"{row[i]:.4f}" for row in scores[name])
            print(f"    per frame {method}: {curve}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
