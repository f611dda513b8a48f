"""Edge-stopping weights of the spatial-variance kernel (paper section 4.3, equations 3-5).

That kernel loops taps outer and pixels inner; for one tap offset these helpers fill row
buffers over a contiguous run of centre pixels ``p`` and their neighbours ``q = p + offset``,
so every inner loop is branch-free and vectorizes. The a-trous evaluates the same depth and
normal terms register-blocked in ``atrous._tap`` (with ``DEPTH_EPSILON`` from here).

* depth: ``|z(p) - z(q)| / (sigma_z * |grad z(p) . (p - q)| + eps * z(p))`` is the exponent
  of ``w_z`` (the paper's projected gradient; Falcor uses ``|grad z| * |p - q|`` instead,
  which is more permissive across a slope and stricter along a contour). ``eps`` is relative
  to depth (``DEPTH_EPSILON``) so the weight does not depend on scene units; it keeps
  curved surfaces filterable along their contour lines where the projected gradient is 0.
* normal: ``max(0, n(p).n(q)) ** sigma_n``; for a power-of-two ``sigma_n`` (128 = 7
  squarings) the power is repeated squaring over the row buffer, which vectorizes.
  Background normals are zero, so background never exchanges weight with a surface.
  The paper's sigma_n = 128 (7 squarings) has its own fully unrolled loop.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from svgf_cli.filters.fastmath import FASTMATH

F32 = np.float32
_ZERO = F32(0.0)
DEPTH_EPSILON = F32(1e-3)
# Keeps 0/0 away for background centres (depth 0) without changing any real weight.
DEPTH_TINY = F32(1e-20)


def normal_squarings(sigma_normal: float) -> int:
    """Number of squarings equal to ``x ** sigma_normal``, or -1 if it is not a power of 2."""
    if sigma_normal >= 1.0:
        exponent = int(round(np.log2(sigma_normal)))
        if 0 <= exponent <= 12 and 2.0**exponent == sigma_normal:
            return exponent
    return -1


@njit(
    inline="always", fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
    error_model="numpy",
)
def tap_geometry(
    z_p: np.ndarray,
    gx_p: np.ndarray,
    gy_p: np.ndarray,
    nx_p: np.ndarray,
    ny_p: np.ndarray,
    nz_p: np.ndarray,
    z_q: np.ndarray,
    nx_q: np.ndarray,
    ny_q: np.ndarray,
    nz_q: np.ndarray,
    offset_x: np.float32,
    offset_y: np.float32,
    sigma_depth: np.float32,
    squarings: int,
    sigma_normal: np.float32,
    kernel: np.float32,
    depth_exponent: np.ndarray,
    normal_weight: np.ndarray,
    count: int,
) -> None:
    """Fill ``depth_exponent[:count]`` (the w_z exponent) and ``normal_weight[:count]``
    (``kernel * w_n``). Separate loops over few arrays each, so every one vectorizes."""
    for i in range(count):
        z = z_p[i]
        projected = abs(gx_p[i] * offset_x + gy_p[i] * offset_y)
        floor = DEPTH_EPSILON * z + DEPTH_TINY
        depth_exponent[i] = abs(z - z_q[i]) / (sigma_depth * projected + floor)
    if squarings == 7:
        for i in range(count):
            c = max(nx_p[i] * nx_q[i] + ny_p[i] * ny_q[i] + nz_p[i] * nz_q[i], _ZERO)
            c *= c
            c *= c
            c *= c
            c *= c
            c *= c
            c *= c
            c *= c
            normal_weight[i] = kernel * c
        return
    for i in range(count):
        normal_weight[i] = max(nx_p[i] * nx_q[i] + ny_p[i] * ny_q[i] + nz_p[i] * nz_q[i], _ZERO)
    if squarings >= 0:
        for _ in range(squarings):
            for i in range(count):
                normal_weight[i] *= normal_weight[i]
    else:
        for i in range(count):
            c = normal_weight[i]
            normal_weight[i] = c**sigma_normal if c > _ZERO else _ZERO
    for i in range(count):
        normal_weight[i] *= kernel
