"""EXR read and write cost per frame, in CPU seconds and wall seconds (machine-load proof).

The input is `bench_e2e`'s synthetic frame (26 float channels, ZIP). Measured separately:

* read: `read_frame` (decode every channel, gather and clean the filter's planes);
* write: the output of one denoised frame as `svgf denoise` writes it (the input's every
  channel passed through, the colour replaced), or with ``--colour-only`` semantics.

Each is run ``--repeat`` times per OpenEXR thread count; the median is printed. CPU time is
the process's user + system time, so it counts the library's worker threads too.

Run: ``.venv/bin/python bench/bench_io.py [--size 1920x1080] [--repeat 3] [--threads 0,2]``
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

from bench_e2e import synthetic_frame  # noqa: E402

from svgf_cli.io.exr import read_frame, set_io_threads, write_exr  # noqa: E402
from svgf_cli.io.layers import build_mapping  # noqa: E402


def cpu_seconds() -> float:
    times = __import__("os").times()
    return times.user + times.system


def measure(fn, repeat: int) -> tuple[float, float]:
    cpus, walls = [], []
    for _ in range(repeat):
        c0, w0 = cpu_seconds(), time.perf_counter()
        fn()
        cpus.append(cpu_seconds() - c0)
        walls.append(time.perf_counter() - w0)
    return statistics.median(cpus), statistics.median(walls)


def writer(result, out: Path, colour_only: bool):
    """The runner's own output path for one frame (denoised colour = the noisy one)."""
    from types import SimpleNamespace

    from svgf_cli.io.output import write_output
    from svgf_cli.run.output import build_output

    colour = result.frame.total_radiance()

    def write() -> None:
        denoised = SimpleNamespace(color=colour.copy(), layers={}, warnings=list)
        task = SimpleNamespace(frame=1, input=result.info.path, output=out)
        output = build_output(result, denoised, _Config(colour_only), task)
        write_output(
            out,
            output.source,
            part_index=output.part_index,
            channels=output.channels,
            attributes=output.attributes,
            keep_only=output.keep_only,
            threads=_threads[0],
        )

    return write


class _Config:
    def __init__(self, colour_only: bool) -> None:
        self.float_colour = False
        self.debug_aovs = False
        self.colour_only = colour_only
        self.preset = "paper"
        self.warmup_label = "all"
        # Real parameters: output_attributes names the stages their pipeline runs.
        from svgf_cli.filters.params import SVGFParams

        self.params = SVGFParams()


_threads = [0]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="1920x1080")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--threads", default="0,2")
    args = parser.parse_args(argv)
    width, height = (int(v) for v in args.size.split("x"))
    with tempfile.TemporaryDirectory(prefix="svgf-bench-io-") as tmp:
        source = Path(tmp) / "in.0002.exr"
        write_exr(source, synthetic_frame(width, height, 2), compression="zip")
        mapping = build_mapping()
        print(f"{width}x{height}, 26 float channels, ZIP ({source.stat().st_size >> 20} MB)")
        print(f"{'threads':>7} {'step':<28} {'CPU s':>7} {'wall s':>7}")
        for threads in (int(t) for t in args.threads.split(",")):
            set_io_threads(threads)
            _threads[0] = threads
            result = read_frame(source, mapping)
            cpu, wall = measure(lambda: read_frame(source, mapping), args.repeat)
            print(f"{threads:>7} {'read_frame':<28} {cpu:>7.3f} {wall:>7.3f}", flush=True)
            for colour_only, label in ((False, "write (every channel)"),
                                       (True, "write (--colour-only)")):
                out = Path(tmp) / "out.exr"
                cpu, wall = measure(writer(result, out, colour_only), args.repeat)
                print(f"{threads:>7} {label:<28} {cpu:>7.3f} {wall:>7.3f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
