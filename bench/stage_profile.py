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

from svgf_cli.filters import modulate
from svgf_cli.filters.denoiser import Denoiser
from svgf_cli.filters.params import resolve_params
from svgf_cli.filters.stages import (
    accumulate,
    antilag,
    atrous,
    firefly_clamp,
    gradients,
    history_clamp,
    reproject,
    variance,
)
from svgf_cli.filters.stages.store_history import StoreHistory
from svgf_cli.filters.stages.values import CleanGeometry

# Each kernel is patched in the stage module that imports and calls it.
KERNELS: tuple[tuple[Any, str], ...] = (
    (gradients, "unit_normals"), (gradients, "depth_gradients"),
    (gradients, "normal_gradient"), (reproject, "reproject"),
    (history_clamp, "history_clamp"), (antilag, "antilag"),
    (accumulate, "accumulate_in_place"), (variance, "estimate_variance"),
    (atrous, "luminance_stop_guides"), (atrous, "atrous_iteration"),
    (firefly_clamp, "firefly_clamp"),
)


def timed(owner: Any, name: str, totals: dict[str, float], label: str | None = None) -> None:
    """Replace ``owner.name`` by a wrapper adding its CPU seconds to ``totals[label]``
    (``label`` defaults to ``name``)."""
    function: Callable[..., Any] = getattr(owner, name)
    key = label or name

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        start = time.process_time()
        result = function(*args, **kwargs)
        totals[key] = totals.get(key, 0.0) + time.process_time() - start
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
    for module, name in KERNELS:
        timed(module, name, totals)
    for name in ("demodulate", "remodulate_add"):
        timed(modulate, name, totals)  # called as modulate.<name> by the stages
    # the host side of two stages (the geometry value policy; the history swap + guard)
    timed(CleanGeometry, "run", totals, "clean_geometry")
    timed(StoreHistory, "run", totals, "store_history")
    width, height = (int(v) for v in args.size.lower().split("x"))
    canvas = SceneCanvas(width, height, pan=args.warmup + args.frames + 1, signals=args.signals)
    denoiser = Denoiser(resolve_params(args.preset))
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
