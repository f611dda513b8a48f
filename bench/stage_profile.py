"""CPU time of every kernel call inside ``Denoiser.process`` at 1080p (finer than the stages
that ``bench_filters.py`` reports): reprojection, history clamp, anti-lag, guides and a-trous
apart. Same synthetic scene as ``bench_filters.py``.

Run: ``.venv/bin/python bench/stage_profile.py [--signals 2|3] [--frames N] [--warmup N]``;
with ``NUMBA_NUM_THREADS=1`` the numbers are the work itself, without the time threads spend
waiting for each other (which a busy machine inflates).
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from collections.abc import Callable
from typing import Any

from bench_filters import SceneCanvas, denoiser_buffer_bytes

from svgf_cli.filters import denoiser as denoiser_module
from svgf_cli.filters import modulate
from svgf_cli.filters.params import resolve_params

KERNELS = (
    "unit_normals", "depth_gradients", "normal_gradient", "reproject", "history_clamp",
    "antilag", "accumulate_in_place", "estimate_variance", "luminance_stop_guides",
    "atrous_iteration", "firefly_clamp",
)


def timed(owner: Any, name: str, totals: dict[str, float]) -> None:
    """Replace ``owner.name`` by a wrapper adding its CPU seconds to ``totals[name]``."""
    function: Callable[..., Any] = getattr(owner, name)

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        start = time.process_time()
        result = function(*args, **kwargs)
        totals[name] = totals.get(name, 0.0) + time.process_time() - start
        return result

    setattr(owner, name, wrapper)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--signals", type=int, choices=(2, 3), default=3)
    parser.add_argument("--frames", type=int, default=4)
    parser.add_argument("--warmup", type=int, default=5)
    parser.add_argument("--size", default="1920x1080")
    parser.add_argument("--preset", default="default")
    args = parser.parse_args(argv)
    totals: dict[str, float] = {}
    for name in KERNELS:
        timed(denoiser_module, name, totals)
    for name in ("demodulate", "remodulate_add"):
        timed(modulate, name, totals)
    for name in ("_clean_geometry", "_store_history"):
        timed(denoiser_module.Denoiser, name, totals)
    width, height = (int(v) for v in args.size.lower().split("x"))
    canvas = SceneCanvas(width, height, pan=args.warmup + args.frames + 1, signals=args.signals)
    denoiser = denoiser_module.Denoiser(resolve_params(args.preset))
    for index in range(args.warmup):
        denoiser.process(canvas.frame(index))
    totals.clear()
    total = 0.0
    for index in range(args.warmup, args.warmup + args.frames):
        frame = canvas.frame(index)
        start = time.process_time()
        denoiser.process(frame)
        total += time.process_time() - start
        del frame
    print(f"{width}x{height}, {args.signals} signals, preset {args.preset}: CPU ms per frame")
    for name, seconds in sorted(totals.items(), key=lambda item: -item[1]):
        print(f"  {name:24s} {1e3 * seconds / args.frames:8.1f}")
    print(f"  {'Denoiser.process':24s} {1e3 * total / args.frames:8.1f}")
    print(f"denoiser buffers {denoiser_buffer_bytes(denoiser) / 2**20:.0f} MB, peak RSS "
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
