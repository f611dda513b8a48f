"""Production frames end to end: `svgf denoise --preset-aovs cycles` against OIDN-high's whole
pipeline on the same 1080p ~80-channel Cycles frames (`bench/production_frames.py`).

svgf runs as the CLI in its own process (`bench_e2e.run_cli`: steady seconds per frame after
the first output, the -v read/compute/write thread seconds, peak RSS, CPU seconds). OIDN-high
runs the same pipeline in this process, frame by frame: the same reader (`read_frame`), OIDN's
RT filter with quality high and the noisy-aux prefilter (albedo and normal denoised first,
then the beauty with ``clean_aux``, as Blender's Denoise node does:
`svgf_cli.evaluate.baselines.OidnMethod`), and the same drop-in writer (`write_output`, the
input's codec); median seconds per frame after the first.

Run: ``.venv/bin/python bench/bench_production.py [--frames 4] [--stand-in] [--no-oidn]
[--svgf-args '--light-layers as-read'] [--frames-dir DIR --aovs svgf]``
Targets (issue 32, 2 cores): <= 3 s/frame, >= 5x OIDN-high's pipeline, peak < 2 GB.
"""

from __future__ import annotations

import argparse
import shlex
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

from bench_e2e import run_cli  # noqa: E402
from production_frames import make  # noqa: E402


def oidn_pipeline(folder: Path, out: Path, frames: int, aovs: str = "cycles") -> float | None:
    """Median wall seconds per frame (after the first) of read + OIDN-high + write: with the
    noisy-aux prefilter on Cycles frames (1-spp albedo and normal), with the aux taken as
    clean on others (an exact G-buffer: `svgf trace`'s, the synthetic set's)."""
    from svgf_cli.evaluate.baselines import OidnMethod
    from svgf_cli.io.exr import io_threads, read_frame, set_io_threads
    from svgf_cli.io.layers import build_mapping
    from svgf_cli.io.output import prepare_colour, write_output

    try:
        oidn = OidnMethod(prefilter=aovs == "cycles")
    except Exception as exc:  # noqa: BLE001 - report and skip
        print(f"OIDN skipped: {exc}")
        return None
    set_io_threads(2)
    mapping = build_mapping(aovs)
    seconds = []
    for frame in range(1, frames + 1):
        started = time.perf_counter()
        result = read_frame(folder / f"in.{frame:04d}.exr", mapping)
        names = result.colour_channels or ("R", "G", "B")
        source = result.source
        assert source is not None
        part = source.part_holding(names[0]) or source.parts[0]
        stored = part.channels.get(names[0])
        half = stored is None or stored.type_name == "half"
        colour = prepare_colour(oidn.process(result.frame), half).planes
        write_output(out / f"oidn.{frame:04d}.exr", source, part_index=part.index,
                     channels=dict(zip(names, colour, strict=True)), attributes={},
                     threads=io_threads())
        seconds.append(time.perf_counter() - started)
        print(f"  OIDN frame {frame}: {seconds[-1]:.2f} s", flush=True)
    return statistics.median(seconds[1:]) if len(seconds) > 1 else seconds[0]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=4)
    parser.add_argument("--stand-in", action="store_true",
                        help="the widened roll frames even when the production scene renders")
    parser.add_argument("--no-oidn", action="store_true")
    parser.add_argument("--svgf-args", default="",
                        help="more `svgf denoise` options, e.g. '--light-layers as-read'")
    parser.add_argument("--frames-dir", type=Path,
                        help="other frames in.####.exr instead, e.g. bench_e2e.py's synthetic "
                             "set (--workdir DIR: DIR/in_1920x1080), with --aovs")
    parser.add_argument("--aovs", default="cycles",
                        help="their --preset-aovs (OIDN prefilters the aux on cycles only)")
    args = parser.parse_args(argv)
    folder = args.frames_dir or make(frames=args.frames, stand_in=args.stand_in)
    print(f"frames: {folder}/in.####.exr ({args.frames})", flush=True)
    scratch = REPO / "bench" / "out"  # not made by --frames-dir runs on a fresh clone
    scratch.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=scratch) as tmp:
        svgf = run_cli(folder / "in.####.exr", Path(tmp), args.frames, "--preset-aovs",
                       args.aovs, *shlex.split(args.svgf_args))
        print(
            f"svgf: {svgf['steady']:.2f} s/frame steady (first {svgf['first_frame']:.1f} s); "
            f"thread s/frame read {svgf['read']:.2f}, compute {svgf['compute']:.2f}, write "
            f"{svgf['write']:.2f}; CPU {svgf['cpu'] / args.frames:.2f} s/frame; "
            f"peak RSS {svgf['rss_mb']:.0f} MB",
            flush=True,
        )
        if args.no_oidn:
            return 0
        oidn = oidn_pipeline(folder, Path(tmp), args.frames, args.aovs)
    if oidn is not None:
        aux = "noisy-aux prefilter" if args.aovs == "cycles" else "clean aux"
        print(f"OIDN-high pipeline ({aux}): {oidn:.2f} s/frame; "
              f"OIDN / svgf {oidn / svgf['steady']:.2f}x", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
