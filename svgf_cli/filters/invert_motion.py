"""Motion to the next frame, derived from the next frame's backward motion (scatter).

A bidirectional run's reverse pass reprojects frame ``t + 1`` into frame ``t``: it needs, per
pixel of ``t``, where its surface is in ``t + 1``. When the renderer did not write that
(``motion_next``), it is the inverse of frame ``t + 1``'s backward motion: every surface
pixel ``q`` of ``t + 1`` lands at ``P = q + m(q)`` in frame ``t`` (pixel-index space, as the
reprojection reads motion). Scattered with a depth test:

* ``P`` splats to its 2x2 pixels with bilinear weights ``w``;
* a pixel keeps only the candidates within ``depth_tolerance`` (relative) of the nearest
  one (its depth in ``t + 1``): where several surfaces land, the visible one wins;
* its motion is the weighted mean of ``-m(q)`` over those candidates (the next position is
  ``p - m(q)``, exact where the motion is locally constant), and a pixel no surface
  pixel of ``t + 1`` lands on is a hole: its surface is not visible in ``t + 1``
  (a disocclusion, seen backwards) and it gets ``NO_MOTION``, which the reprojection
  reads as "no history".

The reprojection's own tests (depth, normal, mesh id) still check every tap, so a wrong
candidate costs history, never a wrong one. Serial (a scatter has write conflicts), so the
result is the same for any thread count; a few milliseconds at 1080p.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from svgf_cli.filters.fastmath import FASTMATH

F32 = np.float32
_ZERO = F32(0.0)
_ONE = F32(1.0)
# Motion that leads far outside any image: the reprojection treats it as "no history"
# (finite and below the value policy's limit, so it is not counted as a bad input).
NO_MOTION = F32(1e9)
DEPTH_TOLERANCE = 0.02

_JIT = dict(fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy")


def invert_motion(
    next_motion: np.ndarray, next_depth: np.ndarray, out: np.ndarray,
    depth_tolerance: float = DEPTH_TOLERANCE, scratch: np.ndarray | None = None,
) -> int:
    """Fill ``out`` (2, H, W) with the motion from frame ``t`` to ``t + 1`` given frame
    ``t + 1``'s backward motion (2, H, W) and depth (H, W) (module docstring). Returns the
    number of holes (pixels set to ``NO_MOTION``). ``scratch``: an optional (2, H, W)
    float32 buffer to work in (else one is allocated)."""
    height, width = next_depth.shape
    if scratch is None or scratch.shape != (2, height, width):
        scratch = np.empty((2, height, width), dtype=F32)
    return int(_scatter(next_motion, next_depth, F32(depth_tolerance), scratch[0], scratch[1],
                        out))


@njit(inline="always", **_JIT)
def _footprint(qx: int, qy: int, motion: np.ndarray) -> tuple[int, int, np.float32, np.float32]:
    px = F32(qx) + motion[0, qy, qx]
    py = F32(qy) + motion[1, qy, qx]
    fx0 = np.floor(px)
    fy0 = np.floor(py)
    return int(fx0), int(fy0), px - fx0, py - fy0


@njit(**_JIT)
def _scatter(motion: np.ndarray, depth: np.ndarray, tolerance: np.float32,
             nearest: np.ndarray, weight: np.ndarray, out: np.ndarray) -> int:
    height, width = depth.shape
    big = F32(np.inf)
    for y in range(height):
        for x in range(width):
            nearest[y, x] = big
            weight[y, x] = _ZERO
            out[0, y, x] = _ZERO
            out[1, y, x] = _ZERO
    limit = F32(4.0) * F32(max(width, height))
    # Pass 0: the nearest candidate depth per pixel of frame t. Pass 1: the weighted mean of
    # -m(q) over the candidates near that depth. Both walk the same splat footprints.
    for second in range(2):
        for qy in range(height):
            for qx in range(width):
                z = depth[qy, qx]
                mx, my = motion[0, qy, qx], motion[1, qy, qx]
                if not (z > _ZERO and abs(mx) < limit and abs(my) < limit):
                    continue
                x0, y0, fx, fy = _footprint(qx, qy, motion)
                for k in range(4):
                    tx = x0 + (k & 1)
                    ty = y0 + (k >> 1)
                    w = (fx if k & 1 else _ONE - fx) * (fy if k >> 1 else _ONE - fy)
                    if not (w > _ZERO and 0 <= tx < width and 0 <= ty < height):
                        continue
                    if second == 0:
                        nearest[ty, tx] = min(nearest[ty, tx], z)
                    elif z <= nearest[ty, tx] * (_ONE + tolerance):
                        weight[ty, tx] += w
                        out[0, ty, tx] -= w * mx
                        out[1, ty, tx] -= w * my
    holes = 0
    for y in range(height):
        for x in range(width):
            w = weight[y, x]
            if w > _ZERO:
                out[0, y, x] /= w
                out[1, y, x] /= w
            else:
                out[0, y, x] = NO_MOTION
                out[1, y, x] = NO_MOTION
                holes += 1
    return holes
