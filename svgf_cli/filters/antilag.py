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
* stale where ``(m_h - m_c)^2 > k0^2 (var / n) (1 + share) + (tolerance max(m_c, m_h))^2``:
  more than ``k0`` (``sigma_start``) standard errors of the difference plus a small
  relative tolerance;
* there ``b^2 = (m_h - m_c)^2 - var / n`` (the history's squared bias, unbiased) and
  ``lambda = r b^2 / (b^2 + var / N)``: ``b^2 / (b^2 + var / N)`` is the blend weight of
  the current frame that minimises the expected squared error ``(1 - a)^2 b^2 + a^2 var /
  N`` of a result the spatial filter averages over ``N`` pixels (``spatial_samples``), and
  ``r`` ramps linearly in the difference's standard errors ``z`` from 0 at ``k0`` to 1 at
  ``k`` (``sigma``); elsewhere ``lambda = 0``. A light that moves a little every frame
  leaves a lag of a few standard errors that a test at ``k`` alone never sees, while a
  full weight from ``k0`` on would restart a blotch of history wherever the noise of one
  frame crosses it (a static shot's false alarms, many more under 1-spp noise than a
  Gaussian's): the ramp gives a change not yet sure a share of the frame and a false alarm
  little. ``sigma_start >= sigma`` is the step at ``k`` alone.

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


def cell_shape(height: int, width: int) -> tuple[int, int]:
    """Cells covering an image: (ceil(H / 2), ceil(W / 2))."""
    return (height + CELL - 1) // CELL, (width + CELL - 1) // CELL


def scratch_shape(num_signals: int, height: int, width: int) -> tuple[int, ...]:
    """Shape of the float32 scratch :func:`antilag` needs: per signal the window row sums of
    the statistics and of the gradient samples, and the undilated weight."""
    return (num_signals, _TERMS + _GRADIENT_TERMS + 1, *cell_shape(height, width))


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
    sigma_start: float | None = None,
) -> int:
    """Lower ``history_length`` (S, H, W) in place where the history disagrees with the frame.

    ``illumination`` is the current demodulated signal (S, 3, H, W), ``history_moments``
    the reprojected moments (S, 2, H, W), ``luminance_weights`` (3,) float32, ``radius`` in
    cells. ``scratch`` is float32 of :func:`scratch_shape` and ``out_lambda`` (S, Hc, Wc)
    receives the dilated blend weight per cell (see :func:`cell_shape`). ``gradients``
    optionally holds, per signal, temporal gradient samples ``(mask, prev, curr)`` as (H, W)
    float32 planes (``mask`` 1 where a sample sits), or None. Returns how many (signal,
    pixel) histories were shortened. ``sigma_start`` (default: ``sigma``) is where the weight
    starts to ramp in (module docstring). Three parallel passes for all signals together (each
    launch costs a thread wake-up, which dominates small kernels on a busy machine).
    """
    num_signals = illumination.shape[0]
    row_sums = scratch[:, :_TERMS]
    gradient_sums = scratch[:, _TERMS:_TERMS + _GRADIENT_TERMS]
    weight = scratch[:, _TERMS + _GRADIENT_TERMS]
    radius = np.int64(radius)
    statistics_row_sums(illumination, history_moments, history_length, depth,
                        luminance_weights, radius, row_sums)
    has_gradients = np.zeros(num_signals, dtype=np.bool_)
    if gradients is not None:
        for s, samples in enumerate(gradients):
            if samples is not None:
                has_gradients[s] = True
                _gradient_row_sums(*samples, radius, gradient_sums[s])
    start = sigma if sigma_start is None else min(sigma_start, sigma)
    _window_weight(row_sums, gradient_sums, has_gradients, radius, F32(sigma), F32(start),
                   F32(spatial_samples), F32(tolerance), F32(moments_alpha), weight)
    return int(_dilate_and_shorten(weight, history_length, out_lambda))


@njit(inline="always", **_JIT)
def _box_row(row: np.ndarray, radius: int, out: np.ndarray) -> None:
    """``out[x] = sum of row[x - r .. x + r]`` (cells outside the image count 0)."""
    count = row.shape[0]
    for x in range(count):
        out[x] = _ZERO
    for offset in range(-radius, radius + 1):
        first = max(0, -offset)
        last = min(count, count - offset)
        if last <= first:
            continue
        # Slices, so that every index is provably non-negative and the loop vectorizes.
        source = row[first + offset:last + offset]
        target = out[first:last]
        for i in range(last - first):
            target[i] += source[i]


@njit(parallel=True, **_JIT)
def statistics_row_sums(
    current: np.ndarray,
    moments: np.ndarray,
    history_length: np.ndarray,
    depth: np.ndarray,
    weights: np.ndarray,
    radius: int,
    out: np.ndarray,
) -> None:
    """Per signal and cell row: sums of the per-pixel terms over each cell's pixels with
    history, then summed along x over ``2r+1`` cells."""
    num_signals = current.shape[0]
    height, width = depth.shape
    cells_y, cells_x = out.shape[2], out.shape[3]
    wr, wg, wb = weights[0], weights[1], weights[2]
    for job in prange(num_signals * cells_y):
        s = job // cells_y
        cy = job % cells_y
        pixel = np.zeros((_TERMS, CELL * cells_x), dtype=np.float32)
        cells = np.zeros((_TERMS, cells_x), dtype=np.float32)
        for y in range(CELL * cy, min(CELL * cy + CELL, height)):
            r, g, b = current[s, 0, y], current[s, 1, y], current[s, 2, y]
            m1_row, m2_row = moments[s, 0, y], moments[s, 1, y]
            h_row, z_row = history_length[s, y], depth[y]
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
                acc = cells[t]
                for cx in range(cells_x):
                    acc[cx] += row[CELL * cx] + row[CELL * cx + 1]
        for t in range(_TERMS):
            _box_row(cells[t], radius, out[s, t, cy])


@njit(parallel=True, **_JIT)
def _gradient_row_sums(
    mask: np.ndarray, previous: np.ndarray, current: np.ndarray, radius: int, out: np.ndarray
) -> None:
    """One signal's gradient-sample terms per cell, summed along x over ``2r+1`` cells."""
    height, width = mask.shape
    cells_y, cells_x = out.shape[1], out.shape[2]
    for cy in prange(cells_y):
        pixel = np.zeros((_GRADIENT_TERMS, CELL * cells_x), dtype=np.float32)
        cells = np.zeros((_GRADIENT_TERMS, cells_x), dtype=np.float32)
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
                acc = cells[t]
                for cx in range(cells_x):
                    acc[cx] += row[CELL * cx] + row[CELL * cx + 1]
        for t in range(_GRADIENT_TERMS):
            _box_row(cells[t], radius, out[t, cy])


@njit(parallel=True, **_JIT)
def _window_weight(
    row_sums: np.ndarray,
    gradient_sums: np.ndarray,
    has_gradients: np.ndarray,
    radius: int,
    sigma: np.float32,
    sigma_start: np.float32,
    spatial_samples: np.float32,
    tolerance: np.float32,
    moments_alpha: np.float32,
    out: np.ndarray,
) -> None:
    """Sum the row sums over ``2r+1`` cell rows and evaluate the blend weight per cell: the
    statistical one and, for a signal with gradient samples, the larger of it and the
    gradient samples' (module docstring)."""
    num_signals, cells_y, cells_x = out.shape
    k2 = sigma * sigma
    k0_2 = sigma_start * sigma_start
    # 1 / (k - k0): the ramp's slope per standard error (0: a step at k).
    ramp_slope = _ONE / (sigma - sigma_start) if sigma > sigma_start else _ZERO
    tol2 = tolerance * tolerance
    inv_spatial = _ONE / spatial_samples
    stationary = moments_alpha / (F32(2.0) - moments_alpha)
    for job in prange(num_signals * cells_y):
        s = job // cells_y
        cy = job % cells_y
        use_gradients = has_gradients[s]
        sums = np.zeros((_TERMS, cells_x), dtype=np.float32)
        g = np.zeros((_GRADIENT_TERMS, cells_x), dtype=np.float32)
        for yy in range(max(cy - radius, 0), min(cy + radius + 1, cells_y)):
            for t in range(_TERMS):
                row = row_sums[s, t, yy]
                acc = sums[t]
                for cx in range(cells_x):
                    acc[cx] += row[cx]
            if use_gradients:
                for t in range(_GRADIENT_TERMS):
                    row = gradient_sums[s, t, yy]
                    acc = g[t]
                    for cx in range(cells_x):
                        acc[cx] += row[cx]
        o = out[s, cy]
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
            stale = diff2 > k0_2 * var * inv_n * (_ONE + share) + tol2 * level * level
            stale = stale and n >= F32(MIN_SAMPLES)
            bias2 = max(diff2 - var * inv_n, _ZERO)
            noise = var * inv_spatial + F32(1e-30)
            ramp = _ONE
            if stale and ramp_slope > _ZERO:  # no ramp: a step at k, as the test alone
                error2 = var * inv_n * (_ONE + share)  # the difference's squared std. error
                if diff2 < k2 * error2:
                    # z: the difference in its standard errors, between k0 and k.
                    z = np.sqrt(diff2 / max(error2, F32(1e-30)))
                    ramp = min((z - sigma_start) * ramp_slope, _ONE)
            weight = ramp * bias2 / (bias2 + noise) if stale else _ZERO
            if use_gradients and n >= F32(MIN_SAMPLES):
                # The samples' relative change, where their mean delta is significant.
                g_n = g[0, cx]
                g_inv = _ONE / max(g_n, _ONE)
                g_mean = g[1, cx] * g_inv
                g_spread = max(g[2, cx] * g_inv - g_mean * g_mean, _ZERO)
                g_spread *= g_n / max(g_n - _ONE, _ONE)
                significant = g_n >= F32(2.0) and g_mean * g_mean > k2 * g_spread * g_inv
                g_level = g[3, cx]
                change = min(abs(g[1, cx]) / g_level, _ONE) if g_level > _ZERO else _ZERO
                gradient_bias = change * mean_h if significant else _ZERO
                gradient_bias2 = gradient_bias * gradient_bias
                weight = max(weight, gradient_bias2 / (gradient_bias2 + noise))
            o[cx] = weight


@njit(parallel=True, **_JIT)
def _dilate_and_shorten(
    weight: np.ndarray, history_length: np.ndarray, out_lambda: np.ndarray
) -> int:
    """Per pixel row: the 3x3 cell maximum of the weight over the row's cells (written to
    ``out_lambda`` once per cell row), then ``h = min(h, 1/lambda - 1)`` where lambda > 0."""
    num_signals, cells_y, cells_x = weight.shape
    height, width = history_length.shape[1], history_length.shape[2]
    count = 0
    for job in prange(num_signals * height):
        s = job // height
        y = job % height
        cy = y // CELL
        best = np.zeros(cells_x, dtype=np.float32)
        for yy in range(max(cy - 1, 0), min(cy + 2, cells_y)):
            row = weight[s, yy]
            for cx in range(cells_x):
                best[cx] = max(best[cx], row[cx])
        dilated = np.empty(cells_x, dtype=np.float32)
        for cx in range(cells_x):
            dilated[cx] = best[cx]
        for cx in range(1, cells_x):
            dilated[cx] = max(dilated[cx], best[cx - 1])
        for cx in range(cells_x - 1):
            dilated[cx] = max(dilated[cx], best[cx + 1])
        if y % CELL == 0:
            o = out_lambda[s, cy]
            for cx in range(cells_x):
                o[cx] = dilated[cx]
        limit = np.empty(CELL * cells_x, dtype=np.float32)
        for cx in range(cells_x):
            lam = dilated[cx]
            cap = max(_ONE / lam - _ONE, _ZERO) if lam > _ZERO else F32(np.inf)
            limit[CELL * cx] = cap
            limit[CELL * cx + 1] = cap
        h_row = history_length[s, y]
        row_count = 0
        for x in range(width):
            h = h_row[x]
            shorter = limit[x] < h
            h_row[x] = limit[x] if shorter else h
            row_count += 1 if shorter else 0
        count += row_count
    return count
