"""Row order for parallel loops: every thread gets rows from the whole frame.

numba hands each of its T threads one contiguous block of a ``prange``. Frames are not
uniform top to bottom (sky rows cost nothing, the ground is dense), so contiguous blocks
left one thread idle while the other finished (measured in the a-trous). Iteration ``i`` of
``prange(balanced_row_count(h, T))`` maps to row ``balanced_row(i, h, T)``: thread k
processes rows k, k + T, k + 2T, ... Indices past the last row map to ``>= h`` and are
skipped by the caller.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from svgf_cli.filters.fastmath import FASTMATH


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, error_model="numpy")
def balanced_row_count(height: int, threads: int) -> int:
    """Iterations for :func:`balanced_row`: ``threads * ceil(height / threads)``."""
    per_thread = (height + threads - 1) // threads
    return per_thread * threads


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, error_model="numpy")
def balanced_row(i: int, height: int, threads: int) -> np.int64:
    """Row for iteration ``i``: block k of the iteration space gets rows k, k + T, ..."""
    per_thread = (height + threads - 1) // threads
    return np.int64((i % per_thread) * threads + i // per_thread)
