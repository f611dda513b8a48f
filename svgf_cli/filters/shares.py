"""Kernels of the composable light layers (``filters.composable``): a clipped box mean and
the split of a total by per-pixel shares. Float64 references: ``tests/test_light_layers.py``.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from svgf_cli.filters.fastmath import FASTMATH

_JIT = dict(fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, parallel=True,
            error_model="numpy")


# Columns of one job of box_mean's vertical pass: each row's run of them is read at once.
_COLUMNS = 64


@njit(**_JIT)
def box_mean(planes: np.ndarray, radius: int, out: np.ndarray) -> None:
    """``out`` = the (C, H, W) planes' mean over a (2 radius + 1)^2 window clipped at the
    borders (each window divided by the pixels it covers), summed in float64: running sums
    along each row, then down each column (a block of columns at a time, each column's sum
    in the same order)."""
    channels, height, width = planes.shape
    rows = np.empty((channels, height, width), dtype=np.float64)
    for job in prange(channels * height):
        c, y = job // height, job % height
        running = 0.0
        for x in range(min(radius, width)):
            running += planes[c, y, x]
        for x in range(width):
            if x + radius < width:
                running += planes[c, y, x + radius]
            if x - radius - 1 >= 0:
                running -= planes[c, y, x - radius - 1]
            rows[c, y, x] = running
    blocks = (width + _COLUMNS - 1) // _COLUMNS
    for job in prange(channels * blocks):
        c, start = job // blocks, job % blocks * _COLUMNS
        end = min(start + _COLUMNS, width)
        running_columns = np.zeros(end - start)
        for y in range(min(radius, height)):
            for x in range(start, end):
                running_columns[x - start] += rows[c, y, x]
        for y in range(height):
            top, bottom = max(y - radius, 0), min(y + radius + 1, height)
            for x in range(start, end):
                if y + radius < height:
                    running_columns[x - start] += rows[c, y + radius, x]
                if y - radius - 1 >= 0:
                    running_columns[x - start] -= rows[c, y - radius - 1, x]
                left, right = max(x - radius, 0), min(x + radius + 1, width)
                out[c, y, x] = running_columns[x - start] / ((bottom - top) * (right - left))


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
      error_model="numpy")
def _positive_sum(weights: np.ndarray, c: int, y: int, x: int) -> float:
    """The weights of one pixel and channel summed, negative ones as 0."""
    s = 0.0
    for k in range(weights.shape[0]):
        s += max(weights[k, c, y, x], 0.0)
    return s


@njit(**_JIT)
def split_shares(total: np.ndarray, weights: np.ndarray, fallback: np.ndarray,
                 use_fallback: bool, floor: float, out: np.ndarray) -> None:
    """``out[k]`` = ``total`` x ``weights[k] / sum_j weights[j]`` per pixel and channel
    (negative weights count as 0); where that sum is at most ``floor``, the same with
    ``fallback`` (when ``use_fallback``), and where that is too, equal parts. ``out`` may be
    ``weights``: a value's weights are all read before its parts are written."""
    count, channels, height, width = weights.shape
    for job in prange(channels * height):
        c, y = job // height, job % height
        for x in range(width):
            s = _positive_sum(weights, c, y, x)
            source = 0
            if s <= floor and use_fallback:
                s = _positive_sum(fallback, c, y, x)
                source = 1
            t = total[c, y, x]
            if s <= floor:
                for k in range(count):
                    out[k, c, y, x] = t / count
            elif source == 0:
                for k in range(count):
                    out[k, c, y, x] = t * (max(weights[k, c, y, x], 0.0) / s)
            else:
                for k in range(count):
                    out[k, c, y, x] = t * (max(fallback[k, c, y, x], 0.0) / s)


@njit(**_JIT)
def fallback_pixels(total: np.ndarray, weights: np.ndarray, floor: float) -> int:
    """How many (pixel, channel) values :func:`split_shares` would take from its fallback:
    ``total`` not 0 where the weights (negative as 0) sum to at most ``floor``; the same
    sum as there, so 0 means the fallback changes nothing."""
    _, channels, height, width = weights.shape
    found = np.zeros(channels * height, np.int64)
    for job in prange(channels * height):
        c, y = job // height, job % height
        for x in range(width):
            if _positive_sum(weights, c, y, x) <= floor and total[c, y, x] != 0.0:
                found[job] += 1
    return int(found.sum())
