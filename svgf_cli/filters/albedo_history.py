"""Temporal demodulation colour: remodulate with the colour's running mean over frames.

A renderer that jitters its camera samples over the pixel filter (Cycles only from its
second sample on, with a sample offset: its first goes through the pixel centre,
docs/cycles.md) writes, per pixel, the colour of one sample of the filter footprint. Where the
footprint straddles a texture edge, that colour is one texture or the other from frame to
frame, while the reference (many samples) is their filtered mean. Demodulation by the
sample's own colour is exact (the illumination of that sample), and temporal accumulation
and the a-trous average the illumination; remodulating by this frame's single colour sample
then puts the edge noise back, and no amount of history removes it. Remodulating by the
colour's own temporal mean does: it converges to the footprint's mean colour. On Cycles'
default 1-spp frames (pixel centres) against its filtered references it pays for another
reason: the 3x3 mean of a pixel without history and the resampling under motion average
some of the footprint the centre sample missed (``bench/bias_variance.py`` on ``roll`` at
256x144, four noise realisations, frames 4-10, no a-trous: bias^2 0.0136 with the mean,
0.027 without).

:func:`accumulate_albedo` keeps, per signal, a running mean of the demodulation colour:

* resampled at the backprojected position ``(x + motion.x, y + motion.y)`` from the 2x2
  bilinear taps that are in the image, not background and of the same mesh id (weights
  renormalised; rejected below a sum of 0.01), with the history length resampled likewise;
* clamped per channel to the current frame's 3x3 range ``[min, max]`` over foreground pixels
  (the footprint's mean lies within the samples around it; a texture that changed, or a
  surface disoccluded on the same mesh, is pulled to the current colours);
* blended: ``h = min(cap, h_prev + 1)``, ``a = lerp(a_hist, a, max(alpha, 1/h))``
  (paper equation 6 applied to the colour);
* without history (the first frame, a disocclusion) ``h = 1`` and the colour's mean over the
  3x3 pixels of the same mesh id weighted by a Gaussian of sigma 0.5 px (1, ``e^-2``,
  ``e^-4``: the width-2 Gaussian pixel filter of Arnold, RenderMan and Karma), the best
  estimate of the footprint's mean a single frame has;
* only over colours that are reflectances (demodulated: ``modulate.effective_albedo``):
  a pixel whose colour is not one is remodulated by 1 whatever it is, so it keeps its
  colour and restarts; history taps, the 3x3 range and the first frame's mean leave such
  colours out, and a mean that is not one is not kept. A G-buffer albedo that follows a
  specular bounce (Cycles' ``Denoising Albedo``) is a reflectance in some samples of a
  pixel and not in others (below ``guide_albedo_floor``): the samples filtered as radiance
  must not darken or lighten the colour the demodulated ones are remodulated by.

A renderer that samples pixel centres (``svgf trace``) writes a noise-free colour; there the
running mean only adds the resampling blur, hence the option (``--temporal-albedo``).
"""

from __future__ import annotations

import numpy as np
from numba import get_num_threads, njit, prange

from svgf_cli.filters.bidirectional import effective_count_at
from svgf_cli.filters.fastmath import FASTMATH
from svgf_cli.filters.modulate import clean_albedo, effective_albedo
from svgf_cli.filters.reproject import MIN_BILINEAR_WEIGHT
from svgf_cli.filters.resample import clamped_catmull_rom
from svgf_cli.filters.rows import balanced_row, balanced_row_count

F32 = np.float32
U = np.uint64
_ZERO = F32(0.0)
_ONE = F32(1.0)
# The 3x3 range's bound where a pixel is background (finite: fast-math assumes no inf).
_FAR = F32(3e38)
# Weights of a Gaussian of sigma 0.5 px at the edge and corner neighbours.
_EDGE = F32(np.exp(-2.0))
_CORNER = F32(np.exp(-4.0))
_JIT = dict(fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy")


@njit(inline="always", **_JIT)
def _row_range(albedo: np.ndarray, usable: np.ndarray, y: int, lo: np.ndarray,
               hi: np.ndarray, column_lo: np.ndarray, column_hi: np.ndarray) -> None:
    """``lo[c, x]``, ``hi[c, x]``: the (cleaned) colour's 3x3 minimum and maximum over the
    pixels around ``(x, y)`` that are ``usable`` (foreground reflectances:
    :func:`_reflectances`); separable (three rows, then three taps), so every loop runs over
    a row. Where there is none, +-``_FAR``."""
    height, width = usable.shape
    y0, y1 = max(y - 1, 0), min(y + 2, height)
    for c in range(3):
        column_lo[:] = _FAR
        column_hi[:] = -_FAR
        for yy in range(y0, y1):
            row = albedo[c, yy]
            flags = usable[yy]
            for x in range(width):
                v = clean_albedo(row[x])
                inside = flags[x]
                column_lo[x] = min(column_lo[x], v if inside else _FAR)
                column_hi[x] = max(column_hi[x], v if inside else -_FAR)
        out_lo, out_hi = lo[c], hi[c]
        for x in range(width):
            left, right = max(x - 1, 0), min(x + 1, width - 1)
            out_lo[x] = min(column_lo[left], min(column_lo[x], column_lo[right]))
            out_hi[x] = max(column_hi[left], max(column_hi[x], column_hi[right]))


@njit(inline="always", **_JIT)
def _gaussian_mean(albedo: np.ndarray, usable: np.ndarray, mesh_id: np.ndarray, x: int,
                   y: int) -> tuple[np.float32, np.float32, np.float32]:
    """The (cleaned) colour's mean over the 3x3 ``usable`` pixels (foreground reflectances;
    the centre is one) of ``(x, y)``'s mesh id, weighted by a Gaussian of sigma 0.5 px:
    1, ``e^-2`` at the 4 edge neighbours, ``e^-4`` at the corners (the width-2 Gaussian
    pixel filter of Arnold, RenderMan and Karma)."""
    height, width = usable.shape
    mesh = mesh_id[y, x]
    total = _ZERO
    m_r = _ZERO
    m_g = _ZERO
    m_b = _ZERO
    for yy in range(max(y - 1, 0), min(y + 2, height)):
        for xx in range(max(x - 1, 0), min(x + 2, width)):
            if not usable[yy, xx] or mesh_id[yy, xx] != mesh:
                continue
            q_r = clean_albedo(albedo[0, yy, xx])
            q_g = clean_albedo(albedo[1, yy, xx])
            q_b = clean_albedo(albedo[2, yy, xx])
            away = abs(yy - y) + abs(xx - x)
            w = _ONE if away == 0 else (_EDGE if away == 1 else _CORNER)
            total += w
            m_r += w * q_r
            m_g += w * q_g
            m_b += w * q_b
    return m_r / total, m_g / total, m_b / total


@njit(inline="always", **_JIT)
def _catmull_rom_usable(kept: np.ndarray, prev_mesh_id: np.ndarray, mesh: np.int32, x0: int,
                        y0: int, fx: np.float32, fy: np.float32, passed: int) -> bool:
    """Whether the Catmull-Rom support of ``(x0 + fx, y0 + fy)`` (``resample``: one column
    where ``fx`` is 0, one row where ``fy`` is) is all usable history: the bilinear taps
    with weight passed (``passed``, bit ``2 dy + dx``) and every further tap is in the
    image, a kept mean (``kept``) and of the pixel's mesh id. A whole-pixel position is the
    bilinear fetch already."""
    if fx == _ZERO and fy == _ZERO:
        return False
    needed = 1 | (2 if fx > _ZERO else 0) | (4 if fy > _ZERO else 0)
    if fx > _ZERO and fy > _ZERO:
        needed |= 8
    if passed & needed != needed:
        return False
    height, width = kept.shape
    first_i, end_i = (0, 4) if fx > _ZERO else (1, 2)
    first_j, end_j = (0, 4) if fy > _ZERO else (1, 2)
    if (x0 - 1 + first_i < 0 or y0 - 1 + first_j < 0 or x0 - 2 + end_i >= width
            or y0 - 2 + end_j >= height):
        return False
    for j in range(first_j, end_j):
        qy = U(y0 - 1 + j)
        for i in range(first_i, end_i):
            qx = U(x0 - 1 + i)
            if not kept[qy, qx] or prev_mesh_id[qy, qx] != mesh:
                return False
    return True


@njit(parallel=True, **_JIT)
def _reflectances(albedo: np.ndarray, depth: np.ndarray, black: np.float32,
                  max_reflectance: np.float32, relative_floor: np.float32,
                  out: np.ndarray) -> None:
    """``out[y, x]``: the pixel is foreground and its (cleaned) colour a reflectance
    (demodulated: ``effective_albedo``)."""
    height, width = depth.shape
    for y in prange(height):
        z = depth[y]
        flags = out[y]
        for x in range(width):
            demodulated, _, _, _ = effective_albedo(
                clean_albedo(albedo[0, y, x]), clean_albedo(albedo[1, y, x]),
                clean_albedo(albedo[2, y, x]), black, max_reflectance, relative_floor)
            flags[x] = z[x] > _ZERO and demodulated


def accumulate_albedo(
    albedo: np.ndarray,
    history: np.ndarray,
    history_length: np.ndarray,
    motion: np.ndarray,
    depth: np.ndarray,
    mesh_id: np.ndarray,
    prev_depth: np.ndarray,
    prev_mesh_id: np.ndarray,
    alpha: np.float32,
    cap: np.float32,
    black: np.float32,
    max_reflectance: np.float32,
    relative_floor: np.float32,
    out: np.ndarray,
    out_length: np.ndarray,
    catmull_rom: bool = False,
) -> None:
    """One colour's running mean (module docstring): ``out = lerp(clamp(a_hist, min3x3,
    max3x3), a, max(alpha, 1/h))``, ``h = min(cap, h_prev + 1)``; without history the
    3x3 Gaussian mean of the colour over its mesh id, ``h = 1``; over reflectances only.

    ``albedo``, ``history`` and ``out`` are (3, H, W); ``history_length`` and ``out_length``
    (H, W) (0 = no history); ``motion`` (2, H, W); ``prev_depth`` / ``prev_mesh_id`` last
    frame's. Background pixels (depth <= 0) keep their colour with length 0.
    ``catmull_rom``: where every tap of the 4x4 Catmull-Rom support passes the taps' tests,
    the history is the clamped spline fetch (``resample.clamped_catmull_rom``) instead of
    the bilinear one; its length stays bilinear.
    """
    usable = np.empty(depth.shape, dtype=np.bool_)
    _reflectances(albedo, depth, black, max_reflectance, relative_floor, usable)
    # Which history means are reflectances (last frame's foreground): once per pixel, not
    # once per tap that reads them.
    kept = np.empty(prev_depth.shape, dtype=np.bool_)
    _reflectances(history, prev_depth, black, max_reflectance, relative_floor, kept)
    _accumulate_rows(albedo, usable, history, kept, history_length, motion, depth, mesh_id,
                     prev_mesh_id, alpha, cap, black, max_reflectance, relative_floor, out,
                     out_length, bool(catmull_rom), np.int64(get_num_threads()))


@njit(parallel=True, **_JIT)
def _accumulate_rows(
    albedo: np.ndarray,
    usable: np.ndarray,
    history: np.ndarray,
    kept: np.ndarray,
    history_length: np.ndarray,
    motion: np.ndarray,
    depth: np.ndarray,
    mesh_id: np.ndarray,
    prev_mesh_id: np.ndarray,
    alpha: np.float32,
    cap: np.float32,
    black: np.float32,
    max_reflectance: np.float32,
    relative_floor: np.float32,
    out: np.ndarray,
    out_length: np.ndarray,
    catmull_rom: bool,
    threads: int,
) -> None:
    """All rows of :func:`accumulate_albedo` (``usable``: :func:`_reflectances` of the
    colour, ``kept`` of the history on last frame's depth)."""
    height, width = depth.shape
    # Rows spread over the threads (``rows``): a sky or background band is nearly free.
    for i in prange(balanced_row_count(height, threads)):
        y = balanced_row(i, height, threads)
        if y >= height:
            continue
        lo = np.empty((3, width), dtype=F32)
        hi = np.empty((3, width), dtype=F32)
        column_lo = np.empty(width, dtype=F32)
        column_hi = np.empty(width, dtype=F32)
        _row_range(albedo, usable, y, lo, hi, column_lo, column_hi)
        # Unsigned indices from here: numba then skips its negative-index wrap-around.
        uy = U(y)
        for x in range(width):
            ux = U(x)
            a_r = clean_albedo(albedo[0, uy, ux])
            a_g = clean_albedo(albedo[1, uy, ux])
            a_b = clean_albedo(albedo[2, uy, ux])
            out[0, uy, ux] = a_r
            out[1, uy, ux] = a_g
            out[2, uy, ux] = a_b
            out_length[uy, ux] = _ZERO
            if depth[uy, ux] <= _ZERO:
                continue
            out_length[uy, ux] = _ONE
            if not usable[uy, ux]:
                continue  # remodulated by 1 whatever the colour: no mean
            px = F32(x) + motion[0, uy, ux]
            py = F32(y) + motion[1, uy, ux]
            if not (abs(px) < F32(1e7) and abs(py) < F32(1e7)):  # NaN or far outside
                px = py = F32(-2.0)  # no tap is in the image
            x0 = int(np.floor(px))
            y0 = int(np.floor(py))
            fx = px - F32(x0)
            fy = py - F32(y0)
            mesh = mesh_id[uy, ux]
            total = _ZERO
            h_r = _ZERO
            h_g = _ZERO
            h_b = _ZERO
            h_len = _ZERO
            passed = 0  # bit 2 dy + dx: the tap passed
            for dy in range(2):
                ty = y0 + dy
                wy = fy if dy == 1 else _ONE - fy
                for dx in range(2):
                    tx = x0 + dx
                    wx = fx if dx == 1 else _ONE - fx
                    if tx < 0 or ty < 0 or tx >= width or ty >= height:
                        continue
                    # Last frame's foreground, the same mesh, a mean that is a reflectance
                    # (not one of samples that were not demodulated).
                    qy, qx = U(ty), U(tx)
                    if not kept[qy, qx] or prev_mesh_id[qy, qx] != mesh:
                        continue
                    w = wx * wy
                    passed |= 1 << (2 * dy + dx)
                    total += w
                    h_r += w * history[0, qy, qx]
                    h_g += w * history[1, qy, qx]
                    h_b += w * history[2, qy, qx]
                    h_len += w * history_length[qy, qx]
            if total >= MIN_BILINEAR_WEIGHT and h_len > _ZERO:
                inv = _ONE / total
                length = min(cap, h_len * inv + _ONE)
                blend = max(alpha, _ONE / length)
                h_r *= inv
                h_g *= inv
                h_b *= inv
                if catmull_rom and _catmull_rom_usable(kept, prev_mesh_id, mesh, x0, y0, fx,
                                                       fy, passed):
                    h_r, h_g, h_b = clamped_catmull_rom(history, x0, y0, fx, fy)
                m_r = min(max(h_r, lo[0, x]), hi[0, x])
                m_g = min(max(h_g, lo[1, x]), hi[1, x])
                m_b = min(max(h_b, lo[2, x]), hi[2, x])
                m_r += blend * (a_r - m_r)
                m_g += blend * (a_g - m_g)
                m_b += blend * (a_b - m_b)
            else:
                # No history: the footprint's mean from the samples around it.
                length = _ONE
                m_r, m_g, m_b = _gaussian_mean(albedo, usable, mesh_id, x, y)
            mean, _, _, _ = effective_albedo(m_r, m_g, m_b, black, max_reflectance,
                                             relative_floor)
            if not mean:
                continue  # another mode: the remodulation must undo this frame's
            out[0, uy, ux] = m_r
            out[1, uy, ux] = m_g
            out[2, uy, ux] = m_b
            out_length[uy, ux] = length


@njit(parallel=True, **_JIT)
def combine_albedo(
    forward: np.ndarray,
    forward_length: np.ndarray,
    reverse: np.ndarray,
    reverse_length: np.ndarray,
    albedo: np.ndarray,
    counts: np.ndarray,
    black: np.float32,
    max_reflectance: np.float32,
    relative_floor: np.float32,
    out: np.ndarray,
) -> None:
    """A bidirectional run's colour mean of one signal: both passes' running means (each
    over its side's frames and this one) weighted by their effective sample counts,
    ``a = (n_f a_f + n_r a_r) / (n_f + n_r)`` with ``n = counts(h)``
    (``bidirectional.effective_counts``); the reverse mean alone where the forward pass has
    none, or where the combination classifies otherwise than this frame's colour
    (``albedo``). (3, H, W) colours, (H, W) lengths; ``out`` may be ``forward``."""
    height, width = albedo.shape[1], albedo.shape[2]
    for y in prange(height):
        for x in range(width):
            r_r = reverse[0, y, x]
            r_g = reverse[1, y, x]
            r_b = reverse[2, y, x]
            n_f = effective_count_at(counts, forward_length[y, x])
            n_r = effective_count_at(counts, reverse_length[y, x])
            m_r, m_g, m_b = r_r, r_g, r_b
            if n_f > _ZERO and n_r > _ZERO:
                share = n_f / (n_f + n_r)
                m_r += share * (forward[0, y, x] - r_r)
                m_g += share * (forward[1, y, x] - r_g)
                m_b += share * (forward[2, y, x] - r_b)
                now, _, _, _ = effective_albedo(
                    clean_albedo(albedo[0, y, x]), clean_albedo(albedo[1, y, x]),
                    clean_albedo(albedo[2, y, x]), black, max_reflectance, relative_floor)
                mean, _, _, _ = effective_albedo(m_r, m_g, m_b, black, max_reflectance,
                                                 relative_floor)
                if now != mean:
                    m_r, m_g, m_b = r_r, r_g, r_b
            out[0, y, x] = m_r
            out[1, y, x] = m_g
            out[2, y, x] = m_b
