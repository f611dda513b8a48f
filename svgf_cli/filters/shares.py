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
                 use_fallback: bool, last: np.ndarray, floor: float, out: np.ndarray) -> None:
    """``out[k]`` = ``total`` x ``weights[k] / sum_j weights[j]`` per pixel and channel
    (negative weights count as 0); where that sum is at most ``floor``, the same with
    ``fallback`` (when ``use_fallback``), and where that is too, with the (K, C) ``last``
    (one weight per part and channel for the whole image: ones for equal parts), and where
    those are all 0, no parts (0: the caller gives the total to someone else). ``out`` may
    be ``weights``: a value's weights are all read before its parts are written."""
    count, channels, height, width = weights.shape
    for job in prange(channels * height):
        c, y = job // height, job % height
        rest = 0.0
        for k in range(count):
            rest += max(last[k, c], 0.0)
        for x in range(width):
            s = _positive_sum(weights, c, y, x)
            source = 0
            if s <= floor and use_fallback:
                s = _positive_sum(fallback, c, y, x)
                source = 1
            t = total[c, y, x]
            if s <= floor:
                for k in range(count):
                    out[k, c, y, x] = t * (max(last[k, c], 0.0) / rest) if rest > 0.0 else 0.0
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


@njit(**_JIT)
def touching(mask: np.ndarray, out: np.ndarray) -> None:
    """``out`` (H, W) bool: whether one of the pixel's 4 neighbours (up, down, left, right;
    inside the image) is in ``mask`` (H, W) bool."""
    height, width = mask.shape
    for y in prange(height):
        for x in range(width):
            out[y, x] = ((y > 0 and mask[y - 1, x]) or (y + 1 < height and mask[y + 1, x])
                         or (x > 0 and mask[y, x - 1]) or (x + 1 < width and mask[y, x + 1]))


@njit(**_JIT)
def fill_from_neighbours(stored: np.ndarray, colour: np.ndarray, source: np.ndarray,
                         target: np.ndarray) -> int:
    """In place, on each ``target`` pixel (H, W) bool with a ``source`` pixel among its 4
    neighbours: ``stored`` (3, H, W) = those neighbours' ``stored x colour`` summed over their
    ``colour`` summed, per channel (0 where that colour sum is 0): a light pass stored
    divided by its colour, one pixel past where its colour ends. Targets must not be
    sources (a target's value is read by none). Returns how many pixels were filled."""
    _, height, width = stored.shape
    filled = np.zeros(height, np.int64)
    for y in prange(height):
        for x in range(width):
            if not target[y, x]:
                continue
            found = False
            for c in range(3):
                light = 0.0
                weight = 0.0
                for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                    yy, xx = y + dy, x + dx
                    if 0 <= yy < height and 0 <= xx < width and source[yy, xx]:
                        found = True
                        light += stored[c, yy, xx] * colour[c, yy, xx]
                        weight += colour[c, yy, xx]
                if found:
                    stored[c, y, x] = light / weight if weight > 0.0 else 0.0
            if found:
                filled[y] += 1
    return int(filled.sum())
