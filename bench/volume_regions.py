"""relMSE inside a volume (issue 30): the whole frame and the pixels whose reference light is
mostly the medium's, per frame, for the input, OIDN-high with its noisy-aux prefilter and
svgf outputs.

    .venv/bin/python bench/volume_regions.py testdata/cycles/production \\
        [--compare NAME=DIR ...] [--share 0.3]

``DIR`` holds ``o.####.exr`` (e.g. ``svgf denoise ... -o DIR/o.####.exr``); without any
``--compare`` the sequence is denoised with the default settings into a temporary folder.
The reference (``ref.####.exr``, multilayer, Cycles' light passes) must carry ``VolumeDir``
and ``VolumeInd``: the volume region is where their sum's mean over RGB is over ``--share``
of ``Combined``'s. Whole frame: trimmed relMSE (`svgf evaluate`'s); inside the volume: the
mean per-pixel relMSE there.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import OpenEXR

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from svgf_cli.evaluate.baselines import InputMethod, OidnMethod  # noqa: E402
from svgf_cli.evaluate.metrics import per_pixel_relmse, relmse_trimmed  # noqa: E402
from svgf_cli.io.exr import read_frame, read_rgb  # noqa: E402
from svgf_cli.io.layers import build_mapping  # noqa: E402


def reference(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The reference's colour and its volume light, (3, H, W) float64 each."""
    with OpenEXR.File(str(path), separate_channels=True) as exr:
        channels = {n: c.pixels.astype(np.float64) for n, c in exr.parts[0].channels.items()}

    def layer(name: str) -> np.ndarray:
        return np.stack([channels[f"ViewLayer.{name}.{c}"] for c in "RGB"])

    return layer("Combined"), layer("VolumeDir") + layer("VolumeInd")


def scores(sequence: Path, outputs: dict[str, Path], share: float) -> dict[str, np.ndarray]:
    """Per method, per frame: (whole-frame trimmed relMSE, volume relMSE, volume share)."""
    mapping = build_mapping("cycles")
    methods = {"input": InputMethod(), "oidn": OidnMethod(prefilter=True)}
    rows: dict[str, list[tuple[float, float, float]]] = {}
    for path in sorted(sequence.glob("in.*.exr")):
        frame_number = path.name.split(".")[1]
        colour, volume = reference(sequence / f"ref.{frame_number}.exr")
        inside = volume.mean(axis=0) > share * np.maximum(colour.mean(axis=0), 1e-6)
        frame = read_frame(path, mapping).frame
        images = {name: m.process(frame) for name, m in methods.items()}
        for name, folder in outputs.items():
            images[name] = read_rgb(folder / f"o.{frame_number}.exr", mapping)[0]
        for name, image in images.items():
            x = image.astype(np.float64)
            per_pixel = per_pixel_relmse(x, colour)
            per_pixel = per_pixel.mean(axis=0) if per_pixel.ndim == 3 else per_pixel
            rows.setdefault(name, []).append(
                (relmse_trimmed(x, colour), float(per_pixel[inside].mean()), float(inside.mean())))
    return {name: np.array(r) for name, r in rows.items()}


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sequence", type=Path)
    parser.add_argument("--compare", action="append", default=[], metavar="NAME=DIR")
    parser.add_argument("--share", type=float, default=0.3)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="svgf-volume-") as tmp:
        outputs = {n: Path(d) for n, d in (c.split("=", 1) for c in args.compare)}
        if not outputs:
            subprocess.run([sys.executable, "-m", "svgf_cli", "denoise",
                            str(args.sequence / "in.####.exr"), "-o", f"{tmp}/o.####.exr",
                            "--preset-aovs", "cycles", "-q"], check=True, cwd=ROOT)
            outputs = {"svgf": Path(tmp)}
        table = scores(args.sequence, outputs, args.share)
    print(f"volume region: {table['input'][:, 2].mean():.3f} of the frame "
          f"(reference volume light > {args.share:g} of the pixel's)")
    print(f"{'method':14s} {'whole':>7s} {'volume':>7s}   volume per frame")
    for name, r in table.items():
        print(f"{name:14s} {r[:, 0].mean():7.4f} {r[:, 1].mean():7.4f}   "
              + " ".join(f"{v:.3f}" for v in r[:, 1]))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
