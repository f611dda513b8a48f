"""Temporal anti-aliasing of the output at object outlines (the paper's last step).

A renderer that jitters its one sample per pixel over the pixel filter (Cycles with a sample
offset, docs/cycles.md; any renderer that does not trace its first sample through the pixel
centre) puts an outline pixel's sample on the object in some
frames and on what lies behind it in others, while its reference is the two surfaces' mix
weighted by their coverage. The reprojection keeps the surfaces' histories apart (its depth
and normal tests are per sample), so SVGF's output there follows the surface of the moment:
noise no spatial or temporal stage of SVGF removes. TAA blends the output with its own past
where no surface test applies, bounded by what the current frame shows around the pixel:

* only on surface pixels near an outline: a surface pixel of the 3x3 around the pixel has a
  background neighbour or one whose depth differs by more than ``DEPTH_JUMP`` (5 %); a
  jittered sample lands up to 0.75 px from its pixel's centre, so the surfaces that mix in a
  pixel show within these two pixels. Inside a surface SVGF's history already holds the
  pixel's samples, and blending there would only add the resampling's blur;
* the previous TAA output is fetched at the backprojected position ``(x + motion.x,
  y + motion.y)`` with the Catmull-Rom spline over the 4x4 taps (indices clamped to the
  image; ``filters.resample``): bilinear fetching blurs the output a little more each frame;
  negative results become 0. A position outside ``[-0.5, size - 0.5]`` keeps the current
  value;
* colours are compared in the tonemapped space ``T(c) = c / (1 + l(c))`` (``l`` the frame's
  luminance; ``T`` maps luminance into [0, 1) and back exactly, ``c = T / (1 - l(T))``), so
  that a light or a firefly in the neighbourhood cannot widen the bound without limit;
* the fetched history is clipped per channel to ``mu +- CLIP_SIGMA sigma`` of the current
  output's 3x3 (in-image pixels) in that space (variance clipping, Salvi 2016), widened to
  hold the pixel's own current value (a thin line brighter than its neighbourhood keeps a
  history that matches it): the mix of two surfaces lies inside it, a surface that moved
  away or a light that changed does not;
* the blend is ``alpha current + (1 - alpha) history``. Not Karis' luminance weights
  (``alpha / (1 + l)``), which keep a frame's firefly from lasting: the output's fireflies
  are the despike's, and those weights pull the mix of a pixel flipping between a bright
  and a dark surface toward the dark one (``testdata/seq_jit``, seven noise realisations,
  frames 5-10: video JOD 8.80 without them, 8.75 with them, 8.64 without TAA).

Measured (docs/algorithm.md): on Blender renders whose one sample is jittered
(``testdata/cycles/render.py --sample-offset 1``; four noise realisations of ``roll`` and
``metal`` at 256x144, frames 4-10) relMSE 0.0468 and 0.0451 against 0.0673 and 0.0683
without TAA; on Blender's default renders (pixel centres, filtered references) 0.91x and
0.99x; against references of pixel centres (``svgf trace``'s) a loss of up to 15 %, hence
off by default.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from svgf_cli.filters.fastmath import FASTMATH
from svgf_cli.filters.resample import catmull_rom_weights

F32 = np.float32
_ZERO = F32(0.0)
_HALF = F32(0.5)
_ONE = F32(1.0)
# Depths further apart than this ratio are two surfaces (an outline).
DEPTH_JUMP = F32(1.05)
# Half-width of the history's clip box in standard deviations of the current 3x3 (0.75
# before 2026-11-28: 0.5 lowers relMSE on every jittered sequence measured and loses less
# video JOD where glossy reflections move over the outlines: docs/stability.md
# #jittered-outlines).
CLIP_SIGMA = F32(0.5)
# Keeps the inverse tonemap finite where a clipped colour reaches luminance 1.
_MAX_TONEMAPPED = F32(0.999)
_JIT = dict(fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy")


@njit(**_JIT)
def _jump(depth: np.ndarray, y: int, x: int) -> bool:
    """Whether surface pixel ``(y, x)`` has a background neighbour or one whose depth is
    more than ``DEPTH_JUMP`` times nearer or farther (8 neighbours, in the image)."""
    height, width = depth.shape
    z = depth[y, x]
    for yy in range(max(y - 1, 0), min(y + 2, height)):
        for xx in range(max(x - 1, 0), min(x + 2, width)):
            other = depth[yy, xx]
            if other <= _ZERO or other > DEPTH_JUMP * z or z > DEPTH_JUMP * other:
                return True
    return False


@njit(**_JIT)
def on_outline(depth: np.ndarray, y: int, x: int) -> bool:
    """Whether a surface pixel of the 3x3 around ``(y, x)`` borders another surface or the
    background (:func:`_jump`): the pixels a jittered sample can carry across an outline,
    on both sides of it. A depth that only slopes (a floor seen at a grazing angle) is no
    outline. (:func:`taa_resolve` computes the same from a plane of :func:`_jump`.)"""
    height, width = depth.shape
    for yy in range(max(y - 1, 0), min(y + 2, height)):
        for xx in range(max(x - 1, 0), min(x + 2, width)):
            if depth[yy, xx] > _ZERO and _jump(depth, yy, xx):
                return True
    return False


@njit(**_JIT)
def _near_jump(jumps: np.ndarray, y: int, x: int) -> bool:
    """Whether ``jumps`` (H, W) is set anywhere in the 3x3 around ``(y, x)``."""
    height, width = jumps.shape
    for yy in range(max(y - 1, 0), min(y + 2, height)):
        for xx in range(max(x - 1, 0), min(x + 2, width)):
            if jumps[yy, xx]:
                return True
    return False


@njit(**_JIT)
def _history(previous: np.ndarray, px: np.float32, py: np.float32, out: np.ndarray) -> None:
    """``out`` (3,): the Catmull-Rom fetch of ``previous`` (3, H, W) at ``(px, py)``,
    indices clamped to the image, negative results 0."""
    height, width = previous.shape[1], previous.shape[2]
    x0 = np.floor(px)
    y0 = np.floor(py)
    wx = catmull_rom_weights(px - x0)
    wy = catmull_rom_weights(py - y0)
    for c in range(3):
        out[c] = _ZERO
    for j in range(4):
        yy = min(max(int(y0) + j - 1, 0), height - 1)
        for i in range(4):
            xx = min(max(int(x0) + i - 1, 0), width - 1)
            w = wy[j] * wx[i]
            for c in range(3):
                out[c] += w * previous[c, yy, xx]
    for c in range(3):
        out[c] = max(out[c], _ZERO)


@njit(**_JIT)
def _tonemapped(r: np.float32, g: np.float32, b: np.float32,
                weights: np.ndarray) -> np.float32:
    """``1 / (1 + l(c))``: the factor that takes ``c`` to ``T(c)``."""
    return _ONE / (_ONE + max(weights[0] * r + weights[1] * g + weights[2] * b, _ZERO))


@njit(**_JIT)
def _clip(t: np.float32, mean: np.float32, mean_square: np.float32,
          centre: np.float32) -> np.float32:
    """``t`` clipped to ``mean +- CLIP_SIGMA sigma`` widened to hold ``centre``."""
    sigma = np.sqrt(max(mean_square - mean * mean, _ZERO))
    low = min(mean - CLIP_SIGMA * sigma, centre)
    high = max(mean + CLIP_SIGMA * sigma, centre)
    return min(max(t, low), high)


@njit(**_JIT)
def _clip_to_neighbourhood(current: np.ndarray, y: int, x: int, weights: np.ndarray,
                           history: np.ndarray) -> None:
    """In place: ``history`` (3,) clipped per channel to ``mu +- CLIP_SIGMA sigma`` of the
    tonemapped current 3x3 around ``(y, x)``, and taken back to linear."""
    height, width = current.shape[1], current.shape[2]
    sum_r = sum_g = sum_b = _ZERO
    square_r = square_g = square_b = _ZERO
    count = _ZERO
    for yy in range(max(y - 1, 0), min(y + 2, height)):
        for xx in range(max(x - 1, 0), min(x + 2, width)):
            r, g, b = current[0, yy, xx], current[1, yy, xx], current[2, yy, xx]
            scale = _tonemapped(r, g, b, weights)
            r, g, b = r * scale, g * scale, b * scale
            sum_r += r
            sum_g += g
            sum_b += b
            square_r += r * r
            square_g += g * g
            square_b += b * b
            count += _ONE
    centre = _tonemapped(current[0, y, x], current[1, y, x], current[2, y, x], weights)
    scale = _tonemapped(history[0], history[1], history[2], weights)
    history[0] = _clip(history[0] * scale, sum_r / count, square_r / count,
                       current[0, y, x] * centre)
    history[1] = _clip(history[1] * scale, sum_g / count, square_g / count,
                       current[1, y, x] * centre)
    history[2] = _clip(history[2] * scale, sum_b / count, square_b / count,
                       current[2, y, x] * centre)
    luma = weights[0] * history[0] + weights[1] * history[1] + weights[2] * history[2]
    inverse = _ONE / (_ONE - min(max(luma, _ZERO), _MAX_TONEMAPPED))
    for c in range(3):
        history[c] = max(history[c], _ZERO) * inverse


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def taa_resolve(
    current: np.ndarray,
    previous: np.ndarray,
    motion: np.ndarray,
    depth: np.ndarray,
    weights: np.ndarray,
    alpha: np.float32,
    out: np.ndarray,
) -> None:
    """Blend ``current`` (3, H, W) with the reprojected, clipped ``previous`` at outlines.

    Per surface pixel near an outline (:func:`on_outline`): ``h`` the Catmull-Rom fetch of
    ``previous`` at ``(x + motion.x, y + motion.y)`` clipped to ``mu +- 0.5 sigma`` of the
    tonemapped current 3x3, then ``out = alpha c + (1 - alpha) h`` (module docstring).
    Elsewhere, and where the position falls outside the image, ``out = current``.
    ``weights`` (3,) float32 is the frame's luminance (the tonemap's).
    """
    height, width = current.shape[1], current.shape[2]
    # Which surface pixels border another surface or the background, once per pixel (the
    # outline test of a pixel reads its 3x3 of these).
    jumps = np.empty((height, width), dtype=np.bool_)
    for y in prange(height):
        for x in range(width):
            jumps[y, x] = depth[y, x] > _ZERO and _jump(depth, y, x)
    low_x, low_y = F32(-0.5), F32(-0.5)
    high_x, high_y = F32(width) - _HALF, F32(height) - _HALF
    for y in prange(height):
        history = np.empty(3, dtype=F32)
        for x in range(width):
            for c in range(3):
                out[c, y, x] = current[c, y, x]
            if depth[y, x] <= _ZERO or not _near_jump(jumps, y, x):
                continue
            px = F32(x) + motion[0, y, x]
            py = F32(y) + motion[1, y, x]
            if not (px >= low_x and py >= low_y and px <= high_x and py <= high_y):
                continue
            _history(previous, px, py, history)
            _clip_to_neighbourhood(current, y, x, weights, history)
            for c in range(3):
                out[c, y, x] = alpha * current[c, y, x] + (_ONE - alpha) * history[c]
