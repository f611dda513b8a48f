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


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def edge_filter(colour: np.ndarray, mesh_id: np.ndarray, depth: np.ndarray,
                weight: np.float32, out: np.ndarray) -> None:
    """``out`` (3, H, W): ``colour`` (3, H, W) with ``weight`` of each outline neighbour's
    colour exchanged, along rows then columns (module docstring); float32."""
    height, width = depth.shape
    rows = np.empty((3, height, width), dtype=F32)
    for y in prange(height):
        ids, z = mesh_id[y], depth[y]
        for c in range(3):
            source, row = colour[c, y], rows[c, y]
            for x in range(width):
                row[x] = source[x]
            for x in range(width - 1):
                if _outline(ids[x], ids[x + 1], z[x], z[x + 1]):
                    flow = weight * (source[x + 1] - source[x])
                    row[x] += flow
                    row[x + 1] -= flow
    for y in prange(height):
        for c in range(3):
            target = out[c, y]
            here = rows[c, y]
            for x in range(width):
                target[x] = here[x]
        for other in (y - 1, y + 1):
            if other < 0 or other >= height:
                continue
            ids, z = mesh_id[y], depth[y]
            ids_o, z_o = mesh_id[other], depth[other]
            for x in range(width):
                if _outline(ids[x], ids_o[x], z[x], z_o[x]):
                    for c in range(3):
                        out[c, y, x] += weight * (rows[c, other, x] - rows[c, y, x])
