"""A G-buffer for the pixels whose one sample scattered in a participating medium.

A renderer writes its G-buffer from one sample per pixel at 1 spp: inside fog or smoke
that sample either scatters in the medium (Cycles then writes depth 1e10, normal 0 and
object index 0: "no surface") or reaches the surface behind it. Both are samples of the
same pixel's light, but a filter steered by that G-buffer sees every other pixel as
background: it passes them through unfiltered (salt-and-pepper fog) and rejects their
history. Here each such *medium pixel* (no surface, and medium light in its 3x3
neighbourhood) takes the G-buffer of the nearest surface pixel within ``radius`` (the
surface the medium is in front of, as far as one frame can tell): its surface light (0 on
this sample, the surface's on its neighbours') and its medium light are then filtered with
its neighbours', whose mean is the pixel's expectation. Where no surface is that near
(smoke against the sky) it becomes a *medium surface* of its own: depth
:data:`MEDIUM_DEPTH`, object id :data:`MEDIUM_ID`, normal +Z, so the filter joins medium
pixels with each other and never with a surface. Surface pixels and background without
medium light are unchanged.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from svgf_cli.filters.fastmath import FASTMATH
from svgf_cli.filters.shares import box_mean

F32 = np.float32
NO_FILL = -1  # not a medium pixel: keeps its own G-buffer
MEDIUM_SURFACE = -2  # a medium pixel with no surface within the radius
# The medium surface's depth: far behind any scene a renderer writes (below the readers'
# 1e9 "background" limit) and the same on every such pixel, so the reprojection and edge
# stops join medium pixels with each other and never with a surface.
MEDIUM_DEPTH = F32(1e8)
MEDIUM_ID = np.int32(-2)


@njit(parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False)
def fill_sources(depth: np.ndarray, medium: np.ndarray, radius: int, out: np.ndarray) -> int:
    """Per pixel of ``out`` (H, W) int32: the flat index of the surface pixel whose G-buffer
    it takes (the nearest in Euclidean distance within the (2 radius + 1)^2 window, ties to
    the smaller depth), :data:`MEDIUM_SURFACE` for a medium pixel with none, or
    :data:`NO_FILL`. A medium pixel has depth <= 0 and medium light (``medium`` (3, H, W),
    any channel > 0) on itself or a 3x3 neighbour. Returns the medium pixels' count."""
    height, width = depth.shape
    counts = np.zeros(height, np.int64)
    for y in prange(height):
        for x in range(width):
            out[y, x] = NO_FILL
            if depth[y, x] > 0.0:
                continue
            lit = False
            for yy in range(max(y - 1, 0), min(y + 2, height)):
                for xx in range(max(x - 1, 0), min(x + 2, width)):
                    if medium[0, yy, xx] > 0.0 or medium[1, yy, xx] > 0.0 or \
                            medium[2, yy, xx] > 0.0:
                        lit = True
            if not lit:
                continue
            counts[y] += 1
            best = MEDIUM_SURFACE
            best_distance = radius * radius * 2 + 1
            best_depth = np.inf
            # Ring by ring (Chebyshev distance r), until no pixel of a further ring can be
            # nearer than the best found: the same answer as scanning the whole window.
            for r in range(1, radius + 1):
                if r * r > best_distance:
                    break
                for dy in range(-r, r + 1):
                    step = 1 if dy == -r or dy == r else 2 * r
                    for dx in range(-r, r + 1, step):
                        yy, xx = y + dy, x + dx
                        if yy < 0 or yy >= height or xx < 0 or xx >= width:
                            continue
                        z = depth[yy, xx]
                        if z <= 0.0:
                            continue
                        distance = dy * dy + dx * dx
                        if distance < best_distance or (distance == best_distance
                                                        and z < best_depth):
                            best, best_distance, best_depth = yy * width + xx, distance, z
            out[y, x] = best
    return int(counts.sum())


def filled(plane: np.ndarray, sources: np.ndarray, medium_value: float | None = None
           ) -> np.ndarray:
    """A copy of ``plane`` ((H, W) or (C, H, W)) where each pixel with a source (``sources``
    from :func:`fill_sources`) takes the source pixel's values, and medium-surface pixels
    ``medium_value`` (every channel; None: their own)."""
    out = plane.copy()
    channels = 1 if plane.ndim == 2 else plane.shape[0]
    flat_in = plane.reshape(channels, -1)
    flat_out = out.reshape(channels, -1)
    own = medium_value is None
    _gather(flat_in, sources.reshape(-1), own, flat_out.dtype.type(0 if own else medium_value),
            flat_out)
    return out


@njit(parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False)
def _gather(plane: np.ndarray, sources: np.ndarray, own: bool, medium_value: float,
            out: np.ndarray) -> None:
    """``out[c, i] = plane[c, sources[i]]`` where ``sources[i] >= 0``; ``medium_value``
    where it is MEDIUM_SURFACE, unless ``own``."""
    channels, size = plane.shape
    rows = (size + 4095) // 4096
    for block in prange(rows):
        for i in range(block * 4096, min(size, (block + 1) * 4096)):
            source = sources[i]
            if source >= 0:
                for c in range(channels):
                    out[c, i] = plane[c, source]
            elif source == MEDIUM_SURFACE and not own:
                for c in range(channels):
                    out[c, i] = medium_value


def coverage(pixels: np.ndarray, radius: int) -> np.ndarray:
    """``c(p)``, (H, W) float32: the share of the (2 radius + 1)^2 pixels around ``p``
    (clipped at the borders) that are medium pixels (``pixels`` (H, W) bool: their one sample
    scattered in the medium), an estimate of the probability that a sample of ``p``
    scatters: the medium's light divided by it is the light of one scattering, which does
    not end where the medium does (``filters.stages.medium_coverage``)."""
    out = np.empty((1, *pixels.shape), np.float32)
    box_mean(np.ascontiguousarray(pixels, dtype=np.float32)[None], int(radius), out)
    return out[0]


# The window of the means a medium pixel's motion is chosen by: 3x3, the smallest that
# measured as well as 5x5 and 7x7 at 384x216 and 640x360 and better at 128x72.
MOTION_CHOICE_RADIUS = 1


def medium_motion(light: np.ndarray, previous: np.ndarray, motion: np.ndarray,
                  pixels: np.ndarray) -> tuple[np.ndarray, int]:
    """The medium pixels' motion (backward, pixels: previous = p + v) chosen between the
    surface behind's (``motion`` (2, H, W), filled by :func:`filled`) and none: for each of
    ``pixels`` (H, W) bool, the one whose nearest pixel in last frame's medium light
    ``previous`` (3, H, W) has the 3x3 mean closest (L1 over the channels) to the 3x3 mean of
    this frame's ``light`` (3, H, W), none on a tie or where the surface's points outside the
    frame. A fog's light moves with the fog, which the surface behind it does not (a camera
    move's parallax); Cycles writes no motion where a sample scattered. A copy of ``motion``
    and how many pixels that had some took none."""
    now = np.empty(light.shape, np.float32)
    box_mean(np.ascontiguousarray(light, dtype=np.float32), MOTION_CHOICE_RADIUS, now)
    before = np.empty(previous.shape, np.float32)
    box_mean(np.ascontiguousarray(previous, dtype=np.float32), MOTION_CHOICE_RADIUS, before)
    out = np.array(motion, dtype=np.float32, order="C")
    still = np.zeros(pixels.shape[0], np.int64)
    _choose_motion(now, before, np.ascontiguousarray(pixels), out, still)
    return out, int(still.sum())


@njit(parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False)
def _choose_motion(now: np.ndarray, before: np.ndarray, pixels: np.ndarray,
                   motion: np.ndarray, still: np.ndarray) -> None:
    """In place on ``motion``: 0 at the ``pixels`` where no motion matches (see
    :func:`medium_motion`); ``still[y]`` counts them per row."""
    _, height, width = now.shape
    for y in prange(height):
        for x in range(width):
            # A medium surface's motion (no surface near) is none already.
            if not pixels[y, x] or (motion[0, y, x] == 0.0 and motion[1, y, x] == 0.0):
                continue
            resting = np.float32(0.0)
            for c in range(3):
                resting += abs(now[c, y, x] - before[c, y, x])
            qx = int(np.floor(np.float32(x) + motion[0, y, x] + np.float32(0.5)))
            qy = int(np.floor(np.float32(y) + motion[1, y, x] + np.float32(0.5)))
            if 0 <= qx < width and 0 <= qy < height:
                moving = np.float32(0.0)
                for c in range(3):
                    moving += abs(now[c, y, x] - before[c, qy, qx])
                if moving < resting:
                    continue
            motion[0, y, x] = 0.0
            motion[1, y, x] = 0.0
            still[y] += 1
