"""A small deterministic synthetic sequence with a known reference, for tests and benchmarks.

A textured floor (checker albedo, smooth lighting) with a disc sliding to the right. The
reference radiance is ``albedo * irradiance``; the noisy input multiplies the direct and the
indirect part by independent mean-1 Gamma noise (shape 4 and 1: like a few-sample direct
estimate and a 1-sample indirect one), so an unbiased denoiser converges to the reference.
The G-buffer (albedo, normal, depth, motion, id) is exact, as a renderer's primary hits are.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from svgf_cli.frame import Frame

DIRECT_SHARE = 0.6
DIRECT_SHAPE = 4.0
INDIRECT_SHAPE = 1.0
DISC_SPEED = 2.0  # pixels per frame, to the right


def synthetic_frame(
    index: int, width: int = 64, height: int = 48, seed: int = 7
) -> tuple[Frame, np.ndarray]:
    """Frame ``index`` (0-based) of the sequence and its (3, H, W) reference radiance."""
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float32)
    xs += 0.5
    ys += 0.5
    f32 = np.float32

    checker = ((xs // 8 + ys // 8) % 2).astype(f32)
    albedo = np.stack([0.25 + 0.5 * checker, 0.35 + 0.3 * checker, 0.6 - 0.3 * checker])
    normal = np.zeros((3, height, width), f32)
    normal[1] = 1.0
    depth = (4.0 + 6.0 * ys / height).astype(f32)
    mesh_id = np.zeros((height, width), np.int32)
    motion = np.zeros((2, height, width), f32)

    # The disc: own albedo, facing the camera, nearer, moving right (backward motion -speed).
    cx = width * 0.3 + DISC_SPEED * index
    cy = height * 0.5
    radius = min(width, height) * 0.22
    inside = (xs - cx) ** 2 + (ys - cy) ** 2 < radius**2
    albedo[:, inside] = np.array([[0.8], [0.2], [0.15]], f32)
    normal[:, inside] = np.array([[0.0], [0.0], [1.0]], f32)
    depth[inside] = 2.0
    mesh_id[inside] = 1
    motion[0, inside] = -DISC_SPEED

    irradiance = 0.4 + 1.6 * np.exp(-((xs - width * 0.7) ** 2 + (ys * 0.8) ** 2) / (width**2 * 0.3))
    irradiance = irradiance.astype(f32)
    reference = (albedo * irradiance).astype(f32)

    rng = np.random.default_rng([seed, index])
    noise_direct = rng.gamma(DIRECT_SHAPE, 1.0 / DIRECT_SHAPE, size=(height, width)).astype(f32)
    noise_indirect = rng.gamma(INDIRECT_SHAPE, 1.0 / INDIRECT_SHAPE, size=(height, width))
    direct = reference * DIRECT_SHARE * noise_direct
    indirect = reference * (1.0 - DIRECT_SHARE) * noise_indirect.astype(f32)

    frame = Frame.direct_indirect(
        np.ascontiguousarray(direct, f32),
        np.ascontiguousarray(indirect, f32),
        albedo=np.ascontiguousarray(albedo, f32),
        normal=np.ascontiguousarray(normal),
        depth=np.ascontiguousarray(depth),
        motion=np.ascontiguousarray(motion),
        mesh_id=mesh_id,
    )
    return frame, np.ascontiguousarray(reference)


def write_synthetic_sequence(
    directory: str | os.PathLike[str],
    frames: int = 6,
    width: int = 64,
    height: int = 48,
    first: int = 1,
) -> tuple[str, str]:
    """Write ``in.####.exr`` (svgf layer names) and ``ref.####.exr``; return both patterns."""
    from svgf_cli.io.exr import write_exr

    folder = Path(directory)
    folder.mkdir(parents=True, exist_ok=True)
    for i in range(frames):
        frame, reference = synthetic_frame(i, width, height)
        number = first + i
        direct = frame.signal("direct").radiance
        indirect = frame.signal("indirect").radiance
        beauty = frame.total_radiance()
        channels = {
            "R": beauty[0],
            "G": beauty[1],
            "B": beauty[2],
            **{f"direct.{c}": direct[k] for k, c in enumerate("RGB")},
            **{f"indirect.{c}": indirect[k] for k, c in enumerate("RGB")},
            **{f"albedo.{c}": frame.albedo[k] for k, c in enumerate("RGB")},
            **{f"N.{c}": frame.normal[k] for k, c in enumerate("XYZ")},
            "Z": frame.depth,
            "motion.X": frame.motion[0],
            "motion.Y": frame.motion[1],
            "id": frame.mesh_id.astype(np.float32),
        }
        write_exr(folder / f"in.{number:04d}.exr", channels)
        write_exr(
            folder / f"ref.{number:04d}.exr",
            {"R": reference[0], "G": reference[1], "B": reference[2]},
        )
    return str(folder / "in.####.exr"), str(folder / "ref.####.exr")
