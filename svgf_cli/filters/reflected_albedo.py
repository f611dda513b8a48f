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

The objects found sharp (weight above 0) are handed on (:class:`SharpObjects`): on them a
reflected light's pair of pixels is a piece of a light's image, elsewhere a rough
reflection's scattered hits (``modulate.emitter_colour``). The objects found rough (mean
agreement below ``ROUGH_AGREEMENT``) are handed on too: their heavy-tailed glossy light
keeps the history clamp's 3x3 (``filters.clamp.heavy_tailed``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

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
# production shot's glass (through the specular signal's TransCol) 0.81 at 384x216, 0.84 at
# 640x360, 0.865 at 1920x1080; demodulating the glass cost 0.014 JOD at 640x360, so the ramp
# starts at its agreement there (the mirror ball at 128x72 falls below it).
RAMP = (0.84, 0.92)
# An object whose candidates' mean agreement is below this (over at least
# ROUGH_MIN_CANDIDATES of them) has rough reflections: the rough gold bust of the Cycles
# renders 0.50-0.73 at every size, the glass 0.81-0.865, the mirror ball 0.82-0.955
# (above). Its glossy history keeps the 3x3 clamp (filters.clamp.heavy_tailed).
ROUGH_AGREEMENT = 0.75
ROUGH_MIN_CANDIDATES = 50


@dataclass(frozen=True)
class SharpObjects:
    """A set of objects by id, ``table[id - low_id] > 0`` (uint8; ids outside the table are
    not in it): those whose reflections are sharp, or (:func:`reflect`) rough."""

    low_id: int
    table: np.ndarray

    def holds(self, ids: np.ndarray) -> np.ndarray:
        """Bool per id (any shape): whether that object is in the set."""
        k = np.asarray(ids, dtype=np.int64) - self.low_id
        inside = (k >= 0) & (k < self.table.size)
        return inside & (self.table[np.where(inside, k, 0)] > 0) if self.table.size else inside


def _sharp_table(ids: np.ndarray) -> SharpObjects:
    """:class:`SharpObjects` of these object ids (sorted, at least one). Ids spanning
    ``_DENSE_IDS`` or more (hashes) get an empty table: no object counts as sharp, the
    rule for rough reflections applies everywhere."""
    low, high = int(ids[0]), int(ids[-1])
    if high - low >= _DENSE_IDS:
        return SharpObjects(0, np.zeros(0, dtype=np.uint8))
    table = np.zeros(high - low + 1, dtype=np.uint8)
    table[ids.astype(np.int64) - low] = 1
    return SharpObjects(low, table)


def reflected_candidates(gloss_colour: np.ndarray, albedo: np.ndarray,
                         diffuse_colours: Sequence[np.ndarray], depth: np.ndarray
                         ) -> np.ndarray:
    """(H, W) bool: surface pixels (``depth > 0``) where every one of ``diffuse_colours``
    (the non-glossy signals' (3, H, W) colours) is below 1e-3 in every channel, whose
    ``gloss_colour`` (3, H, W) has a channel above 0, and whose ``albedo`` (3, H, W: the
    G-buffer albedo) is a reflectance (a channel above 0, none above ``MAX_REFLECTANCE``)
    with every channel at most ``1.05 c + 1e-4``. Non-finite albedo is no candidate. (A
    reflected light's emission in the albedo AOV is no reflectance: it must not count in its
    object's agreement; ``stages.reflected_lights`` marks those pixels afterwards.)"""
    out = np.empty(depth.shape, dtype=np.bool_)
    darks = tuple(diffuse_colours) or (np.zeros((3, 1, 1), dtype=F32),)
    _candidate_rows(gloss_colour, albedo, darks, bool(diffuse_colours), depth, out)
    return out


@njit(parallel=True, **_JIT)
def _candidate_rows(gloss: np.ndarray, albedo: np.ndarray, darks: tuple, use_darks: bool,
                    depth: np.ndarray, out: np.ndarray) -> None:
    """:func:`reflected_candidates` row by row, in one pass (no frame-sized temporaries:
    fresh pages are slow on these machines, docs/performance.md)."""
    height, width = depth.shape
    slack, bound, floor = F32(1.05), F32(1e-4), F32(1e-3)
    limit = F32(MAX_REFLECTANCE)
    for y in prange(height):
        row = out[y]
        for x in range(width):
            ok = depth[y, x] > _ZERO
            brightest = _ZERO
            glossiest = _ZERO
            for c in range(3):
                a = albedo[c, y, x]
                g = gloss[c, y, x]
                ok = ok and not is_nonfinite(a) and a <= g * slack + bound
                brightest = max(brightest, a)
                glossiest = max(glossiest, g)
            ok = ok and brightest > _ZERO and brightest <= limit and glossiest > _ZERO
            # The diffuse colours last: most pixels fail above, and three colours are
            # most of the memory this pass would read.
            if ok and use_darks:
                for dark in darks:
                    ok = ok and max(dark[0, y, x], max(dark[1, y, x], dark[2, y, x])) < floor
            row[x] = ok


def floored_albedo(gloss_colour: np.ndarray, albedo: np.ndarray) -> np.ndarray:
    """``a' = max(albedo, FLOOR gloss_colour)`` per channel, non-finite albedo as 0."""
    clean = np.where(np.isfinite(albedo), albedo, F32(0.0))
    return np.maximum(clean, gloss_colour * F32(FLOOR)).astype(F32, copy=False)


def albedo_agreement(gloss_colour: np.ndarray, albedo: np.ndarray, candidates: np.ndarray
                     ) -> np.ndarray:
    """(H, W) float32: on each candidate the share of its 8 neighbours whose level is
    within a factor ``AGREE`` of its own (the larger below ``AGREE`` times the smaller;
    outside the image: the edge pixel repeated), 0 elsewhere. A pixel's level is the mean
    over the channels of the floored albedo (:func:`floored_albedo`), at least 1e-4."""
    out = np.empty(candidates.shape, dtype=F32)
    _agreement_rows(gloss_colour, albedo, candidates, out)
    return out


@njit(inline="always", **_JIT)
def _floored(a: np.float32, g: np.float32) -> np.float32:
    """One channel of :func:`floored_albedo`."""
    return max(_ZERO if is_nonfinite(a) else a, g * F32(FLOOR))


@njit(inline="always", **_JIT)
def _level(gloss: np.ndarray, albedo: np.ndarray, y: int, x: int) -> np.float32:
    total = _ZERO
    for c in range(3):
        total += _floored(albedo[c, y, x], gloss[c, y, x])
    return max(total / F32(3.0), F32(1e-4))


@njit(parallel=True, **_JIT)
def _agreement_rows(gloss: np.ndarray, albedo: np.ndarray, candidates: np.ndarray,
                    out: np.ndarray) -> None:
    """:func:`albedo_agreement` row by row, on the candidates only (a frame pays for its
    mirrors' area, not for its size)."""
    height, width = candidates.shape
    for y in prange(height):
        row = out[y]
        for x in range(width):
            if not candidates[y, x]:
                row[x] = _ZERO
                continue
            row[x] = _agreement(gloss, albedo, y, x)


@njit(inline="always", **_JIT)
def _agreement(gloss: np.ndarray, albedo: np.ndarray, y: int, x: int) -> np.float32:
    """One pixel's share of its 8 neighbours (clamped at the edges) within ``AGREE``."""
    height, width = albedo.shape[1], albedo.shape[2]
    factor = F32(AGREE)
    own = _level(gloss, albedo, y, x)
    count = 0
    for dy in range(-1, 2):
        qy = min(max(y + dy, 0), height - 1)
        for dx in range(-1, 2):
            if dy == 0 and dx == 0:
                continue
            other = _level(gloss, albedo, qy, min(max(x + dx, 0), width - 1))
            count += 1 if max(own, other) < factor * min(own, other) else 0
    return F32(count) / F32(8.0)


def object_weights(agreement: np.ndarray, candidates: np.ndarray, mesh_id: np.ndarray
                   ) -> np.ndarray:
    """(H, W) float32: on each candidate the weight of its object (``mesh_id``): the mean
    of the object's candidates' ``agreement`` (float64 sums) mapped linearly from 0 at
    ``RAMP[0]`` to 1 at ``RAMP[1]``; 0 elsewhere."""
    weights = np.zeros(agreement.shape, dtype=F32)
    ids = mesh_id[candidates]
    if ids.size:
        objects, members = np.unique(ids, return_inverse=True)
        sums = np.bincount(members, weights=agreement[candidates].astype(np.float64))
        weights[candidates] = _ramp(sums / np.bincount(members))[members]
    return weights


def _ramp(means: np.ndarray) -> np.ndarray:
    low, high = RAMP
    return np.clip((means - low) / (high - low), 0.0, 1.0).astype(F32)


# Object ids spanning fewer values than this are summed in a dense table by
# :func:`reflected_albedo`; wider (ids as hashes) go through :func:`object_weights`.
_DENSE_IDS = 1 << 16


@njit(**_JIT)
def _id_range(candidates: np.ndarray, mesh_id: np.ndarray) -> tuple[int, int]:
    """The smallest and largest id among the candidates ((0, -1) when there are none)."""
    low, high = np.int64(1) << 40, -(np.int64(1) << 40)
    height, width = candidates.shape
    for y in range(height):
        for x in range(width):
            if candidates[y, x]:
                low = min(low, np.int64(mesh_id[y, x]))
                high = max(high, np.int64(mesh_id[y, x]))
    return (low, high) if high >= low else (0, -1)


@njit(**_JIT)
def _agreement_sums(gloss: np.ndarray, albedo: np.ndarray, candidates: np.ndarray,
                    mesh_id: np.ndarray, low_id: int, sums: np.ndarray, counts: np.ndarray
                    ) -> None:
    """Per object (index ``id - low_id``): the sum of its candidates' agreement (as
    :func:`albedo_agreement`; float64, in row order) and their count, without a plane of
    agreements."""
    height, width = candidates.shape
    for y in range(height):
        for x in range(width):
            if candidates[y, x]:
                k = np.int64(mesh_id[y, x]) - low_id
                sums[k] += np.float64(_agreement(gloss, albedo, y, x))
                counts[k] += 1


@njit(parallel=True, **_JIT)
def _reflected_rows(gloss: np.ndarray, albedo: np.ndarray, candidates: np.ndarray,
                    mesh_id: np.ndarray, low_id: int, per_object: np.ndarray,
                    out: np.ndarray, changed: np.ndarray) -> None:
    """:func:`reflected_colour` with each candidate's object weight, the gloss colour
    elsewhere, row by row into ``out``; ``changed`` (H,) counts the pixels per row."""
    height, width = candidates.shape
    tiny = F32(1e-6)
    for y in prange(height):
        count = 0
        for x in range(width):
            w = per_object[np.int64(mesh_id[y, x]) - low_id] if candidates[y, x] else _ZERO
            count += 1 if w > _ZERO else 0
            for c in range(3):
                g = gloss[c, y, x]
                if w > _ZERO:
                    d = _floored(albedo[c, y, x], g)
                    if w < F32(1.0):
                        d = np.exp(w * np.log(max(d, tiny))
                                   + (F32(1.0) - w) * np.log(max(g, tiny)))
                    out[c, y, x] = d
                else:
                    out[c, y, x] = g
        changed[y] = count


def reflected_colour(gloss_colour: np.ndarray, floored: np.ndarray, weights: np.ndarray
                     ) -> np.ndarray:
    """(3, H, W) float32: ``gloss_colour^(1 - w) floored^w`` per channel where the weight
    is above 0 (``floored`` itself where it is 1), ``gloss_colour`` elsewhere."""
    w = weights[None]
    mixed = np.exp(w * np.log(np.maximum(floored, F32(1e-6)))
                   + (F32(1.0) - w) * np.log(np.maximum(gloss_colour, F32(1e-6))))
    out = np.where(w >= F32(1.0), floored, np.where(w > 0, mixed, gloss_colour))
    return np.ascontiguousarray(out, dtype=F32)


Found = tuple[np.ndarray, int, SharpObjects]


def reflected_albedo(gloss_colour: np.ndarray, albedo: np.ndarray,
                     diffuse_colours: Sequence[np.ndarray], depth: np.ndarray,
                     mesh_id: np.ndarray) -> Found | None:
    """A glossy signal's demodulation colour with sharp reflections demodulated by the
    albedo they reflect (module docstring), how many pixels changed and the objects whose
    weight is above 0; None where no pixel is a candidate or no object's weight is above
    0 (:func:`reflect` with the rough objects too)."""
    return reflect(gloss_colour, albedo, diffuse_colours, depth, mesh_id)[0]


def reflect(gloss_colour: np.ndarray, albedo: np.ndarray,
            diffuse_colours: Sequence[np.ndarray], depth: np.ndarray, mesh_id: np.ndarray
            ) -> tuple[Found | None, SharpObjects | None]:
    """:func:`reflected_albedo`'s result and the objects whose reflections are rough (mean
    agreement below ``ROUGH_AGREEMENT`` over at least ``ROUGH_MIN_CANDIDATES`` candidates;
    None without candidates or with ids as hashes). Without a candidate it costs two
    passes over the frame; the agreement is computed on the candidates alone and no
    frame-sized plane is made but the result."""
    candidates = reflected_candidates(gloss_colour, albedo, diffuse_colours, depth)
    low_id, high_id = _id_range(candidates, mesh_id)
    if high_id < low_id:
        return None, None
    if high_id - low_id >= _DENSE_IDS:  # ids as hashes (the rare case): sort them
        weights = object_weights(albedo_agreement(gloss_colour, albedo, candidates),
                                 candidates, mesh_id)
        rows, columns = np.nonzero(weights)
        if not rows.size:
            return None, None
        out = np.array(gloss_colour, dtype=F32, copy=True)
        gloss = gloss_colour[:, rows, columns]
        out[:, rows, columns] = reflected_colour(
            gloss, floored_albedo(gloss, albedo[:, rows, columns]), weights[rows, columns])
        return (out, int(rows.size), _sharp_table(np.unique(mesh_id[rows, columns]))), None
    sums = np.zeros(high_id - low_id + 1, dtype=np.float64)
    counts = np.zeros(high_id - low_id + 1, dtype=np.int64)
    _agreement_sums(gloss_colour, albedo, candidates, mesh_id, np.int64(low_id), sums, counts)
    means = sums / np.maximum(counts, 1)
    rough = (means < ROUGH_AGREEMENT) & (counts >= ROUGH_MIN_CANDIDATES)
    rough_objects = SharpObjects(low_id, rough.astype(np.uint8))
    per_object = _ramp(means)
    if not (per_object > 0).any():
        return None, rough_objects
    out = np.empty_like(gloss_colour, dtype=F32)
    changed = np.zeros(depth.shape[0], dtype=np.int64)
    _reflected_rows(gloss_colour, albedo, candidates, mesh_id, np.int64(low_id), per_object,
                    out, changed)
    sharp = SharpObjects(low_id, (per_object > 0).astype(np.uint8))
    return (out, int(changed.sum()), sharp), rough_objects
