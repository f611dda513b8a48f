"""Optional temporal anti-aliasing of the final output (the paper's last step, off by default).

The previous output is resampled bilinearly at the backprojected position (same motion as
the reprojection), clamped per channel to the min/max of the current output's 3x3
neighbourhood (so disoccluded or changed content cannot ghost), and blended:
``out = lerp(prev_clamped, current, taa_alpha)``. Pixels whose previous position falls
outside the image take the current value.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from svgf_cli.filters.fastmath import FASTMATH

F32 = np.float32
_ONE = F32(1.0)


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def taa_resolve(
    current: np.ndarray,
    previous: np.ndarray,
    motion: np.ndarray,
    alpha: np.float32,
    out: np.ndarray,
) -> None:
    """Blend ``current`` (3, H, W) with the reprojected, neighbourhood-clamped ``previous``."""
    height, width = current.shape[1], current.shape[2]
    for y in prange(height):
        for x in range(width):
            px = F32(x) + motion[0, y, x]
            py = F32(y) + motion[1, y, x]
            inside = (
                px >= F32(-0.5)
                and py >= F32(-0.5)
                and px <= F32(width) - F32(0.5)
                and py <= F32(height) - F32(0.5)
            )
            if not inside:
                for c in range(3):
                    out[c, y, x] = current[c, y, x]
                continue
            fx0 = np.floor(px)
            fy0 = np.floor(py)
            fx = px - fx0
            fy = py - fy0
            xa = min(max(int(fx0), 0), width - 1)
            xb = min(max(int(fx0) + 1, 0), width - 1)
            ya = min(max(int(fy0), 0), height - 1)
            yb = min(max(int(fy0) + 1, 0), height - 1)
            for c in range(3):
                lo = current[c, y, x]
                hi = lo
                for yy in range(max(y - 1, 0), min(y + 2, height)):
                    for xx in range(max(x - 1, 0), min(x + 2, width)):
                        v = current[c, yy, xx]
                        lo = min(lo, v)
                        hi = max(hi, v)
                plane = previous[c]
                sampled = (
                    (_ONE - fy) * ((_ONE - fx) * plane[ya, xa] + fx * plane[ya, xb])
                    + fy * ((_ONE - fx) * plane[yb, xa] + fx * plane[yb, xb])
                )
                sampled = min(max(sampled, lo), hi)
                out[c, y, x] = sampled + alpha * (current[c, y, x] - sampled)
