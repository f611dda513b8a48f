"""Benchmark of `svgf trace`: seconds per frame, rays per second, share of time inside Embree.

The bundled Cornell box (checker floor, animated) at 640x360, 1 spp, max depth 5 by default.
A small warm-up frame loads the numba kernels first, so the timed frames exclude JIT work.
Per frame it reports the wall time of render_frame (scene transform, Embree build, primary
rays, G-buffer, all bounces) and of writing the EXR, the rays traced (primary + shadow +
continuation), and the wall time spent inside Embree calls (build included).

Run: ``.venv/bin/python bench/bench_trace.py [--resolution 640x360] [--frames 3] [--spp 1]
[--max-depth 5] [--threads 0]``
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from svgf_cli.commands.trace import parse_resolution, resolve_threads
from svgf_cli.io.exr import write_exr
from svgf_trace.animation import load_animation
from svgf_trace.output import frame_attributes, input_channels
from svgf_trace.render import TraceStats, render_frame
from svgf_trace.scene import load_obj

TESTDATA = Path(__file__).resolve().parent.parent / "testdata"
FLOOR_SECONDS = 1.5


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolution", default="640x360")
    parser.add_argument("--frames", type=int, default=3)
    parser.add_argument("--spp", type=int, default=1)
    parser.add_argument("--max-depth", type=int, default=5)
    parser.add_argument("--threads", type=int, default=0)
    parser.add_argument("--scene", default=str(TESTDATA / "cornell_checker.obj"))
    args = parser.parse_args(argv)
    width, height = parse_resolution(args.resolution)
    threads = resolve_threads(args.threads)

    scene = load_obj(args.scene)
    anim = load_animation(TESTDATA / "anim.json", [o.name for o in scene.objects])
    render_frame(scene, anim, 1, 32, 18, 1, args.max_depth, 0, threads=threads)  # warm-up

    print(f"scene {Path(args.scene).name}: {scene.triangle_count} triangles; {width}x{height}, "
          f"{args.spp} spp, max depth {args.max_depth}, {threads} threads")  # fmt: skip
    print(f"{'frame':>5} {'render s':>9} {'write s':>8} {'Mrays':>7} {'Mrays/s':>8} "
          f"{'embree %':>9}")  # fmt: skip
    totals = TraceStats()
    render_total = 0.0
    write_total = 0.0
    with tempfile.TemporaryDirectory() as tmp:
        for frame in range(1, args.frames + 1):
            stats = TraceStats()
            start = time.perf_counter()
            result, _ = render_frame(scene, anim, frame, width, height, args.spp,
                                     args.max_depth, 0, threads=threads, stats=stats)  # fmt: skip
            rendered = time.perf_counter() - start
            channels, half = input_channels(result)
            attrs = frame_attributes(result, frame=frame, spp=args.spp, seed=0,
                                     max_depth=args.max_depth, kind="input")  # fmt: skip
            start = time.perf_counter()
            write_exr(Path(tmp) / f"in.{frame:04d}.exr", channels, attributes=attrs, half=half,
                      compression="piz")  # fmt: skip
            written = time.perf_counter() - start
            embree = stats.embree_seconds + stats.build_seconds
            rate = stats.rays / rendered / 1e6
            print(f"{frame:>5} {rendered:>9.3f} {written:>8.3f} {stats.rays / 1e6:>7.2f} "
                  f"{rate:>8.2f} {100 * embree / rendered:>8.1f}%")  # fmt: skip
            render_total += rendered
            write_total += written
            totals.rays += stats.rays
            totals.embree_seconds += stats.embree_seconds
            totals.build_seconds += stats.build_seconds
    n = args.frames
    embree_share = (totals.embree_seconds + totals.build_seconds) / render_total
    per_frame = render_total / n
    print(f"mean: {per_frame:.3f} s/frame render + {write_total / n:.3f} s write; "
          f"{totals.rays / render_total / 1e6:.2f} Mrays/s; {100 * embree_share:.1f}% of render "
          f"time inside Embree (build {totals.build_seconds / n * 1e3:.1f} ms/frame)")  # fmt: skip
    verdict = "ok" if per_frame + write_total / n <= FLOOR_SECONDS else "ABOVE FLOOR"
    print(f"floor {FLOOR_SECONDS} s/frame (render + write): {verdict}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
