"""End-to-end benchmark of `svgf denoise` with EXR I/O: seconds per frame, split, peak memory.

Writes synthetic input sequences (a textured scene, direct + indirect 1-spp-like noise,
emission, a one-pixel camera pan with exact backward motion) with a realistic channel set:
26 float channels (R,G,B,A, direct.*, indirect.*, emission.*, albedo.*, N.*, P.*, Z,
motion.X/Y, id), ZIP-compressed. Then runs the CLI in a fresh process per size and reports:

* the steady-state seconds per frame (first frame excluded: JIT cache load and cold start),
* where the time went (read, compute, write summed over frames; read and write overlap the
  compute in the runner, so the wall time is less than their sum),
* the peak RSS of that process, for N and 2N frames (it must not grow with the length).

Run: ``.venv/bin/python bench/bench_e2e.py [--frames N] [--sizes 1280x720,1920x1080]``
Floors (issue 2): <= 1.2 s per 1080p frame end to end (aim 0.7); peak memory < 1.5 GB.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from svgf_cli.io.exr import write_exr  # noqa: E402

F32 = np.float32


def synthetic_frame(width: int, height: int, frame: int, seed: int = 1) -> dict[str, np.ndarray]:
    """One frame of a panning textured scene with two depth layers and 1-spp-like noise."""
    rng = np.random.default_rng(seed * 7919 + frame)
    y, x = np.mgrid[0:height, 0:width].astype(F32)
    wx = x + frame  # camera pans one pixel per frame to the right
    near = ((wx // 160) % 3 == 0) & (y > height * 0.3)
    depth = np.where(near, 3.0, 8.0 + 0.002 * y).astype(F32)
    check = (((wx // 32) + (y // 32)) % 2).astype(F32)
    albedo = np.stack([0.2 + 0.6 * check, 0.3 + 0.4 * check, 0.25 + 0.2 * check]).astype(F32)
    light = np.where(near, 1.5, 0.6).astype(F32)
    noise = rng.exponential(1.0, (6, height, width)).astype(F32)
    direct = light * albedo * noise[:3]
    indirect = 0.35 * albedo * noise[3:]
    emission = np.zeros((3, height, width), F32)
    emission[:, : height // 20, :] = 4.0  # a lamp strip at the top
    beauty = direct + indirect + emission
    normal = np.zeros((3, height, width), F32)
    normal[2] = 1.0
    normal[1] = np.where(near, 0.0, 0.2)
    normal /= np.sqrt((normal**2).sum(0))
    channels: dict[str, np.ndarray] = {}
    for i, c in enumerate("RGB"):
        channels[c] = beauty[i]
        channels[f"direct.{c}"] = direct[i]
        channels[f"indirect.{c}"] = indirect[i]
        channels[f"emission.{c}"] = emission[i]
        channels[f"albedo.{c}"] = albedo[i]
    channels["A"] = np.ones((height, width), F32)
    for i, c in enumerate("XYZ"):
        channels[f"N.{c}"] = normal[i]
        channels[f"P.{c}"] = (wx, y, depth)[i].astype(F32)
    channels["Z"] = depth
    channels["motion.X"] = np.full((height, width), -1.0 if frame > 1 else 0.0, F32)
    channels["motion.Y"] = np.zeros((height, width), F32)
    channels["id"] = np.where(near, 1.0, 2.0).astype(F32)
    return channels


def write_inputs(folder: Path, width: int, height: int, frames: int) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for f in range(1, frames + 1):
        path = folder / f"in.{f:04d}.exr"
        if not path.exists():
            write_exr(path, synthetic_frame(width, height, f), compression="zip")


def run_cli(pattern: Path, out: Path, frames: int, *extra: str) -> dict[str, float]:
    """One `svgf denoise` process; timings from its JSON progress, memory from wait4."""
    args = [
        sys.executable,
        "-m",
        "svgf_cli",
        "denoise",
        str(pattern),
        "-o",
        str(out / "den.####.exr"),
        "--frames",
        f"1-{frames}",
        "--overwrite",
        "--progress",
        "json",
        *extra,
    ]
    started = time.perf_counter()
    proc = subprocess.Popen(
        args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO
    )
    times: list[float] = []
    assert proc.stdout is not None and proc.stderr is not None
    for line in proc.stdout:
        event = json.loads(line)
        if event["event"] == "frame_done":
            times.append(time.perf_counter())
    err = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - started
    if proc.returncode != 0:
        raise SystemExit(f"svgf denoise failed ({proc.returncode}):\n{err}")
    done = re.search(r"read ([\d.]+) s, compute ([\d.]+) s, write ([\d.]+) s", err)
    assert done is not None, err
    # Mean wall per frame after the first output (events can arrive in pairs: a frame is
    # reported once its write finishes, so single gaps are noisy; the span is not).
    steady = (times[-1] - times[0]) / (len(times) - 1) if len(times) > 1 else wall
    return {
        "wall": wall,
        "first_frame": times[0] - started if times else wall,
        "steady": steady,
        "read": float(done.group(1)) / frames,
        "compute": float(done.group(2)) / frames,
        "write": float(done.group(3)) / frames,
        "rss_mb": usage.ru_maxrss / 1024.0,  # Linux reports KiB
        # CPU seconds of the whole process (all threads): independent of other load on a
        # shared machine, unlike the wall times.
        "cpu": usage.ru_utime + usage.ru_stime,
    }


def _warm_start_cost(folder: Path, out: Path, n: int, cpu_default: float,
                     per_frame: float) -> None:
    """The default's look-ahead warm start (docs/stability.md#warm-start) is paid once per
    cold start, so the per-frame difference above cancels it: print it per shot, from the
    same N frames run with ``--warm-start 0``."""
    cold = run_cli(folder / "in.####.exr", out, n, "--warm-start", "0")
    extra = cpu_default - cold["cpu"]
    print(f"  warm start: {extra:+.1f} CPU seconds per shot ({extra / per_frame:.1f} causal "
          f"frames' work; {cold['cpu']:.1f} with --warm-start 0 over {n} frames)", flush=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=6, help="frames per run (N)")
    parser.add_argument("--sizes", default="1280x720,1920x1080")
    parser.add_argument("--workdir", type=Path, default=None, help="keep inputs here")
    parser.add_argument("--modes", default="causal",
                        help="comma-separated: causal, bidirectional (docs/bidirectional.md)")
    args = parser.parse_args(argv)
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    n = args.frames
    with tempfile.TemporaryDirectory(prefix="svgf-bench-e2e-") as tmp:
        root = args.workdir or Path(tmp)
        # JIT compile / cache load once so no timed run pays for compilation.
        write_inputs(root / "tiny", 64, 36, 2)
        run_cli(root / "tiny" / "in.####.exr", root / "tiny_out", 2)
        print(
            f"{'size':>10} {'frames':>6} {'s/frame':>8} {'1st':>6} {'read':>6} "
            f"{'compute':>8} {'write':>6} {'peak MB':>8} {'CPU s':>7}",
            flush=True,
        )
        modes = args.modes.split(",")
        for width, height in sizes:
            folder = root / f"in_{width}x{height}"
            t0 = time.perf_counter()
            write_inputs(folder, width, height, 2 * n)
            print(
                f"  (inputs {width}x{height}: {time.perf_counter() - t0:.0f} s to write, "
                f"{sum(p.stat().st_size for p in folder.iterdir()) / 2**20 / (2 * n):.0f} "
                "MB/frame)",
                flush=True,
            )
            per_mode = {}
            for mode in modes:
                extra = ("--bidirectional",) if mode == "bidirectional" else ()
                cpu = {}
                for frames in (n, 2 * n):
                    r = run_cli(folder / "in.####.exr", root / f"out_{width}x{height}", frames,
                                *extra)
                    cpu[frames] = r["cpu"]
                    print(
                        f"{width}x{height:<5} {frames:>6} {r['steady']:>8.3f} "
                        f"{r['first_frame']:>6.2f} {r['read']:>6.3f} {r['compute']:>8.3f} "
                        f"{r['write']:>6.3f} {r['rss_mb']:>8.0f} {r['cpu']:>7.1f}  {mode}",
                        flush=True,
                    )
                per_frame = per_mode[mode] = (cpu[2 * n] - cpu[n]) / n
                print(
                    f"  {mode}: CPU seconds per frame (the {n} extra frames of the longer run):"
                    f" {per_frame:.2f}; on 2 fully used cores that is >= {per_frame / 2:.2f}"
                    " s/frame",
                    flush=True,
                )
                if mode == "causal":
                    _warm_start_cost(folder, root / f"out_{width}x{height}", n, cpu[n],
                                     per_frame)
            if len(per_mode) == 2:
                ratio = per_mode["bidirectional"] / per_mode["causal"]
                print(f"  bidirectional / causal CPU seconds per frame: {ratio:.2f}", flush=True)
    print(
        "s/frame: mean wall per frame after the first written one; 1st: seconds to the "
        "first written frame, process start included; read/compute/write: mean seconds per "
        "frame in each (read and write overlap compute)."
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
