"""The renderer's pixel filter, for frames whose one sample went through the pixel centre.

SVGF's output estimates, per pixel, the radiance its samples saw. Where every frame's sample
goes through the pixel centre (Cycles at 1 spp traces its sample 0 there, docs/cycles.md),
that is the radiance at the centre: edges and texture boundaries stay as sharp as point
samples make them, while a converged frame of the same renderer averages the footprint of
its pixel filter. Measured on Blender renders of ``roll`` at 256x144, the mean of four 1-spp
realisations differs from the 1024-sample reference by a squared relative error of 0.027
beyond their noise: more than the whole bias of the filtered output (docs/cycles.md).

:func:`pixel_filter` applies the difference as a separable three-tap kernel
``[w, 1 - 2 w, w]`` per axis to the output without its emission (emitters and the
environment, noise-free and added back unfiltered as everywhere in svgf), image edges
replicated: it keeps a constant image constant and, away from edges, a linear ramp. Between
centre samples the radiance is known only at the centres; a tent through them, filtered by
Cycles' default pixel filter (Blackman-Harris, 1.5 px wide), weighs each neighbour by
``int_0^0.75 k(u) u du = 0.084``. The a-trous and the resampling already blur a little, and
measured on the Blender fixtures the best ``w`` was 0.05-0.07 (``CENTRE_SAMPLE_WEIGHT``; the
metal scene at 128x72 preferred less).

``auto`` (``AUTO_PIXEL_FILTER``, the ``default`` preset) applies it to frames whose header
says they are centre-sampled (``Frame.centre_sampled``) and leaves every other frame as it
is: a renderer that jitters its sample over the pixel filter (or Cycles with a sample
offset) already averages the footprint over the frames, and ``svgf trace``'s references
are pixel centres too.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from svgf_cli.filters.fastmath import FASTMATH
from svgf_cli.filters.params import AUTO_PIXEL_FILTER

F32 = np.float32
_ONE = F32(1.0)
_TWO = F32(2.0)
# Each neighbour's weight for a centre-sampled frame against Cycles' default pixel filter.
CENTRE_SAMPLE_WEIGHT = 0.05


def pixel_filter_weight(setting: float, centre_sampled: bool) -> float:
    """The kernel's neighbour weight for a frame: ``setting`` itself unless it is
    ``AUTO_PIXEL_FILTER``, then ``CENTRE_SAMPLE_WEIGHT`` for a centre-sampled frame and 0
    for any other."""
    if setting != AUTO_PIXEL_FILTER:
        return setting
    return CENTRE_SAMPLE_WEIGHT if centre_sampled else 0.0


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def pixel_filter(
    colour: np.ndarray, emission: np.ndarray, weight: np.float32, out: np.ndarray
) -> None:
    """``out = K (colour - emission) + emission``, ``K`` the separable kernel
    ``[w, 1 - 2 w, w]`` along rows then columns, edges replicated; all (3, H, W) float32."""
    height, width = colour.shape[1], colour.shape[2]
    centre = _ONE - _TWO * weight
    rows = np.empty((3, height, width), dtype=F32)
    for y in prange(height):
        for c in range(3):
            source = colour[c, y]
            light = emission[c, y]
            row = rows[c, y]
            last = width - 1
            for x in range(width):
                left = max(x - 1, 0)
                right = min(x + 1, last)
                row[x] = (centre * (source[x] - light[x])
                          + weight * (source[left] - light[left] + source[right] - light[right]))
    for y in prange(height):
        up = rows[:, max(y - 1, 0)]
        here = rows[:, y]
        down = rows[:, min(y + 1, height - 1)]
        for c in range(3):
            light = emission[c, y]
            target = out[c, y]
            for x in range(width):
                target[x] = centre * here[c, x] + weight * (up[c, x] + down[c, x]) + light[x]
