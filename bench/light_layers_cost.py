"""Cost of the denoised light layers (issue 31) at 1080p: `svgf denoise` with
`--light-layers denoised` against `as-read`, end to end, the two runs alternated
(``--repeat`` pairs), wall and CPU seconds (user + system of the child).

    nice -n 10 .venv/bin/python bench/light_layers_cost.py [--frames 4] [--tiled DIR]
    .venv/bin/python bench/light_layers_cost.py --frames-dir bench/out/production/production
    .venv/bin/python bench/light_layers_cost.py --tiled DIR --parts

The frames: the committed production shot's tiled 15 x 15 to 1920x1080 (every channel, 3
light groups; its fog boxes then cover the frame, as a defocused or smoky shot's noisy
outlines do), or ``--frames-dir``'s ``in.####.exr`` (the real 1080p render of
`bench/production_frames.py`). Prints each run, then the medians per frame and the extra
per denoised light layer (the light groups and light passes the denoised output writes
anew: the issue's "each extra denoised layer", ~0.15 s a frame end to end on 2 cores).
With ``--parts``: in this process, `LayeredDenoiser.process` on the same frames, wall and
CPU seconds per frame of its parts (the colour's filter, the groups' filter,
`write_passes`, `compose_groups`, the rest; and within the filters, each one's
``fill_medium`` stage), the mean over the frames after the first, best of ``--repeat``.
Running it from a baseline worktree times that tree.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import OpenEXR

ROOT = Path(__file__).resolve().parents[1]
SHOT = ROOT / "testdata/cycles/production"
sys.path.insert(0, str(ROOT))


def tile(source: Path, target: Path, reps: tuple[int, int] = (15, 15)) -> None:
    exr = OpenEXR.File(str(source), separate_channels=True)
    part = exr.parts[0]
    header = dict(part.header)
    channels = {n: np.ascontiguousarray(np.tile(c.pixels, reps)) for n, c in part.channels.items()}
    h, w = next(iter(channels.values())).shape
    window = (np.array([0, 0], np.int32), np.array([w - 1, h - 1], np.int32))
    header["dataWindow"] = header["displayWindow"] = window
    OpenEXR.File(header, channels).write(str(target))


def timed(args: list[str]) -> tuple[float, float]:
    """Wall and CPU (user + system) seconds of the command ``args``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    subprocess.run(args, check=True)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def denoised_layers(folder: Path) -> list[str]:
    """The layers the denoised output of the first frame writes anew (its channels that
    differ from the as-read output's)."""
    name = "in.0001.exr"
    ours = OpenEXR.File(str(folder / "out-denoised" / name), separate_channels=True)
    read = OpenEXR.File(str(folder / "out-as-read" / name), separate_channels=True)
    theirs = read.parts[0].channels
    return sorted({n.rsplit(".", 1)[0] for n, c in ours.parts[0].channels.items()
                   if not np.array_equal(c.pixels, theirs[n].pixels)} - {"ViewLayer.Combined"})


Clock = dict[str, list[float]]  # part -> [wall, CPU] seconds


def clocked(function: Callable[..., Any], clock: Clock, part: str) -> Callable[..., Any]:
    """``function``, adding the wall and CPU seconds of each call to ``clock[part]``."""

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        wall, cpu = time.perf_counter(), time.process_time()
        result = function(*args, **kwargs)
        spent = clock.setdefault(part, [0.0, 0.0])
        spent[0] += time.perf_counter() - wall
        spent[1] += time.process_time() - cpu
        return result

    return wrapper


def parts(folder: Path, frames: int, repeat: int) -> None:
    """Print the wall and CPU seconds per frame of `LayeredDenoiser.process`'s parts."""
    from svgf_cli.filters import composable
    from svgf_cli.filters.params import PRESETS
    from svgf_cli.io.exr import fix_signal_set, read_frame
    from svgf_cli.io.layers import build_mapping
    from svgf_cli.io.lightlayers import read_light_layers

    paths = [folder / f"in.{frame:04d}.exr" for frame in range(1, frames + 1)]
    mapping, _ = fix_signal_set(paths[0], build_mapping("cycles"))
    clock: Clock = {}
    inner = ("colour filter", "groups filter", "write_passes", "compose_groups")
    for name in inner[2:]:
        setattr(composable, name, clocked(getattr(composable, name), clock, name))
    layered = composable.LayeredDenoiser(PRESETS["default"])
    filters = {"colour": layered.colour, "groups": layered.groups}
    for name, denoiser in filters.items():
        denoiser._run = clocked(denoiser._run, clock, f"{name} filter")  # type: ignore[method-assign]
    process = clocked(layered.process, clock, "process")
    best: Clock = {}
    for _ in range(repeat):
        layered.reset()
        clock.clear()
        for index, path in enumerate(paths):
            result = read_frame(path, mapping)
            result.frame.light = read_light_layers(result, "cycles")
            if index == 1:
                clock.clear()  # the first frame: no history, and JIT caches loaded
            process(result.frame)
            for name, denoiser in filters.items():
                spent = clock.setdefault(f"{name} fill_medium", [0.0, 0.0])
                spent[0] += denoiser.stage_seconds.get("medium", 0.0)
                spent[1] += denoiser.stage_cpu_seconds.get("medium", 0.0)
        clock["rest"] = [clock["process"][i] - sum(clock.get(k, [0.0, 0.0])[i] for k in inner)
                         for i in range(2)]
        for part, (wall, cpu) in clock.items():
            per_frame = [wall / (frames - 1), cpu / (frames - 1)]
            if part not in best or per_frame[0] < best[part][0]:
                best[part] = per_frame
    print(f"per frame over frames 2-{frames}, best of {repeat} (wall s, CPU s):")
    for part, (wall, cpu) in best.items():
        print(f"  {part:>20}: {wall:7.3f} {cpu:7.3f}")


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=4)
    parser.add_argument("--tiled", type=Path, help="folder for the tiled frames (kept)")
    parser.add_argument("--frames-dir", type=Path,
                        help="real 1080p frames in.####.exr instead of the tiled shot")
    parser.add_argument("--repeat", type=int, default=3,
                        help="runs of each mode, alternated (the median is kept; --parts: best)")
    parser.add_argument("--parts", action="store_true",
                        help="time LayeredDenoiser.process's parts in this process instead")
    args = parser.parse_args(argv)
    out_root = args.tiled or Path(tempfile.mkdtemp(prefix="svgf_light_cost_"))
    out_root.mkdir(parents=True, exist_ok=True)
    folder = args.frames_dir or out_root
    for frame in range(1, args.frames + 1):
        target = folder / f"in.{frame:04d}.exr"
        if not target.exists():
            tile(SHOT / f"in.{frame:04d}.exr", target)
    if args.parts:
        parts(folder, args.frames, args.repeat)
        return 0
    svgf = str(ROOT / ".venv/bin/svgf")
    runs: dict[str, list[tuple[float, float]]] = {}
    for mode in ("as-read", "denoised") * args.repeat:
        out = out_root / f"out-{mode}"
        wall, cpu = timed([svgf, "denoise", "-q", "--preset-aovs", "cycles", "--overwrite",
                           str(folder / "in.####.exr"), "-o", f"{out}/", "--frames",
                           f"1-{args.frames}", "--light-layers", mode])
        runs.setdefault(mode, []).append((wall / args.frames, cpu / args.frames))
        print(f"{mode:>9}: {wall:.2f} s wall, {cpu:.2f} CPU-s", flush=True)
    median = {mode: np.median(np.array(pairs), axis=0) for mode, pairs in runs.items()}
    extra = median["denoised"] - median["as-read"]
    layers = denoised_layers(out_root)
    threads = os.environ.get("NUMBA_NUM_THREADS", "default")
    print(f"threads {threads}; medians per frame (wall, CPU): as-read {median['as-read'][0]:.3f}"
          f" s, {median['as-read'][1]:.3f} CPU-s; denoised {median['denoised'][0]:.3f} s, "
          f"{median['denoised'][1]:.3f} CPU-s")
    print(f"{len(layers)} layers written anew ({', '.join(n.split('.')[-1] for n in layers)}):"
          f" {extra[0]:.3f} s wall and {extra[1]:.3f} CPU-s a frame more, "
          f"{extra[0] / max(len(layers), 1):.3f} s wall a layer")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
