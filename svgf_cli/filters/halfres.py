"""A frame at half resolution and back: the light groups' filter on 2x2 blocks.

The light groups' filter only gives each group's share of the colour (``composable``), whose
detail is the colour filter's own; its shares are smooth, so it may run on a quarter of the
pixels: each 2x2 block's light and colour averaged (its samples pooled: four times the
samples per pixel), its G-buffer the block's nearest surface, and the filtered groups
brought back to every pixel from the blocks around it that see the same surface (a joint
bilateral upsampling, Kopf et al. 2007, with the object id and depth as the guide).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numba import njit, prange

from svgf_cli.filters.fastmath import FASTMATH
from svgf_cli.frame import Frame

F32 = np.float32
_JIT = {"fastmath": FASTMATH, "cache": True, "nogil": True, "boundscheck": False,
        "error_model": "numpy"}
# A block whose nearest surface is another object (or farther than this relative depth)
# weighs this little: used only when no block around the pixel sees its surface.
FOREIGN_WEIGHT = 1e-4
DEPTH_TOLERANCE = 0.05


@njit(parallel=True, **_JIT)
def _nearest_in_blocks(depth: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> None:
    """Per 2x2 block (clipped at the border), the row and column of its nearest pixel
    (smallest depth; the first in row-major order on a tie)."""
    height, width = depth.shape
    for by in prange(rows.shape[0]):
        for bx in range(rows.shape[1]):
            best_y, best_x = 2 * by, 2 * bx
            best = depth[best_y, best_x]
            for y in range(2 * by, min(2 * by + 2, height)):
                for x in range(2 * bx, min(2 * bx + 2, width)):
                    if depth[y, x] < best:
                        best, best_y, best_x = depth[y, x], y, x
            rows[by, bx], cols[by, bx] = best_y, best_x


@njit(parallel=True, **_JIT)
def _block_means(planes: np.ndarray, out: np.ndarray) -> None:
    """Each (C, H, W) plane's mean over each 2x2 block (clipped at the border)."""
    channels, height, width = planes.shape
    for c_by in prange(channels * out.shape[1]):
        c, by = c_by // out.shape[1], c_by % out.shape[1]
        for bx in range(out.shape[2]):
            total, count = F32(0.0), 0
            for y in range(2 * by, min(2 * by + 2, height)):
                for x in range(2 * bx, min(2 * bx + 2, width)):
                    total += planes[c, y, x]
                    count += 1
            out[c, by, bx] = total / F32(count)


def block_means(planes: np.ndarray) -> np.ndarray:
    """(C, H, W) -> (C, ceil(H/2), ceil(W/2)): the 2x2 blocks' means."""
    channels, height, width = planes.shape
    out = np.empty((channels, (height + 1) // 2, (width + 1) // 2), dtype=F32)
    _block_means(np.ascontiguousarray(planes, dtype=F32), out)
    return out


def _picked(plane: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(plane[..., rows, cols])


def halve_frame(frame: Frame) -> Frame:
    """``frame`` on 2x2 blocks: light, colours and media averaged, the G-buffer (depth,
    normal, id, motion in half pixels) the block's nearest pixel's, samples per pixel x4."""
    height, width = frame.depth.shape
    rows = np.empty(((height + 1) // 2, (width + 1) // 2), dtype=np.int64)
    cols = np.empty_like(rows)
    _nearest_in_blocks(np.ascontiguousarray(frame.depth, dtype=F32), rows, cols)
    means: dict[int, np.ndarray] = {}

    def mean(plane: np.ndarray) -> np.ndarray:
        if id(plane) not in means:
            means[id(plane)] = block_means(plane)
        return means[id(plane)]

    signals = [dataclasses.replace(s, radiance=mean(s.radiance), albedo=mean(s.albedo),
                                   gradient=None) for s in frame.signals]
    motion = _picked(frame.motion, rows, cols) * F32(0.5)
    return dataclasses.replace(
        frame, signals=signals, depth=_picked(frame.depth, rows, cols),
        normal=_picked(frame.normal, rows, cols), mesh_id=_picked(frame.mesh_id, rows, cols),
        motion=motion, albedo=mean(frame.albedo),
        motion_next=None if frame.motion_next is None
        else _picked(frame.motion_next, rows, cols) * F32(0.5),
        medium=None if frame.medium is None else mean(frame.medium),
        emission=None, samples_per_pixel=4 * frame.samples_per_pixel, centre_sampled=False)


@njit(parallel=True, **_JIT)
def _upsample(values: np.ndarray, small_depth: np.ndarray, small_id: np.ndarray,
              depth: np.ndarray, mesh_id: np.ndarray, out: np.ndarray) -> None:
    count, small_h, small_w = values.shape[0], small_depth.shape[0], small_depth.shape[1]
    height, width = depth.shape
    # Per column: its two block columns and the right one's bilinear weight.
    left = np.empty(width, dtype=np.int64)
    right = np.empty(width, dtype=np.int64)
    right_weight = np.empty(width, dtype=np.float32)
    for x in range(width):
        fx = (x + F32(0.5)) * F32(0.5) - F32(0.5)
        x0 = min(max(int(np.floor(fx)), 0), small_w - 1)
        left[x], right[x] = x0, min(x0 + 1, small_w - 1)
        right_weight[x] = min(max(fx - x0, F32(0.0)), F32(1.0))
    for y in prange(height):
        fy = (y + F32(0.5)) * F32(0.5) - F32(0.5)
        y0 = min(max(int(np.floor(fy)), 0), small_h - 1)
        y1 = min(y0 + 1, small_h - 1)
        wy1 = min(max(fy - y0, F32(0.0)), F32(1.0))
        # The four blocks' weights of every pixel of the row, normalised.
        weights = np.empty((4, width), dtype=np.float32)
        for x in range(width):
            z, own = depth[y, x], mesh_id[y, x]
            tolerance = F32(DEPTH_TOLERANCE) * abs(z)
            total = F32(0.0)
            for corner in range(4):
                sy = y1 if corner >= 2 else y0
                sx = right[x] if corner % 2 == 1 else left[x]
                w = (wy1 if corner >= 2 else F32(1.0) - wy1) * (
                    right_weight[x] if corner % 2 == 1 else F32(1.0) - right_weight[x]
                ) + F32(1e-6)
                if small_id[sy, sx] != own or abs(small_depth[sy, sx] - z) > tolerance:
                    w *= F32(FOREIGN_WEIGHT)
                weights[corner, x] = w
                total += w
            for corner in range(4):
                weights[corner, x] /= total
        for k in range(count):
            for c in range(3):
                top, bottom, row = values[k, c, y0], values[k, c, y1], out[k, c, y]
                for x in range(width):
                    row[x] = (weights[0, x] * top[left[x]] + weights[1, x] * top[right[x]]
                              + weights[2, x] * bottom[left[x]]
                              + weights[3, x] * bottom[right[x]])


def upsample(values: np.ndarray, small: Frame, full: Frame) -> np.ndarray:
    """(K, 3, h, w) values of the blocks of ``small`` (:func:`halve_frame` of ``full``) at
    every pixel of ``full``: the 4 nearest blocks bilinearly, each weighted down by
    ``FOREIGN_WEIGHT`` unless its surface is the pixel's (same id, depth within
    ``DEPTH_TOLERANCE``)."""
    height, width = full.depth.shape
    out = np.empty((values.shape[0], 3, height, width), dtype=F32)
    _upsample(np.ascontiguousarray(values, dtype=F32), small.depth, small.mesh_id,
              np.ascontiguousarray(full.depth, dtype=F32), full.mesh_id, out)
    return out

