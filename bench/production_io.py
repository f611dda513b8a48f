"""What reading and writing one production frame costs, per codec and OpenEXR thread count.

On one frame of `bench/production_frames.py` (1080p, ~80 channels): `read_frame` (decode every
channel, gather and clean the filter's planes) and `write_output` (the drop-in output: every
channel passed through, the colour replaced) with each lossless ``--compression`` (the
default keeps the input's codec), in CPU seconds (user + system, the library's threads
included: what a busy 2-core farm node pays) and wall seconds, median of ``--repeat``; the
file size of each, and how many different files the repeats wrote (1: the same input gives
the same file; ISA-L's deflate, used before zlib-ng, gave 2-3 from ten writes).

Run: ``.venv/bin/python bench/production_io.py [--frame PATH] [--repeat 3] [--threads 0,2]``
"""

from __future__ import annotations

import argparse
import hashlib
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

from production_frames import make  # noqa: E402

from svgf_cli.io.exr import read_frame, set_io_threads  # noqa: E402
from svgf_cli.io.layers import build_mapping  # noqa: E402
from svgf_cli.io.output import prepare_colour, write_output  # noqa: E402

CODECS = ("zip", "zips", "piz", "rle", "none")


def measure(fn: Callable[[], object], repeat: int,
            then: Callable[[], object] | None = None) -> tuple[float, float]:
    """Median (CPU seconds, wall seconds) of ``fn()``; ``then()`` after each, not timed."""
    cpus, walls = [], []
    for _ in range(repeat):
        before, started = os.times(), time.perf_counter()
        fn()
        after = os.times()
        walls.append(time.perf_counter() - started)
        cpus.append(after.user + after.system - before.user - before.system)
        if then is not None:
            then()
    return statistics.median(cpus), statistics.median(walls)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frame", type=Path, default=None)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--threads", default="0,2")
    parser.add_argument("--stand-in", action="store_true")
    args = parser.parse_args(argv)
    frame = args.frame or make(frames=2, stand_in=args.stand_in) / "in.0002.exr"
    mapping = build_mapping("cycles")
    result = read_frame(frame, mapping)
    names = result.colour_channels or ("R", "G", "B")
    assert result.source is not None
    part = result.source.part_holding(names[0]) or result.source.parts[0]
    colour = prepare_colour(result.frame.total_radiance(), half=True).planes
    print(f"{frame}: {len(result.info.channels)} channels, {result.info.compression}, "
          f"{frame.stat().st_size / 1e6:.0f} MB")
    print(f"{'what':>12} {'threads':>7} {'CPU s':>6} {'wall s':>6} {'MB':>5} {'files':>5}")
    scratch = REPO / "bench" / "out"  # not made when --frame names a frame elsewhere
    scratch.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=scratch) as tmp:
        out = Path(tmp) / "out.exr"
        for threads in (int(t) for t in args.threads.split(",")):
            set_io_threads(threads)
            cpu, wall = measure(lambda: read_frame(frame, mapping), args.repeat)
            print(f"{'read':>12} {threads:7d} {cpu:6.2f} {wall:6.2f}", flush=True)
            for codec in CODECS:
                digests: set[str] = set()

                def write(codec: str = codec, threads: int = threads) -> None:
                    write_output(out, result.source, part_index=part.index,
                                 channels=dict(zip(names, colour, strict=True)),
                                 attributes={}, compression=codec, threads=threads)

                def digest(digests: set[str] = digests) -> None:
                    digests.add(hashlib.sha1(out.read_bytes()).hexdigest())
                cpu, wall = measure(write, args.repeat, digest)
                size = out.stat().st_size / 1e6
                print(f"{'write ' + codec:>12} {threads:7d} {cpu:6.2f} {wall:6.2f} {size:5.0f} "
                      f"{len(digests):5d}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
