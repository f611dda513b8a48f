"""Object ids that name the same surface from frame to frame, or do not.

The filter takes an object id as a surface's name: history and taps of another id belong
to another surface. Some renderers number objects anew for every frame: Mitsuba 3's
``shape_index`` AOV counts shapes in the order the scene loaded them, which changes from
one load to the next. Taken at their word, such ids reset the history of whole objects
whenever their numbers change, and the output is as noisy as a cold start.

The test compares two consecutive frames at the same pixel: where both see a surface at
(nearly) the same view depth with (nearly) the same normal, it is the same surface in all
but a few pixels (a surface moving by, an outline crossing), so its id should not change.
Measured shares of such pixels whose id changed: docs/inputs.md#object-ids.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from svgf_cli.filters.fastmath import FASTMATH

# The test looks at every ROW_STEP-th row: a share, not a map, is wanted.
ROW_STEP = 4
# "The same surface at the same pixel": view depth within 1 %, normals within ~8 degrees.
MAX_DEPTH_CHANGE = 0.01
MIN_NORMAL_DOT = 0.99
# Ids are called unstable when, over at least MIN_COMPARED_SHARE of the rows' pixels, more
# than UNSTABLE_SHARE of the pixels that saw the same surface changed id. A camera cut
# rarely shows a tenth of the frame at the same depth and normal. Measured: at most 1.3 %
# on every bundled sequence (outlines crossing, jittered outlines, fog, depth of field);
# 12-84 % on Mitsuba's renumbered shapes wherever their order changed.
MIN_COMPARED_SHARE = 0.1
UNSTABLE_SHARE = 0.1


@njit(parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
      error_model="numpy")
def _count_rows(prev_id, prev_depth, prev_normal, mesh_id, depth, normal, max_change,
                min_dot):  # noqa: ANN001, ANN202
    rows = prev_id.shape[0]
    width = prev_id.shape[1]
    compared = np.zeros(rows, np.int64)
    changed = np.zeros(rows, np.int64)
    for r in prange(rows):
        y = r * ROW_STEP
        for x in range(width):
            d0 = prev_depth[r, x]
            d1 = depth[y, x]
            if d0 <= 0.0 or d1 <= 0.0 or abs(d1 - d0) > max_change * d1:
                continue
            dot = (prev_normal[0, r, x] * normal[0, y, x] + prev_normal[1, r, x] * normal[1, y, x]
                   + prev_normal[2, r, x] * normal[2, y, x])
            if dot < min_dot:
                continue
            compared[r] += 1
            if prev_id[r, x] != mesh_id[y, x]:
                changed[r] += 1
    return compared.sum(), changed.sum()


def sampled_rows(mesh_id: np.ndarray, depth: np.ndarray, normal: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A frame's ids, depth and normals on the rows the test looks at (copies: the frame's
    planes are let go after filtering)."""
    return (np.ascontiguousarray(mesh_id[::ROW_STEP]), np.ascontiguousarray(depth[::ROW_STEP]),
            np.ascontiguousarray(normal[:, ::ROW_STEP]))


def id_change_share(
    previous: tuple[np.ndarray, np.ndarray, np.ndarray],
    mesh_id: np.ndarray,
    depth: np.ndarray,
    normal: np.ndarray,
) -> tuple[float, float]:
    """(share of the compared pixels whose id changed, compared pixels' share of the rows'
    pixels) between ``previous`` (`sampled_rows` of the last frame) and this frame.

    A pixel is compared when both frames see a surface there (depth > 0) at view depths
    within ``MAX_DEPTH_CHANGE`` of this frame's and with normals whose dot product is at
    least ``MIN_NORMAL_DOT``; it changed when its two ids differ.
    """
    prev_id, prev_depth, prev_normal = previous
    if prev_id.shape[1] != mesh_id.shape[1] or prev_id.shape[0] != -(-mesh_id.shape[0] // ROW_STEP):
        raise ValueError("id stability: the frames' sizes differ")
    compared, changed = _count_rows(prev_id, prev_depth, prev_normal, mesh_id, depth, normal,
                                    MAX_DEPTH_CHANGE, MIN_NORMAL_DOT)
    total = prev_id.size
    if compared == 0:
        return 0.0, 0.0
    return changed / compared, compared / total


def ids_unstable(change_share: float, compared_share: float) -> bool:
    """Whether a frame pair's shares (`id_change_share`) say the ids are renumbered."""
    return compared_share >= MIN_COMPARED_SHARE and change_share > UNSTABLE_SHARE


def without_ids(depth: np.ndarray) -> np.ndarray:
    """The id plane of a frame without ids: 0 on surfaces, -1 on background (as read)."""
    return np.where(depth > 0, 0, -1).astype(np.int32)
