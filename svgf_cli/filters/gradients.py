"""Screen-space geometry gradients from the G-buffer (what a GPU gets from ddx/ddy/fwidth).

Both gradients use, per axis, the smaller of the two one-sided differences (in magnitude) so a
silhouette does not inflate the slope of the surface it bounds, and never difference across
background (depth <= 0): a side whose neighbour is background or outside the image is not
used; with neither side usable the derivative along that axis is 0.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from svgf_cli.filters.fastmath import FASTMATH

F32 = np.float32
_ZERO = F32(0.0)


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, error_model="numpy")
def _pick_one_sided(
    left_ok: bool, right_ok: bool, left: np.float32, right: np.float32
) -> np.float32:
    if left_ok and right_ok:
        return left if abs(left) <= abs(right) else right
    if left_ok:
        return left
    if right_ok:
        return right
    return _ZERO


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def depth_gradients(depth: np.ndarray, ddx: np.ndarray, ddy: np.ndarray, slope: np.ndarray) -> None:
    """Per-axis depth derivatives ``ddx``, ``ddy`` (signed, depth units per pixel) and the
    reprojection slope ``max(|ddx|, |ddy|)`` (Falcor's ``LinearZ.y``). Background gets 0."""
    height, width = depth.shape
    for y in prange(height):
        for x in range(width):
            z = depth[y, x]
            if z <= _ZERO:
                ddx[y, x] = _ZERO
                ddy[y, x] = _ZERO
                slope[y, x] = _ZERO
                continue
            left_ok = x > 0 and depth[y, x - 1] > _ZERO
            right_ok = x < width - 1 and depth[y, x + 1] > _ZERO
            gx = _pick_one_sided(
                left_ok,
                right_ok,
                z - depth[y, x - 1] if left_ok else _ZERO,
                depth[y, x + 1] - z if right_ok else _ZERO,
            )
            up_ok = y > 0 and depth[y - 1, x] > _ZERO
            down_ok = y < height - 1 and depth[y + 1, x] > _ZERO
            gy = _pick_one_sided(
                up_ok,
                down_ok,
                z - depth[y - 1, x] if up_ok else _ZERO,
                depth[y + 1, x] - z if down_ok else _ZERO,
            )
            ddx[y, x] = gx
            ddy[y, x] = gy
            slope[y, x] = max(abs(gx), abs(gy))


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, error_model="numpy")
def _normal_step(
    normal: np.ndarray, y: int, x: int, y0: int, x0: int, y1: int, x1: int, ok0: bool, ok1: bool
) -> tuple[np.float32, np.float32, np.float32]:
    """One-sided normal difference along one axis, the smaller of the usable sides."""
    d0x = d0y = d0z = d1x = d1y = d1z = _ZERO
    if ok0:
        d0x = normal[0, y, x] - normal[0, y0, x0]
        d0y = normal[1, y, x] - normal[1, y0, x0]
        d0z = normal[2, y, x] - normal[2, y0, x0]
    if ok1:
        d1x = normal[0, y1, x1] - normal[0, y, x]
        d1y = normal[1, y1, x1] - normal[1, y, x]
        d1z = normal[2, y1, x1] - normal[2, y, x]
    if ok0 and ok1:
        if d0x * d0x + d0y * d0y + d0z * d0z <= d1x * d1x + d1y * d1y + d1z * d1z:
            return d0x, d0y, d0z
        return d1x, d1y, d1z
    if ok0:
        return d0x, d0y, d0z
    return d1x, d1y, d1z


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def normal_gradient(normal: np.ndarray, depth: np.ndarray, out: np.ndarray) -> None:
    """``length(fwidth(n))`` with fwidth = |ddx n| + |ddy n| per component (Falcor's
    ``PositionNormalFwidth.y``), one-sided as described in the module docstring."""
    height, width = depth.shape
    for y in prange(height):
        for x in range(width):
            if depth[y, x] <= _ZERO:
                out[y, x] = _ZERO
                continue
            left_ok = x > 0 and depth[y, x - 1] > _ZERO
            right_ok = x < width - 1 and depth[y, x + 1] > _ZERO
            ax, ay, az = _normal_step(normal, y, x, y, x - 1, y, x + 1, left_ok, right_ok)
            up_ok = y > 0 and depth[y - 1, x] > _ZERO
            down_ok = y < height - 1 and depth[y + 1, x] > _ZERO
            bx, by, bz = _normal_step(normal, y, x, y - 1, x, y + 1, x, up_ok, down_ok)
            fx = abs(ax) + abs(bx)
            fy = abs(ay) + abs(by)
            fz = abs(az) + abs(bz)
            out[y, x] = np.sqrt(fx * fx + fy * fy + fz * fz)


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def unit_normals(normal: np.ndarray, depth: np.ndarray, out: np.ndarray) -> None:
    """Normalise normals; background and degenerate normals become (0, 0, 0).

    A zero normal makes ``max(0, n.n')`` vanish, so the spatial kernels need no separate
    background test: no weight ever flows to or from a background pixel.
    """
    height, width = depth.shape
    for y in prange(height):
        for x in range(width):
            nx = normal[0, y, x]
            ny = normal[1, y, x]
            nz = normal[2, y, x]
            length_sq = nx * nx + ny * ny + nz * nz
            if depth[y, x] <= _ZERO or not (length_sq > F32(1e-12)):
                out[0, y, x] = _ZERO
                out[1, y, x] = _ZERO
                out[2, y, x] = _ZERO
            else:
                inv = F32(1.0) / np.sqrt(length_sq)
                out[0, y, x] = nx * inv
                out[1, y, x] = ny * inv
                out[2, y, x] = nz * inv
