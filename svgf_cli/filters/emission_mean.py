"""The emission of a still light's jittered outline, averaged over time.

A renderer's emission pass is noise-free but for where a light's outline crosses a pixel:
one jittered sample per pixel hits the light or misses it, so the outline's pixels flip
between the light's radiance and nothing from frame to frame, while the converged frame
shows their coverage (the light's radiance times the share of the pixel it covers). Where
nothing moves, the pixel's running mean over frames is that coverage. The filter adds the
emission back unfiltered, so without this a light's outline flickers in the output.

Per pixel, with ``E`` this frame's emission, ``h`` the running mean and ``n`` its length:

* *still*: the largest motion in the 3x3 around the pixel is at most ``STILL_MOTION``
  pixels, in this frame and the last (a light that moved away leaves still pixels behind);
* *steady*: the brightest emission in the 3x3 (the light's radiance, for an outline
  pixel) is within ``LEVEL_CHANGE`` of last frame's (a light dimming or switching on
  starts over);
* where both hold, ``h`` is clamped to the 3x3 range of ``E`` (inside a light or away from
  it that range is one value: ``h = E`` exactly), ``n = min(n + 1, cap)``, and
  ``h += max(1 / n, alpha) (E - h)``; elsewhere ``h = E``, ``n = 1``.

Measured: docs/stability.md#a-still-lights-outline.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from svgf_cli.filters.fastmath import FASTMATH

F32 = np.float32
STILL_MOTION = F32(0.01)  # pixels
LEVEL_CHANGE = F32(0.01)  # relative


@njit(parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
      error_model="numpy")
def emission_mean(
    emission: np.ndarray,
    motion: np.ndarray,
    mean: np.ndarray,
    length: np.ndarray,
    still: np.ndarray,
    level: np.ndarray,
    alpha: np.float32,
    cap: np.float32,
) -> None:
    """In place: ``mean`` (3, H, W) and ``length`` (H, W) one frame on, and ``still``
    (H, W, uint8) and ``level`` (H, W) set to this frame's (module docstring). ``length``
    0 means no mean yet (the first frame)."""
    height, width = length.shape
    limit = STILL_MOTION * STILL_MOTION
    for y in prange(height):
        y0, y1 = max(y - 1, 0), min(y + 2, height)
        for x in range(width):
            x0, x1 = max(x - 1, 0), min(x + 2, width)
            moving = False
            brightest = F32(0.0)
            for yy in range(y0, y1):
                for xx in range(x0, x1):
                    mx, my = motion[0, yy, xx], motion[1, yy, xx]
                    moving |= mx * mx + my * my > limit
                    for c in range(3):
                        brightest = max(brightest, emission[c, yy, xx])
            was_still = still[y, x] != 0
            before = level[y, x]
            still[y, x] = 0 if moving else 1
            level[y, x] = brightest
            steady = abs(brightest - before) <= LEVEL_CHANGE * max(brightest, before)
            if moving or not was_still or not steady or length[y, x] <= F32(0.0):
                length[y, x] = F32(1.0)
                for c in range(3):
                    mean[c, y, x] = emission[c, y, x]
                continue
            n = min(length[y, x] + F32(1.0), cap)
            length[y, x] = n
            if brightest <= F32(0.0):  # no light around: the 3x3 range is 0, so is the mean
                for c in range(3):
                    mean[c, y, x] = emission[c, y, x]
                continue
            weight = max(F32(1.0) / n, alpha)
            for c in range(3):
                low = emission[c, y, x]
                high = low
                for yy in range(y0, y1):
                    for xx in range(x0, x1):
                        value = emission[c, yy, xx]
                        low = min(low, value)
                        high = max(high, value)
                h = min(max(mean[c, y, x], low), high)
                mean[c, y, x] = h + weight * (emission[c, y, x] - h)
