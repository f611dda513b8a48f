"""Benchmark of the SVGF filter core: ms/frame per stage at 1280x720 and 1920x1080.

Synthetic but realistic input: a textured ground plane and spheres (depth, normals, mesh ids
from the analytic geometry), heavy-tailed 1-spp-like noise on direct and indirect, emission
on one object, a background strip, and a camera pan of one pixel per frame with exact
backward motion. ``--signals 3`` filters the signals ``--signals lobes-split`` makes of a
Cycles file with glossy and transmission passes instead of direct + indirect:
``diffuse_direct`` and ``diffuse_indirect`` (the checker colour) and ``specular`` (glossy
plus transmission light, demodulated by the sum of their colours: a grey 0.5, plus up to 1
on one sphere, which is therefore filtered as radiance; ``glossy=True``, so the preset's
glossy rules apply). A warm-up sequence excludes
JIT compilation and the cold first frames; the timed frames are in steady state (most
pixels have history >= 4).

Run: ``.venv/bin/python bench/bench_filters.py [--frames N] [--sizes 1280x720,1920x1080]
[--signals 2|3] [--motion-offset DX] [--set NAME=VALUE]``
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from typing import Any

import numpy as np
from overrides import parse_overrides  # bench/, the script's folder

from svgf_cli.filters.denoiser import Denoiser
from svgf_cli.filters.params import resolve_params
from svgf_cli.frame import Frame, Signal

F32 = np.float32
STAGES = (
    "values", "gradients", "demodulate", "reproject", "variance", "atrous", "history", "despike",
    "modulate",
)


class SceneCanvas:
    """An analytic scene rendered once on a canvas wider than the frame; frames are crops."""

    def __init__(self, width: int, height: int, pan: int, seed: int = 0,
                 signals: int = 2, motion_offset: float = 0.0) -> None:
        self.width, self.height, self.pan, self.signals = width, height, pan, signals
        self.motion_offset = motion_offset
        cw = width + pan
        y, x = np.mgrid[0:height, 0:cw].astype(np.float64)
        horizon = 0.3 * height
        depth = np.zeros((height, cw))
        normal = np.zeros((3, height, cw))
        mesh = np.full((height, cw), -1, dtype=np.int32)
        ground = y > horizon
        depth[ground] = 2.0 * height / (y[ground] - horizon + 1.0)
        normal[1][ground] = -1.0
        mesh[ground] = 0
        rng = np.random.default_rng(seed)
        for sphere in range(6):
            cx = rng.uniform(0.1, 0.9) * cw
            cy = rng.uniform(0.35, 0.8) * height
            radius = rng.uniform(0.06, 0.16) * height
            dz = ((x - cx) ** 2 + (y - cy) ** 2) / radius**2
            inside = dz < 1.0
            cap = np.sqrt(np.clip(1.0 - dz, 0.0, 1.0))
            zs = 3.0 + sphere * 0.4 - cap * 0.5
            closer = inside & ((depth <= 0) | (zs < depth))
            depth[closer] = zs[closer]
            normal[0][closer] = ((x - cx) / radius)[closer]
            normal[1][closer] = ((y - cy) / radius)[closer]
            normal[2][closer] = -cap[closer]
            mesh[closer] = sphere + 1
        self.depth = depth.astype(F32)
        self.normal = normal.astype(F32)
        self.mesh = mesh
        checker = ((np.floor(x / 24) + np.floor(y / 24)) % 2).astype(np.float64)
        self.albedo = np.stack([0.3 + 0.5 * checker, 0.4 + 0.3 * checker, 0.5 + 0.1 * checker])
        self.albedo = self.albedo.astype(F32)
        light = 0.5 + 0.5 * np.clip(-normal[1] * 0.6 - normal[2] * 0.8, 0.0, 1.0)
        self.direct = np.stack([light * 1.0, light * 0.9, light * 0.8]).astype(F32)
        self.indirect = (0.3 * self.direct[::-1]).astype(F32)
        self.emission = np.zeros((3, height, cw), dtype=F32)
        self.emission[:, mesh == 1] = 2.0
        self.gloss_colour = np.full((3, height, cw), 0.5, dtype=F32)
        self.trans_colour = np.zeros((3, height, cw), dtype=F32)
        self.trans_colour[:, mesh == 2] = np.array([[0.9], [0.95], [1.0]], dtype=F32)
        self.rng = rng

    def frame(self, index: int) -> Frame:
        # The crop slides left over the canvas, so the content moves one pixel right per frame:
        # what pixel x shows was at x - 1 in the previous frame (backward motion -1).
        x0 = self.pan - (index % (self.pan + 1))
        sl = np.s_[..., x0:x0 + self.width]
        h, w = self.height, self.width

        def crop(a: np.ndarray) -> np.ndarray:
            return np.ascontiguousarray(a[sl])

        albedo = crop(self.albedo)
        spp = self.rng.exponential(1.0, (self.signals, h, w)).astype(F32)
        emission = crop(self.emission)
        direct = albedo * crop(self.direct) * spp[0]
        indirect = albedo * crop(self.indirect) * spp[1]
        motion = np.zeros((2, h, w), dtype=F32)
        motion[0] = -1.0 if index % (self.pan + 1) else 0.0
        motion += F32(self.motion_offset)
        if self.signals == 2:
            signals = [Signal("direct", np.ascontiguousarray(direct, dtype=F32), albedo),
                       Signal("indirect", np.ascontiguousarray(indirect, dtype=F32), albedo)]
        else:
            gloss, trans = crop(self.gloss_colour), crop(self.trans_colour)
            light = crop(self.direct) + crop(self.indirect)
            specular = (gloss + trans) * light * spp[2]
            signals = [
                Signal("diffuse_direct", np.ascontiguousarray(direct, dtype=F32), albedo),
                Signal("diffuse_indirect", np.ascontiguousarray(indirect, dtype=F32), albedo),
                Signal("specular", np.ascontiguousarray(specular, dtype=F32),
                       np.ascontiguousarray(gloss + trans, dtype=F32), glossy=True),
            ]
        return Frame(
            signals=signals, albedo=albedo, normal=crop(self.normal), depth=crop(self.depth),
            motion=motion, mesh_id=crop(self.mesh), emission=emission,
        )


def bench_size(
    width: int, height: int, frames: int, warmup: int, preset: str, signals: int = 2,
    motion_offset: float = 0.0, overrides: dict[str, Any] | None = None,
) -> tuple[dict[str, float], dict[str, float]]:
    """(wall ms/frame per stage + summary, CPU ms/frame per stage)."""
    canvas = SceneCanvas(width, height, pan=warmup + frames + 1, signals=signals,
                         motion_offset=motion_offset)
    denoiser = Denoiser(resolve_params(preset, **(overrides or {})))
    for index in range(warmup):
        denoiser.process(canvas.frame(index))
    totals = dict.fromkeys(STAGES, 0.0)
    cpu_totals = dict.fromkeys(STAGES, 0.0)
    walls: list[float] = []
    cpu = 0.0
    counters = cpu_steal_counters()
    for index in range(warmup, warmup + frames):
        frame = canvas.frame(index)  # generated outside the timed region
        start = time.perf_counter()
        cpu_start = time.process_time()
        denoiser.process(frame)
        cpu += time.process_time() - cpu_start
        walls.append(time.perf_counter() - start)
        for stage, seconds in denoiser.stage_seconds.items():
            totals[stage] = totals.get(stage, 0.0) + seconds
        for stage, seconds in denoiser.stage_cpu_seconds.items():
            cpu_totals[stage] = cpu_totals.get(stage, 0.0) + seconds
    result = {stage: 1e3 * seconds / frames for stage, seconds in totals.items()}
    result["total"] = 1e3 * sum(walls) / frames
    result["fastest"] = 1e3 * min(walls)
    # CPU time over both cores: unlike wall time it does not grow with the hypervisor's
    # steal (measured up to 17% on this shared VM), so it compares runs more fairly.
    result["cpu"] = 1e3 * cpu / frames
    result["steal"] = steal_percent(counters, cpu_steal_counters())
    result["buffers_mb"] = denoiser_buffer_bytes(denoiser) / 2**20
    return result, {stage: 1e3 * seconds / frames for stage, seconds in cpu_totals.items()}


def cpu_steal_counters() -> tuple[int, int] | None:
    """(steal, total) jiffies of all CPUs from /proc/stat, None where there is none."""
    try:
        with open("/proc/stat") as handle:
            fields = [int(v) for v in handle.readline().split()[1:]]
    except (OSError, ValueError):
        return None
    return (fields[7] if len(fields) > 7 else 0), sum(fields[:8])


def steal_percent(before: tuple[int, int] | None, after: tuple[int, int] | None) -> float:
    """Share of CPU time the hypervisor took from this VM between two counter readings."""
    if before is None or after is None or after[1] <= before[1]:
        return 0.0
    return 100.0 * (after[0] - before[0]) / (after[1] - before[1])


def denoiser_buffer_bytes(denoiser: Denoiser) -> int:
    """Bytes of the full-frame arrays a Denoiser keeps between frames (workspace, history,
    colour means, TAA), each counted once: ``PipelineFilter.held_bytes``."""
    return denoiser.held_bytes()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=5, help="timed frames per size")
    parser.add_argument("--warmup", type=int, default=6, help="untimed frames first")
    parser.add_argument("--sizes", default="1280x720,1920x1080")
    parser.add_argument("--preset", default="paper")
    parser.add_argument("--signals", type=int, choices=(2, 3), default=2,
                        help="2: direct + indirect; 3: Cycles lobes-split (diffuse_direct, "
                             "diffuse_indirect, specular)")
    parser.add_argument("--motion-offset", type=float, default=0.0,
                        help="added to both motion components: every history fetch at a"
                        " sub-pixel position (the resampling's cost; the pan is whole pixels)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="override a parameter of the preset (Python literal); repeatable")
    args = parser.parse_args(argv)
    overrides = parse_overrides(args.set)
    kind = ("direct + indirect" if args.signals == 2
            else "diffuse_direct + diffuse_indirect + specular (lobes-split)")
    print(f"SVGF filter core, preset {args.preset}, {kind}, "
          f"{args.frames} timed frames after {args.warmup} warm-up frames")
    for size in args.sizes.split(","):
        width, height = (int(v) for v in size.lower().split("x"))
        result, cpu = bench_size(width, height, args.frames, args.warmup, args.preset,
                                 args.signals, args.motion_offset, overrides)
        pixels = width * height
        print(f"{width}x{height}: CPU ms/frame  "
              + "  ".join(f"{s} {cpu.get(s, 0.0):7.1f}" for s in STAGES))
        stages = "  ".join(f"{s} {result.get(s, 0.0):7.1f}" for s in STAGES)
        summary = {"total", "fastest", "cpu", "steal", "buffers_mb"}
        extra = sorted(set(result) - set(STAGES) - summary)
        if extra:
            stages += "  " + "  ".join(f"{s} {result[s]:7.1f}" for s in extra)
        print(f"{width}x{height}: ms/frame  {stages}")
        print(f"{width}x{height}: total {result['total']:7.1f} ms/frame  "
              f"{1e6 * result['total'] / pixels:6.1f} ns/pixel  "
              f"(fastest frame {result['fastest']:.1f} ms, CPU {result['cpu']:.0f} ms/frame "
              f"over all threads, steal {result['steal']:.0f}%)  "
              f"denoiser buffers {result['buffers_mb']:.0f} MB")
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(f"peak RSS {peak_mb:.0f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
