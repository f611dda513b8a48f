"""Benchmark: per-frame time of Intel OIDN vs our SVGF denoiser on the same frames.

Both run on the same synthetic direct + indirect frames (``svgf_cli.evaluate.synthetic``:
textured floor, moving disc, Gamma noise, exact G-buffer) at 1280x720 and 1920x1080. OIDN is
the RT filter through ``pyoidn``, HDR colour with clean albedo + normal, quality "high",
exactly as ``svgf evaluate --baseline oidn`` runs it (including the (3,H,W) <-> (H,W,3)
copies). SVGF is ``Denoiser`` with the paper preset. Warm-up frames first (numba JIT, OIDN
device/filter creation, SVGF history); then the median of the timed frames. Both use every
core of the machine.

Run: ``.venv/bin/python bench/bench_oidn.py [--frames N] [--sizes 1280x720,1920x1080]``
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

from svgf_cli.evaluate.baselines import OidnMethod
from svgf_cli.evaluate.synthetic import synthetic_frame
from svgf_cli.filters.denoiser import Denoiser
from svgf_cli.filters.params import resolve_params


def time_per_frame(process, frames, warmup: int) -> float:  # noqa: ANN001 - any callable
    """Median wall milliseconds of ``process(frame)`` over the frames after ``warmup``."""
    for frame in frames[:warmup]:
        process(frame)
    samples = []
    for frame in frames[warmup:]:
        start = time.perf_counter()
        process(frame)
        samples.append(1e3 * (time.perf_counter() - start))
    return statistics.median(samples)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=4, help="timed frames per size")
    parser.add_argument("--warmup", type=int, default=2, help="untimed frames first")
    parser.add_argument("--sizes", default="1280x720,1920x1080")
    parser.add_argument("--preset", default="paper")
    args = parser.parse_args(argv)
    try:
        oidn = OidnMethod()
    except Exception as exc:  # noqa: BLE001 - report and skip, as the README says
        print(f"OIDN benchmark skipped: {exc}")
        return 0
    from importlib.metadata import version

    print(
        f"Per-frame time, median of {args.frames} frames after {args.warmup} warm-up; "
        f"SVGF preset {args.preset} (direct + indirect), OIDN RT (pyoidn {version('pyoidn')}, "
        "HDR, clean albedo + normal, quality high)"
    )
    print(f"{'size':>10}  {'SVGF ms':>9}  {'OIDN ms':>9}  {'OIDN / SVGF':>11}")
    for size in args.sizes.split(","):
        width, height = (int(v) for v in size.lower().split("x"))
        frames = [synthetic_frame(i, width, height)[0] for i in range(args.warmup + args.frames)]
        denoiser = Denoiser(resolve_params(args.preset))
        svgf_ms = time_per_frame(denoiser.process, frames, args.warmup)
        oidn_ms = time_per_frame(oidn.process, frames, args.warmup)
        print(f"{size:>10}  {svgf_ms:9.1f}  {oidn_ms:9.1f}  {oidn_ms / svgf_ms:10.2f}x", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
