"""Cost of the denoised light layers (issue 31) at 1080p: `svgf denoise` of the production
shot's frames tiled 15 x 15 to 1920x1080 (every channel, 3 light groups), with
`--light-layers denoised` against `as-read`, CPU seconds (user + system of the child).

    nice -n 10 .venv/bin/python bench/light_layers_cost.py [--frames 4] [--tiled DIR]

Prints the CPU seconds per frame of each run and the difference per extra denoised layer
(the light groups and the light passes written denoised).
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import OpenEXR

ROOT = Path(__file__).resolve().parents[1]
SHOT = ROOT / "testdata/cycles/production"


def tile(source: Path, target: Path, reps: tuple[int, int] = (15, 15)) -> None:
    exr = OpenEXR.File(str(source), separate_channels=True)
    part = exr.parts[0]
    header = dict(part.header)
    channels = {n: np.ascontiguousarray(np.tile(c.pixels, reps)) for n, c in part.channels.items()}
    h, w = next(iter(channels.values())).shape
    window = (np.array([0, 0], np.int32), np.array([w - 1, h - 1], np.int32))
    header["dataWindow"] = header["displayWindow"] = window
    OpenEXR.File(header, channels).write(str(target))


def cpu_of(args: list[str]) -> float:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(args, check=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=4)
    parser.add_argument("--tiled", type=Path, help="folder for the tiled frames (kept)")
    parser.add_argument("--repeat", type=int, default=2, help="runs of each mode (best kept)")
    args = parser.parse_args(argv)
    folder = args.tiled or Path(tempfile.mkdtemp(prefix="svgf_light_cost_"))
    folder.mkdir(parents=True, exist_ok=True)
    for frame in range(1, args.frames + 1):
        target = folder / f"in.{frame:04d}.exr"
        if not target.exists():
            tile(SHOT / f"in.{frame:04d}.exr", target)
    svgf = str(ROOT / ".venv/bin/svgf")
    env_threads = os.environ.get("NUMBA_NUM_THREADS", "default")
    results = {}
    for mode in ("as-read", "denoised") * args.repeat:
        out = folder / f"out-{mode}"
        cpu = cpu_of([svgf, "denoise", "-q", "--preset-aovs", "cycles", "--overwrite",
                      str(folder / "in.####.exr"), "-o", f"{out}/", "--light-layers", mode])
        results.setdefault(mode, []).append(cpu / args.frames)
        print(f"{mode:>9}: {cpu:.2f} CPU-s, {cpu / args.frames:.3f} per frame", flush=True)
    extra = min(results["denoised"]) - min(results["as-read"])
    channels = OpenEXR.File(str(folder / "out-denoised" / "in.0001.exr"),
                            separate_channels=True).parts[0].channels
    groups = sum(1 for n in channels if ".Combined_" in n and n.endswith(".R"))
    print(f"threads {env_threads}; extra per frame (best of {args.repeat}): {extra:.3f} CPU-s for "
          f"{groups} light groups and the light passes; per light group (if all of it were "
          f"the groups): {extra / max(groups, 1):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
