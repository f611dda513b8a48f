"""Anti-lag: shorten the history where the lighting changed (between reprojection and
accumulation).

SVGF rejects history only with geometric tests, so under a moving light, a moving shadow, a
dimmed light or a sliding reflection the stale colour fades only at rate alpha (about
1/alpha frames). This stage tests, per signal, whether the reprojected history still agrees
with the current frame beyond what the noise explains, and where it does not it lowers the
history length, so that the accumulation's blend factor ``max(alpha, 1/h)`` takes more of
the current frame. It needs nothing from the renderer.

Statistics are gathered on cells of 2x2 pixels (a quarter of the work) over a window of
``(2r+1)^2`` cells around each cell, from the pixels that have history (``h > 0``):

* ``m_c``: mean current luminance; ``m_h``: mean of the reprojected first moment ``m1``
  (the temporally accumulated luminance; unlike the colour history it is never spatially
  filtered, so it carries no bias from the a-trous feedback at edges);
* ``var``: per-sample noise variance of the current luminance, the larger of the window's
  Bessel-corrected sample variance and its mean temporal variance ``m2 - m1^2`` (a few
  1-spp samples often miss the outliers that a long history has seen);
* the noise of ``m_h``: a share ``max(1/h_mean, alpha_m / (2 - alpha_m))`` of a sample's
  (short histories are averages of few frames; a long exponential average keeps
  ``alpha_m / (2 - alpha_m)``);
* stale where ``(m_h - m_c)^2 > k^2 (var / n) (1 + share) + (tolerance max(m_c, m_h))^2``:
  more than ``k`` (``sigma``) standard errors of the difference plus a small relative
  tolerance;
* there ``b^2 = (m_h - m_c)^2 - var / n`` (the history's squared bias, unbiased) and
  ``lambda = b^2 / (b^2 + var / N)``, the blend weight of the current frame that minimises
  the expected squared error ``(1 - a)^2 b^2 + a^2 var / N`` of a result the spatial filter
  averages over ``N`` pixels (``spatial_samples``); elsewhere ``lambda = 0``.

``lambda`` is dilated by the 3x3 cell maximum (a change seen by a window reaches its border
pixels) and each pixel with history gets ``h <= 1/lambda - 1`` (``lambda = 1`` drops the
history: the next accumulation restarts at ``h = 1`` and the variance falls back to the
spatial estimate). Every term scales with the signal, so the test is the same at any
exposure; where the difference is within the noise nothing changes.

**Temporal gradient samples** (A-SVGF, Schied et al. 2018), when the renderer wrote them
(``svgf trace --gradient-samples``): sparse samples of last frame's shading re-shaded in this
frame with last frame's random numbers, so their difference ``delta = curr - prev`` measures
the change of the signal nearly free of Monte Carlo noise. Per window, their relative change
``r = |sum delta| / sum max(curr, prev)`` counts where the mean ``delta`` exceeds ``k``
standard errors of the samples' own spread (re-shading does not cancel noise where the
geometry moved), and gives a second bias estimate ``b_g = r m_h`` with weight
``b_g^2 / (b_g^2 + var / N)``; a pixel takes the larger of the two weights.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from svgf_cli.filters.fastmath import FASTMATH

F32 = np.float32
_ZERO = F32(0.0)
_ONE = F32(1.0)
CELL = 2  # pixels per cell side
# Fewer pixels with history than this in a window: no decision (the statistics are noise).
MIN_SAMPLES = 4
# Sums per cell: count, sum l, sum l^2, sum m1, sum (m2 - m1^2), sum h.
_TERMS = 6
# Sums per cell of gradient samples: count, sum delta, sum delta^2, sum max(curr, prev).
_GRADIENT_TERMS = 4

_JIT = dict(fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy")


def scratch_planes() -> int:
    """Cell planes of scratch :func:`antilag` needs."""
    return 2 * _TERMS + 2 * _GRADIENT_TERMS + 2


def cell_shape(height: int, width: int) -> tuple[int, int]:
    """Cells covering an image: (ceil(H / 2), ceil(W / 2))."""
    return (height + CELL - 1) // CELL, (width + CELL - 1) // CELL


def antilag(
    illumination: np.ndarray,
    history_moments: np.ndarray,
    history_length: np.ndarray,
    depth: np.ndarray,
    luminance_weights: np.ndarray,
    radius: int,
    sigma: float,
    spatial_samples: float,
    tolerance: float,
    moments_alpha: float,
    scratch: np.ndarray,
    out_lambda: np.ndarray,
    gradients: list[tuple[np.ndarray, np.ndarray, np.ndarray] | None] | None = None,
) -> int:
    """Lower ``history_length`` (S, H, W) in place where the history disagrees with the frame.

    ``illumination`` is the current demodulated signal (S, 3, H, W), ``history_moments``
    the reprojected moments (S, 2, H, W), ``luminance_weights`` (3,) float32, ``radius`` in
    cells. ``scratch`` is float32 (:func:`scratch_planes`, Hc, Wc) and ``out_lambda``
    (S, Hc, Wc) receives the dilated blend weight per cell (see :func:`cell_shape`).
    ``gradients`` optionally holds, per signal, temporal gradient samples ``(mask, prev,
    curr)`` as (H, W) float32 planes (``mask`` 1 where a sample sits), or None. Returns how
    many (signal, pixel) histories were shortened.
    """
    terms = scratch[:_TERMS]
    row_sums = scratch[_TERMS:2 * _TERMS]
    spare = scratch[2 * _TERMS]
    g_first = 2 * _TERMS + 1
    g_terms = scratch[g_first:g_first + _GRADIENT_TERMS]
    g_sums = scratch[g_first + _GRADIENT_TERMS:g_first + 2 * _GRADIENT_TERMS]
    relative = scratch[g_first + 2 * _GRADIENT_TERMS]
    shortened = 0
    for s in range(illumination.shape[0]):
        _cell_terms(illumination[s], history_moments[s], history_length[s], depth,
                    luminance_weights, terms)
        _row_box(terms, np.int64(radius), row_sums)
        samples = gradients[s] if gradients is not None else None
        if samples is not None:
            mask, previous, current = samples
            _gradient_terms(mask, previous, current, g_terms)
            _row_box(g_terms, np.int64(radius), g_sums)
            _gradient_change(g_sums, np.int64(radius), F32(sigma), relative)
        _cell_lambda(row_sums, np.int64(radius), F32(sigma), F32(spatial_samples),
                     F32(tolerance), F32(moments_alpha), relative, samples is not None, spare)
        _dilate(spare, out_lambda[s])
        shortened += int(_shorten(history_length[s], out_lambda[s]))
    return shortened


@njit(parallel=True, **_JIT)
def _cell_terms(
    current: np.ndarray,
    moments: np.ndarray,
    history_length: np.ndarray,
    depth: np.ndarray,
    weights: np.ndarray,
    out: np.ndarray,
) -> None:
    """Sums of the per-pixel terms over each cell's pixels that have history."""
    height, width = depth.shape
    cells_y, cells_x = out.shape[1], out.shape[2]
    wr, wg, wb = weights[0], weights[1], weights[2]
    for cy in prange(cells_y):
        pixel = np.zeros((_TERMS, CELL * cells_x), dtype=np.float32)
        for t in range(_TERMS):
            for cx in range(cells_x):
                out[t, cy, cx] = _ZERO
        for y in range(CELL * cy, min(CELL * cy + CELL, height)):
            r, g, b = current[0, y], current[1, y], current[2, y]
            m1_row, m2_row = moments[0, y], moments[1, y]
            h_row, z_row = history_length[y], depth[y]
            for x in range(width):
                h = h_row[x]
                v = _ONE if (h > _ZERO and z_row[x] > _ZERO) else _ZERO
                lum = v * (wr * r[x] + wg * g[x] + wb * b[x])
                m1 = v * m1_row[x]
                pixel[0, x] = v
                pixel[1, x] = lum
                pixel[2, x] = lum * lum
                pixel[3, x] = m1
                pixel[4, x] = max(v * m2_row[x] - m1 * m1, _ZERO)
                pixel[5, x] = v * h
            for t in range(_TERMS):
                row = pixel[t]
                acc = out[t, cy]
                for cx in range(cells_x):
                    acc[cx] += row[CELL * cx] + row[CELL * cx + 1]


@njit(parallel=True, **_JIT)
def _gradient_terms(
    mask: np.ndarray, previous: np.ndarray, current: np.ndarray, out: np.ndarray
) -> None:
    """Sums of the gradient samples' terms over each cell."""
    height, width = mask.shape
    cells_y, cells_x = out.shape[1], out.shape[2]
    for cy in prange(cells_y):
        pixel = np.zeros((_GRADIENT_TERMS, CELL * cells_x), dtype=np.float32)
        for t in range(_GRADIENT_TERMS):
            for cx in range(cells_x):
                out[t, cy, cx] = _ZERO
        for y in range(CELL * cy, min(CELL * cy + CELL, height)):
            m_row, p_row, c_row = mask[y], previous[y], current[y]
            for x in range(width):
                v = _ONE if m_row[x] > _ZERO else _ZERO
                delta = v * (c_row[x] - p_row[x])
                pixel[0, x] = v
                pixel[1, x] = delta
                pixel[2, x] = delta * delta
                pixel[3, x] = v * max(c_row[x], p_row[x])
            for t in range(_GRADIENT_TERMS):
                row = pixel[t]
                acc = out[t, cy]
                for cx in range(cells_x):
                    acc[cx] += row[CELL * cx] + row[CELL * cx + 1]


@njit(parallel=True, **_JIT)
def _gradient_change(
    row_sums: np.ndarray, radius: int, sigma: np.float32, out: np.ndarray
) -> None:
    """Relative change ``|sum delta| / sum max(curr, prev)`` per window where the mean
    ``delta`` is significant (more than ``sigma`` standard errors of the samples), else 0."""
    cells_y, cells_x = out.shape
    k2 = sigma * sigma
    for cy in prange(cells_y):
        sums = np.zeros((_GRADIENT_TERMS, cells_x), dtype=np.float32)
        for yy in range(max(cy - radius, 0), min(cy + radius + 1, cells_y)):
            for t in range(_GRADIENT_TERMS):
                row = row_sums[t, yy]
                acc = sums[t]
                for cx in range(cells_x):
                    acc[cx] += row[cx]
        o = out[cy]
        for cx in range(cells_x):
            n = sums[0, cx]
            inv_n = _ONE / max(n, _ONE)
            mean = sums[1, cx] * inv_n
            spread = max(sums[2, cx] * inv_n - mean * mean, _ZERO) * n / max(n - _ONE, _ONE)
            significant = n >= F32(2.0) and mean * mean > k2 * spread * inv_n
            level = sums[3, cx]
            change = min(abs(sums[1, cx]) / level, _ONE) if level > _ZERO else _ZERO
            o[cx] = change if significant else _ZERO


@njit(parallel=True, **_JIT)
def _row_box(terms: np.ndarray, radius: int, out: np.ndarray) -> None:
    """Sum every term along x over ``2r+1`` cells (cells outside the image count 0)."""
    num_terms = terms.shape[0]
    cells_y, cells_x = terms.shape[1], terms.shape[2]
    for job in prange(num_terms * cells_y):
        t = job // cells_y
        cy = job % cells_y
        row = terms[t, cy]
        acc = out[t, cy]
        for cx in range(cells_x):
            acc[cx] = _ZERO
        for offset in range(-radius, radius + 1):
            first = max(0, -offset)
            last = min(cells_x, cells_x - offset)
            if last <= first:
                continue
            # Slices, so that every index is provably non-negative and the loop vectorizes.
            source = row[first + offset:last + offset]
            target = acc[first:last]
            for i in range(last - first):
                target[i] += source[i]


@njit(parallel=True, **_JIT)
def _cell_lambda(
    row_sums: np.ndarray,
    radius: int,
    sigma: np.float32,
    spatial_samples: np.float32,
    tolerance: np.float32,
    moments_alpha: np.float32,
    gradient_change: np.ndarray,
    use_gradients: bool,
    out: np.ndarray,
) -> None:
    """Sum the row sums over ``2r+1`` cell rows and evaluate the blend weight per cell
    (the larger of the statistical and the gradient-sample weight with ``use_gradients``)."""
    cells_y, cells_x = out.shape
    k2 = sigma * sigma
    tol2 = tolerance * tolerance
    inv_spatial = _ONE / spatial_samples
    stationary = moments_alpha / (F32(2.0) - moments_alpha)
    for cy in prange(cells_y):
        sums = np.zeros((_TERMS, cells_x), dtype=np.float32)
        for yy in range(max(cy - radius, 0), min(cy + radius + 1, cells_y)):
            for t in range(_TERMS):
                row = row_sums[t, yy]
                acc = sums[t]
                for cx in range(cells_x):
                    acc[cx] += row[cx]
        o = out[cy]
        for cx in range(cells_x):
            n = sums[0, cx]
            inv_n = _ONE / max(n, _ONE)
            mean_c = sums[1, cx] * inv_n
            mean_h = sums[3, cx] * inv_n
            spread = max(sums[2, cx] * inv_n - mean_c * mean_c, _ZERO)
            var = max(spread * n / max(n - _ONE, _ONE), sums[4, cx] * inv_n)
            share = max(_ONE / max(sums[5, cx] * inv_n, _ONE), stationary)
            diff = mean_h - mean_c
            diff2 = diff * diff
            level = max(mean_c, mean_h)
            stale = diff2 > k2 * var * inv_n * (_ONE + share) + tol2 * level * level
            stale = stale and n >= F32(MIN_SAMPLES)
            bias2 = max(diff2 - var * inv_n, _ZERO)
            noise = var * inv_spatial + F32(1e-30)
            weight = bias2 / (bias2 + noise) if stale else _ZERO
            if use_gradients and n >= F32(MIN_SAMPLES):
                gradient_bias = gradient_change[cy, cx] * mean_h
                gradient_bias2 = gradient_bias * gradient_bias
                weight = max(weight, gradient_bias2 / (gradient_bias2 + noise))
            o[cx] = weight


@njit(parallel=True, **_JIT)
def _dilate(cells: np.ndarray, out: np.ndarray) -> None:
    """3x3 maximum over cells (separable: rows here, columns while writing)."""
    cells_y, cells_x = cells.shape
    for cy in prange(cells_y):
        best = np.zeros(cells_x, dtype=np.float32)
        for yy in range(max(cy - 1, 0), min(cy + 2, cells_y)):
            row = cells[yy]
            for cx in range(cells_x):
                best[cx] = max(best[cx], row[cx])
        o = out[cy]
        for cx in range(cells_x):
            o[cx] = best[cx]
        for cx in range(1, cells_x):
            o[cx] = max(o[cx], best[cx - 1])
        for cx in range(cells_x - 1):
            o[cx] = max(o[cx], best[cx + 1])


@njit(parallel=True, **_JIT)
def _shorten(history_length: np.ndarray, cell_lambda: np.ndarray) -> int:
    """``h = min(h, 1/lambda - 1)`` for every pixel with history under a cell with lambda."""
    height, width = history_length.shape
    cells_x = cell_lambda.shape[1]
    count = 0
    for y in prange(height):
        limit = np.empty(CELL * cells_x, dtype=np.float32)
        weights = cell_lambda[y // CELL]
        for cx in range(cells_x):
            weight = weights[cx]
            cap = _ONE / weight - _ONE if weight > _ZERO else F32(np.inf)
            limit[CELL * cx] = max(cap, _ZERO)
            limit[CELL * cx + 1] = max(cap, _ZERO)
        h_row = history_length[y]
        row_count = 0
        for x in range(width):
            h = h_row[x]
            shorter = limit[x] < h
            h_row[x] = limit[x] if shorter else h
            row_count += 1 if shorter else 0
        count += row_count
    return count
