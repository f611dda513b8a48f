"""The renderer's pixel filter across outlines, for frames whose sample went through the
pixel centre.

A centre-sampled frame (``filters.pixel_filter``) sees, at a pixel on an object's outline,
one of the two surfaces: the one at the centre, in every frame, so no history mixes them.
The renderer's converged frame weighs both by the pixel filter: a silhouette against the
sky, a light's edge, an object in front of another are anti-aliased there, and a staircase
of point samples crawls as the outline moves. The a-trous never blurs across an outline
(its edge-stops), and the emission (the sky seen directly, lights) is added back
unfiltered, so the pixel filter's small interior kernel (0.05, tuned where the a-trous has
already blurred) leaves outlines as sharp as the samples.

:func:`edge_filter` adds the filter's spill across outlines: for each pair of neighbouring
pixels on two surfaces (another object id, background, or depths more than ``DEPTH_JUMP``
apart), each takes ``w`` of the other's whole colour, emission included, and gives up as
much of its own (``c'(p) = c(p) + w sum_{q ~ p} (c(q) - c(p))`` over its outline
neighbours, rows then columns): what the pair holds is kept. Where the 1-spp G-buffer
itself is noisy (a defocused region whose depth jumps from sample to sample, the surfaces
seen through fog) every pair is an outline, and the spill is a small blur of what the
G-buffer could not guide.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from svgf_cli.filters.fastmath import FASTMATH
from svgf_cli.filters.params import AUTO_PIXEL_FILTER

F32 = np.float32
_ZERO = F32(0.0)
# Depths further apart than this ratio are two surfaces (as filters.taa's outlines).
DEPTH_JUMP = F32(1.05)
# Each outline neighbour's weight for a centre-sampled frame (on top of the pixel filter's).
CENTRE_SAMPLE_EDGE_WEIGHT = 0.05


def edge_filter_weight(setting: float, centre_sampled: bool) -> float:
    """The outline neighbours' weight for a frame: ``setting`` unless it is
    ``AUTO_PIXEL_FILTER``, then ``CENTRE_SAMPLE_EDGE_WEIGHT`` for a centre-sampled frame and
    0 for any other."""
    if setting != AUTO_PIXEL_FILTER:
        return setting
    return CENTRE_SAMPLE_EDGE_WEIGHT if centre_sampled else 0.0


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, error_model="numpy")
def _outline(mesh_a: np.int32, mesh_b: np.int32, z_a: np.float32, z_b: np.float32) -> bool:
    """Whether two neighbouring pixels show two surfaces."""
    if mesh_a != mesh_b:
        return True
    if z_a <= _ZERO or z_b <= _ZERO:
        return z_a > _ZERO or z_b > _ZERO
    return z_a > DEPTH_JUMP * z_b or z_b > DEPTH_JUMP * z_a


@njit(fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy")
def _pair_weights(ids_a: np.ndarray, z_a: np.ndarray, ids_b: np.ndarray, z_b: np.ndarray,
                  weight: np.float32, out: np.ndarray) -> None:
    """``out[i] = weight`` where pixels ``a[i]`` and ``b[i]`` show two surfaces, else 0."""
    for i in range(out.size):
        out[i] = weight if _outline(ids_a[i], ids_b[i], z_a[i], z_b[i]) else _ZERO


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def edge_filter(colour: np.ndarray, mesh_id: np.ndarray, depth: np.ndarray,
                weight: np.float32, out: np.ndarray) -> None:
    """``out`` (3, H, W): ``colour`` (3, H, W) with ``weight`` of each outline neighbour's
    colour exchanged, along rows then columns (module docstring); float32. The pairs'
    weights are found once per row; the exchanges run over row slices."""
    height, width = depth.shape
    rows = np.empty((3, height, width), dtype=F32)
    for y in prange(height):
        ids, z = mesh_id[y], depth[y]
        left = np.zeros(width, dtype=F32)  # with the pixel to the left
        right = np.zeros(width, dtype=F32)
        _pair_weights(ids[:-1], z[:-1], ids[1:], z[1:], weight, right[:-1])
        left[1:] = right[:-1]
        for c in range(3):
            source, row = colour[c, y], rows[c, y]
            row[0] = source[0] + right[0] * (source[1] - source[0]) if width > 1 else source[0]
            for x in range(1, width - 1):
                here = source[x]
                row[x] = (here + left[x] * (source[x - 1] - here)
                          + right[x] * (source[x + 1] - here))
            if width > 1:
                row[width - 1] = source[width - 1] + left[width - 1] * (
                    source[width - 2] - source[width - 1])
    for y in prange(height):
        ids, z = mesh_id[y], depth[y]
        up = np.zeros(width, dtype=F32)
        down = np.zeros(width, dtype=F32)
        if y > 0:
            _pair_weights(ids, z, mesh_id[y - 1], depth[y - 1], weight, up)
        if y < height - 1:
            _pair_weights(ids, z, mesh_id[y + 1], depth[y + 1], weight, down)
        above = max(y - 1, 0)
        below = min(y + 1, height - 1)
        for c in range(3):
            here, target = rows[c, y], out[c, y]
            over, under = rows[c, above], rows[c, below]
            for x in range(width):
                h = here[x]
                target[x] = h + up[x] * (over[x] - h) + down[x] * (under[x] - h)
