"""Whether a frame's one sample per pixel was jittered over its pixel, read from its depth.

Under a perspective camera the inverse depth of a plane is an affine function of the image
position, so where three neighbouring pixels of a row (or a column) sample one plane through
their centres, their inverse depths ``u`` lie on a line: the second difference ``u[-1] -
2 u[0] + u[1]`` is zero up to rounding. A renderer that puts each pixel's sample at a random
point of the pixel (or of its pixel filter), G-buffer included, as Mitsuba and most
renderers do at one sample per pixel, moves each of the three along the plane's gradient by
up to about a pixel: the second difference is then of the order of the first,
``g = (u[1] - u[-1]) / 2``.

:func:`plane_triples` counts, over the triples of one object with equal normals (a plane)
whose depth changes by at least ``MIN_SLOPE`` per pixel (rounding stays far below the test),
those whose ``|second difference|`` exceeds ``JITTER_RATIO |g|``. Measured over the bundled
frames (``docs/stability.md#jittered-outlines``): 0 % on every frame sampled at pixel centres
(``svgf trace``; Cycles, whose G-buffer is its centre sample at any sample count), 94-96 %
on jittered ones (``svgf trace --jitter``, Cycles with a sample offset), 97 % through a wide
lens (Cycles' depth of field moves the camera rays' origin: its header says centre-sampled,
which wins). A frame with fewer than ``MIN_TRIPLES`` such triples (no plane at a slant) is
not called jittered.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from svgf_cli.filters.fastmath import FASTMATH

F32 = np.float32
_ZERO = F32(0.0)
_HALF = F32(0.5)
# A triple is jittered when its second difference exceeds this share of its slope.
JITTER_RATIO = F32(0.1)
# Slopes below this share of the inverse depth per pixel are not tested (float32 rounding of
# the depth, ~6e-8 of it, must stay far below JITTER_RATIO of the slope).
MIN_SLOPE = F32(1e-4)
# Normals within this (per component) are one plane's.
PLANE_NORMAL = F32(1e-3)
# Too few triples to tell: not jittered.
MIN_TRIPLES = 64
# The share of jittered triples from which the frame is jittered.
JITTERED_SHARE = 0.5
# Every this many rows (from row 1): a 1080p frame still gives millions of triples, a
# 128x72 one thousands, in a quarter of the time (23 -> 6 ms at 1080p, 2 threads).
ROW_STEP = 4


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, error_model="numpy")
def _triple(depth: np.ndarray, normal: np.ndarray, mesh_id: np.ndarray, y0: int, x0: int,
            y1: int, x1: int, y2: int, x2: int) -> int:
    """-1: not a tested triple; 0: on a line; 1: jittered."""
    z0, z1, z2 = depth[y0, x0], depth[y1, x1], depth[y2, x2]
    if z0 <= _ZERO or z1 <= _ZERO or z2 <= _ZERO:
        return -1
    if mesh_id[y0, x0] != mesh_id[y1, x1] or mesh_id[y2, x2] != mesh_id[y1, x1]:
        return -1
    for c in range(3):
        n1 = normal[c, y1, x1]
        if abs(normal[c, y0, x0] - n1) > PLANE_NORMAL or abs(normal[c, y2, x2] - n1) > PLANE_NORMAL:
            return -1
    u0, u1, u2 = F32(1.0) / z0, F32(1.0) / z1, F32(1.0) / z2
    slope = abs(u2 - u0) * _HALF
    if not slope > MIN_SLOPE * u1:
        return -1
    return 1 if abs(u0 - F32(2.0) * u1 + u2) > JITTER_RATIO * slope else 0


@njit(parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
      error_model="numpy")
def plane_triples(depth: np.ndarray, normal: np.ndarray, mesh_id: np.ndarray) -> tuple[int, int]:
    """(tested, jittered): the row and column triples of pixels on one plane at a slant
    (module docstring) centred on every ``ROW_STEP``-th row from row 1, and how many of
    them are off the line by more than ``JITTER_RATIO`` of their slope. ``depth`` (H, W),
    background <= 0; ``normal`` (3, H, W); ``mesh_id`` (H, W)."""
    height, width = depth.shape
    rows = max((height - 2 + ROW_STEP - 1) // ROW_STEP, 0)  # rows 1, 1 + ROW_STEP, ...
    tested = np.zeros(rows, dtype=np.int64)
    jittered = np.zeros(rows, dtype=np.int64)
    for row in prange(rows):
        y = 1 + row * ROW_STEP
        for x in range(1, width - 1):
            t = _triple(depth, normal, mesh_id, y, x - 1, y, x, y, x + 1)
            if t >= 0:
                tested[row] += 1
                jittered[row] += t
        for x in range(width):
            t = _triple(depth, normal, mesh_id, y - 1, x, y, x, y + 1, x)
            if t >= 0:
                tested[row] += 1
                jittered[row] += t
    return int(tested.sum()), int(jittered.sum())


def jittered_samples(depth: np.ndarray, normal: np.ndarray, mesh_id: np.ndarray) -> bool:
    """Whether the G-buffer shows jittered samples: at least ``MIN_TRIPLES`` plane triples,
    ``JITTERED_SHARE`` of them off their line (:func:`plane_triples`)."""
    tested, jittered = plane_triples(depth, normal, mesh_id)
    return tested >= MIN_TRIPLES and jittered >= JITTERED_SHARE * tested


def jittered_frame(centre_sampled: bool, depth: np.ndarray, normal: np.ndarray,
                   mesh_id: np.ndarray) -> bool:
    """Whether a frame's samples are jittered: the header's word first (a frame it says is
    centre-sampled is not, whatever a lens did to its G-buffer), else its planes
    (:func:`jittered_samples`)."""
    return not centre_sampled and jittered_samples(depth, normal, mesh_id)
