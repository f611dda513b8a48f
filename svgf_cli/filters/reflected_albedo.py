"""Reflected albedo: a mirror's glossy light demodulated by the texture it reflects.

A glossy signal is demodulated by its own colour (Cycles' ``GlossCol``), which on a polished
metal is flat: the reflected scene's texture stays in the illumination the filter sees, where
the glossy luminance stop keeps it as detail and with it the one-sample noise around it.
Cycles' ``Denoising Albedo`` follows near-specular bounces: on such a pixel it is the gloss
colour times the albedo of the surface seen in the mirror. Divided by it, the glossy light is
the reflected surface's irradiance, smooth, and the texture returns at remodulation; this is
what a denoiser guided by that albedo (OIDN) sees.

It holds only where the reflection is sharp. On a rough metal the albedo AOV follows one
random specular direction per sample, so it is the albedo of a different reflected point at
every pixel and every frame, and the ratio of light to it is noise. This module tells the two
apart per object from the albedo itself:

* **candidates** (:func:`reflected_candidates`): surface pixels with no diffuse colour, a
  gloss colour, and an albedo AOV above 0 and at most the gloss colour (``<= 1.05 c + 1e-4``
  per channel: a reflectance seen through the mirror; a reflected light's emission is not
  one and is handled as radiance by ``modulate.emitter_colour``);
* **agreement** (:func:`albedo_agreement`): the share of a pixel's 8 neighbours whose
  albedo luminance lies within a factor ``AGREE`` of its own. A sharp reflection is patches
  of one colour (1 inside a patch, 5/8 along a straight edge); one sample of a blurry
  reflection is a random albedo per pixel;
* **weight** (:func:`object_weights`): per object (mesh id), the mean agreement of its
  candidates mapped linearly from 0 at ``RAMP[0]`` to 1 at ``RAMP[1]``, the same for all its
  candidates, so that no seam in the demodulation runs through a surface and the weight of
  a mirror changes smoothly with the frame;
* **colour** (:func:`reflected_colour`): on candidates ``c^(1 - w) a'^w`` with
  ``a' = max(albedo, FLOOR c)`` per channel (a geometric mix of the gloss colour ``c`` and
  the floored albedo), elsewhere ``c``. The signal is demodulated and remodulated by it.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from svgf_cli.filters.context import MAX_REFLECTANCE
from svgf_cli.filters.fastmath import FASTMATH
from svgf_cli.filters.values import is_nonfinite

F32 = np.float32
_ZERO = F32(0.0)
_JIT = dict(fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy")
# The reflected albedo is floored at this share of the gloss colour: a reflected dark
# texel (albedo 0.005 on the metal fixture) would otherwise divide that pixel's own glossy
# highlight by 1/200 and remodulate a hot pixel.
FLOOR = 0.25
# Two neighbours agree when their albedo luminances differ by less than this factor.
AGREE = 1.25
# Mean agreement of an object's candidates: weight 0 at or below the first, 1 at or above
# the second. Measured on the Cycles renders (testdata/cycles/render.py): the mirror ball
# 0.82 at 128x72, 0.91 at 384x216, 0.94 at 960x540, 0.955 at 1920x1080; the rough gold bust
# (roughness 0.25) 0.50 at 128x72 and 4 samples, 0.61 at 128x72, 0.685 at 384x216, 0.71 at
# 960x540, 0.73 at 1920x1080 (it grows with the image: the ramp starts above it); the
# production shot's glass 0.31, its wires 0.56.
RAMP = (0.78, 0.88)


def reflected_candidates(
    gloss_colour: np.ndarray, albedo: np.ndarray, diffuse_colour: np.ndarray, depth: np.ndarray
) -> np.ndarray:
    """(H, W) bool: surface pixels (``depth > 0``) whose ``diffuse_colour`` (H, W: the
    brightest channel of the non-glossy signals' colours) is below 1e-3, whose
    ``gloss_colour`` (3, H, W) has a channel above 0, and whose ``albedo`` (3, H, W: the
    G-buffer albedo) is a reflectance (a channel above 0, none above ``MAX_REFLECTANCE``)
    with every channel at most ``1.05 c + 1e-4``. Non-finite albedo is no candidate. (A
    reflected light's emission, which ``stages.reflected_lights`` has put in the gloss
    colour, is no reflectance: it must not count in its object's agreement.)"""
    out = np.empty(depth.shape, dtype=np.bool_)
    _candidate_rows(gloss_colour, albedo, diffuse_colour, depth, out)
    return out


@njit(parallel=True, **_JIT)
def _candidate_rows(gloss: np.ndarray, albedo: np.ndarray, diffuse: np.ndarray,
                    depth: np.ndarray, out: np.ndarray) -> None:
    """:func:`reflected_candidates` row by row (one pass instead of numpy's six frame-sized
    temporaries: 16 ms a 1080p frame)."""
    height, width = depth.shape
    slack, bound, floor = F32(1.05), F32(1e-4), F32(1e-3)
    limit = F32(MAX_REFLECTANCE)
    for y in prange(height):
        row = out[y]
        for x in range(width):
            ok = depth[y, x] > _ZERO and diffuse[y, x] < floor
            brightest = _ZERO
            glossiest = _ZERO
            for c in range(3):
                a = albedo[c, y, x]
                g = gloss[c, y, x]
                ok = ok and not is_nonfinite(a) and a <= g * slack + bound
                brightest = max(brightest, a)
                glossiest = max(glossiest, g)
            row[x] = ok and brightest > _ZERO and brightest <= limit and glossiest > _ZERO


def floored_albedo(gloss_colour: np.ndarray, albedo: np.ndarray) -> np.ndarray:
    """``a' = max(albedo, FLOOR gloss_colour)`` per channel, non-finite albedo as 0."""
    clean = np.where(np.isfinite(albedo), albedo, F32(0.0))
    return np.maximum(clean, gloss_colour * F32(FLOOR)).astype(F32, copy=False)


def albedo_agreement(floored: np.ndarray) -> np.ndarray:
    """(H, W) float32: per pixel the share of its 8 neighbours whose mean-channel luminance
    of ``floored`` (3, H, W) is within a factor ``AGREE`` of its own (outside the image: the
    edge pixel repeated)."""
    level = np.log(np.maximum(floored.mean(axis=0, dtype=F32), F32(1e-4)))
    height, width = level.shape
    padded = np.pad(level, 1, mode="edge")
    limit = F32(np.log(AGREE))
    agree = np.zeros((height, width), dtype=F32)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dy or dx:
                shifted = padded[1 + dy:1 + dy + height, 1 + dx:1 + dx + width]
                agree += (np.abs(shifted - level) < limit).astype(F32)
    return agree / F32(8.0)


def object_weights(agreement: np.ndarray, candidates: np.ndarray, mesh_id: np.ndarray
                   ) -> np.ndarray:
    """(H, W) float32: on each candidate the weight of its object (``mesh_id``): the mean
    of the object's candidates' ``agreement`` (float64 sum) mapped linearly from 0 at
    ``RAMP[0]`` to 1 at ``RAMP[1]``; 0 elsewhere."""
    weights = np.zeros(agreement.shape, dtype=F32)
    ids = mesh_id[candidates]
    if not ids.size:
        return weights
    values = agreement[candidates]
    order = np.argsort(ids, kind="stable")
    ids, values = ids[order], values[order]
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    low, high = RAMP
    for start, end in zip(starts, [*starts[1:], ids.size], strict=True):
        mean = float(values[start:end].sum(dtype=np.float64)) / (end - start)
        weight = min(max((mean - low) / (high - low), 0.0), 1.0)
        if weight > 0.0:
            weights[candidates & (mesh_id == ids[start])] = F32(weight)
    return weights


def reflected_colour(gloss_colour: np.ndarray, floored: np.ndarray, weights: np.ndarray
                     ) -> np.ndarray:
    """(3, H, W) float32: ``gloss_colour^(1 - w) floored^w`` per channel where the weight
    is above 0 (``floored`` itself where it is 1), ``gloss_colour`` elsewhere."""
    w = weights[None]
    mixed = np.exp(w * np.log(np.maximum(floored, F32(1e-6)))
                   + (F32(1.0) - w) * np.log(np.maximum(gloss_colour, F32(1e-6))))
    out = np.where(w >= F32(1.0), floored, np.where(w > 0, mixed, gloss_colour))
    return np.ascontiguousarray(out, dtype=F32)


def reflected_albedo(gloss_colour: np.ndarray, albedo: np.ndarray, diffuse_colour: np.ndarray,
                     depth: np.ndarray, mesh_id: np.ndarray) -> tuple[np.ndarray, int] | None:
    """A glossy signal's demodulation colour with sharp reflections demodulated by the
    albedo they reflect (module docstring), and how many pixels changed; None where no
    pixel is a candidate or no object's weight is above 0. The agreement is computed on
    the candidates' bounding box only (grown by a pixel), so a frame pays for its mirrors'
    area."""
    candidates = reflected_candidates(gloss_colour, albedo, diffuse_colour, depth)
    if not candidates.any():
        return None
    rows, columns = np.nonzero(candidates)
    height, width = depth.shape
    box = (slice(max(int(rows.min()) - 1, 0), min(int(rows.max()) + 2, height)),
           slice(max(int(columns.min()) - 1, 0), min(int(columns.max()) + 2, width)))
    crop = (slice(None), *box)
    floored = floored_albedo(gloss_colour[crop], albedo[crop])
    weights = object_weights(albedo_agreement(floored), candidates[box], mesh_id[box])
    changed = int(np.count_nonzero(weights))
    if not changed:
        return None
    out = np.array(gloss_colour, dtype=F32, copy=True)
    out[crop] = reflected_colour(gloss_colour[crop], floored, weights)
    return out, changed
