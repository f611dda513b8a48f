"""The colour history kept for the next frame: a blend of an a-trous iteration's output and
the unfiltered accumulation, by whether the pixel moves.

The paper keeps the output of an a-trous iteration as next frame's colour history. Where a
pixel moves, that history is resampled at a sub-pixel position next frame and the a-trous
blur compounds with the resampling's, frame after frame; where it stands still, nothing is
resampled and the recursive filtering pays (docs/algorithm.md, "Feedback where pixels
move"). A causal run keeps the feedback iteration's output where pixels stand still and
``moving_feedback_share`` of it where they move; a pass of a bidirectional run
``STATIC_FILTERED_SHARE`` of the first iteration's where they stand still and none where
they move (``filters.bidirectional``). The blend is written into the unfiltered buffer,
which is dead once the iteration has read it, so it costs no buffer of its own.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from svgf_cli.filters.fastmath import FASTMATH

F32 = np.float32
_ZERO = F32(0.0)
_ONE = F32(1.0)

_JIT = dict(fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy")


@njit(parallel=True, **_JIT)
def blend_history(
    unfiltered: np.ndarray,
    filtered: np.ndarray,
    motion: np.ndarray,
    limit: np.float32,
    still_share: np.float32,
    moving_share: np.float32,
) -> None:
    """The colour history, in place in ``unfiltered`` (S, 3, H, W):
    ``H = w F + (1 - w) U`` per signal, channel and pixel, with ``F`` an a-trous
    iteration's output (``filtered``), ``U`` the colour entering the a-trous, ``w =
    still_share`` where the pixel's motion (2, H, W) is below ``limit`` on both axes and
    ``moving_share`` where it is not. A weight of 1 or 0 gives ``F`` or ``U`` exactly; a
    row whose weights are all 0 is not touched."""
    num_signals = unfiltered.shape[0]
    height, width = motion.shape[1], motion.shape[2]
    for y in prange(height):
        mx = motion[0, y]
        my = motion[1, y]
        w = np.empty(width, dtype=np.float32)
        rest = np.empty(width, dtype=np.float32)
        any_weight = False
        for x in range(width):
            still = (abs(mx[x]) < limit) & (abs(my[x]) < limit)
            w[x] = still_share if still else moving_share
            rest[x] = _ONE - w[x]
            any_weight |= w[x] != _ZERO
        if not any_weight:
            continue  # the whole row moves and keeps none of the filtered colour
        for s in range(num_signals):
            for c in range(3):
                u = unfiltered[s, c, y]
                f = filtered[s, c, y]
                for x in range(width):
                    u[x] = w[x] * f[x] + rest[x] * u[x]
