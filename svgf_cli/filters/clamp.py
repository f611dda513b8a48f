"""Optional outlier clamps from the lecture notes (both off by default: they bias).

* :func:`firefly_clamp` (before accumulation): a pixel whose luminance exceeds the mean +
  ``k`` standard deviations of its 8 neighbours is scaled down to that limit (hue kept).
  The centre is left out of the statistics, otherwise a firefly would widen its own bound.
* :func:`history_clamp` (against ghosting): the reprojected history colour is clamped per
  channel to the current frame's 3x3 (or wider: ``radius``) mean +- ``k`` sigma, so stale
  history that no longer matches the neighbourhood (moving shadows, lights switching) is
  pulled back; its luminance moments are scaled with it. A glossy signal's pixels whose
  history is heavy-tailed (:func:`heavy_tailed`) can take a wider window than the rest of
  the signal (``wide_where``).

Neighbour statistics use only in-image, non-background pixels.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import njit, prange

from svgf_cli.filters.fastmath import FASTMATH, luminance
from svgf_cli.filters.shares import row_sums

F32 = np.float32
_ZERO = F32(0.0)
_ONE = F32(1.0)
# The largest factor the history clamp scales the moments by (m2 by its square), and the
# largest second moment it leaves (finite whatever spread a firefly left in the history).
MAX_RAISE = F32(1e6)
MAX_SECOND_MOMENT = F32(1e36)
# From this many frames of history on, a pixel's luminance moments are taken as a sample of
# its light's tail (:func:`heavy_tailed`): one frame before this one already shows it
# (docs/algorithm.md#heavy-tailed-glossy-light: 1 measured better than 2, 3 and 4).
HEAVY_TAIL_MIN_HISTORY = F32(1.0)
_NO_MASK = np.zeros((1, 1), dtype=np.bool_)


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def firefly_clamp(
    illumination: np.ndarray,
    depth: np.ndarray,
    k: np.float32,
    luminance_weights: tuple[np.float32, np.float32, np.float32],
    out: np.ndarray,
) -> None:
    """Clamp luminance to mean + k*sigma of the 8 neighbours, scaling rgb. (S, 3, H, W).

    Neighbours are counted within the signal as they come (the demodulation mode is not
    consulted: the clamp is an optional, biased extra)."""
    num_signals = illumination.shape[0]
    height, width = depth.shape
    for y in prange(height):
        for x in range(width):
            for s in range(num_signals):
                r = illumination[s, 0, y, x]
                g = illumination[s, 1, y, x]
                b = illumination[s, 2, y, x]
                out[s, 0, y, x] = r
                out[s, 1, y, x] = g
                out[s, 2, y, x] = b
                if depth[y, x] <= _ZERO:
                    continue
                count = 0
                total = _ZERO
                total_sq = _ZERO
                for yy in range(max(y - 1, 0), min(y + 2, height)):
                    for xx in range(max(x - 1, 0), min(x + 2, width)):
                        if (yy == y and xx == x) or depth[yy, xx] <= _ZERO:
                            continue
                        lum_q = luminance(
                            illumination[s, 0, yy, xx],
                            illumination[s, 1, yy, xx],
                            illumination[s, 2, yy, xx],
                            luminance_weights,
                        )
                        count += 1
                        total += lum_q
                        total_sq += lum_q * lum_q
                if count == 0:
                    continue
                mean = total / F32(count)
                sigma = np.sqrt(max(total_sq / F32(count) - mean * mean, _ZERO))
                limit = max(mean + k * sigma, _ZERO)
                lum = luminance(r, g, b, luminance_weights)
                if lum > limit:
                    scale = limit / lum
                    out[s, 0, y, x] = r * scale
                    out[s, 1, y, x] = g * scale
                    out[s, 2, y, x] = b * scale


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
      error_model="numpy")
def _three_tap(column: np.ndarray, out: np.ndarray) -> None:
    """``out[x] = column[x - 1] + column[x] + column[x + 1]`` within the row."""
    width = column.shape[0]
    if width == 1:
        out[0] = column[0]
        return
    out[0] = column[0] + column[1]
    for x in range(1, width - 1):
        out[x] = column[x - 1] + column[x] + column[x + 1]
    out[width - 1] = column[width - 2] + column[width - 1]


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
      error_model="numpy")
def _follow_luminance(m1: np.ndarray, m2: np.ndarray, x: int, before: np.float32,
                      after: np.float32) -> None:
    """A clamped history's moments at ``x`` follow its luminance ``before -> after``."""
    # Raised more than MAX_RAISE-fold, (l'/l)^2 could overflow m2 to inf: such a history
    # counts as black.
    if before > _ZERO and after <= MAX_RAISE * before:
        ratio = after / before
        m1[x] *= ratio
        m2[x] = min(m2[x] * (ratio * ratio), MAX_SECOND_MOMENT)
    else:
        m1[x] = after
        m2[x] = after * after


def history_clamp(
    history: np.ndarray,
    history_moments: np.ndarray,
    history_length: np.ndarray,
    current: np.ndarray,
    depth: np.ndarray,
    k: float | Sequence[float],
    luminance_weights: tuple[np.float32, np.float32, np.float32],
    radius: int | Sequence[int] = 1,
    wide_where: Sequence[np.ndarray | None] | None = None,
    wide_radius: int = 1,
) -> None:
    """In place: clamp each history channel to the current 3x3 mean +- k*sigma (the
    ``(2 radius + 1)^2`` window's: one radius for all signals or one per signal), and let the
    luminance moments follow the history luminance ``l -> l'``: ``m1 *= l'/l`` and
    ``m2 *= (l'/l)^2`` (the relative spread kept; at most ``MAX_SECOND_MOMENT``), except
    ``m1 = l'``, ``m2 = l'^2`` where ``l <= 0`` or ``l' > MAX_RAISE l`` (a history raised
    from near black, whose scaled ``m2`` could overflow).

    Without the moments a clamped outlier would keep its variance, and with it a wide
    luminance stop that spreads the outlier's energy in the a-trous (hot pixels around
    reflections). ``history`` and ``current`` are (S, 3, H, W), ``history_moments``
    (S, 2, H, W), ``history_length`` (S, H, W); a signal's pixels without history are left
    alone. The 3x3 sums are separable (column sums over three rows, then three taps), so
    every inner loop runs over a row.

    ``k`` is one for all signals or one per signal; a signal with ``k <= 0`` is not clamped.
    The 3x3 signals in one parallel pass (the background count is shared); each wider one in
    a pass of its own (:func:`_clamp_wide_rows`). ``wide_where``: per signal None or an
    (H, W) bool plane where that 3x3 signal takes the ``(2 wide_radius + 1)^2`` window
    instead (its history there clamped as if the 3x3 pass had not run).
    """
    num_signals = history.shape[0]
    ks = np.ascontiguousarray(np.broadcast_to(np.asarray(k, dtype=F32), (num_signals,)))
    radii = np.broadcast_to(np.asarray(radius, dtype=np.int64), (num_signals,))
    if radii.min() < 1:
        raise ValueError(f"history clamp radius must be at least 1, got {radii.min()}")
    wide = [s for s in range(num_signals) if radii[s] > 1 and ks[s] > 0]
    narrow = ks.copy()
    narrow[wide] = _ZERO  # clamped by _clamp_wide_rows below
    # The 3x3 signals' pixels that take the wider window: kept as they are through the 3x3
    # pass, put back, then clamped over the wider window alone.
    held = [(s, mask, history[s][:, mask], history_moments[s][:, mask])
            for s, mask in enumerate(wide_where or ())
            if mask is not None and wide_radius > 1 and narrow[s] > _ZERO and mask.any()]
    if narrow.max() > _ZERO:  # a signal left for the 3x3 pass (none when all are wider)
        _history_clamp_rows(history, history_moments, history_length, current, depth, narrow,
                            luminance_weights)
    for s in wide:  # a wider window: one signal at a time, in bands of rows
        _clamp_wide_rows(history[s], history_moments[s], history_length[s], current[s], depth,
                         ks[s], int(radii[s]), luminance_weights, _NO_MASK, False)
    for s, mask, kept, kept_moments in held:
        history[s][:, mask] = kept
        history_moments[s][:, mask] = kept_moments
        _clamp_wide_rows(history[s], history_moments[s], history_length[s], current[s], depth,
                         ks[s], int(wide_radius), luminance_weights, mask, True)


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def _history_clamp_rows(
    history: np.ndarray,
    history_moments: np.ndarray,
    history_length: np.ndarray,
    current: np.ndarray,
    depth: np.ndarray,
    ks: np.ndarray,
    luminance_weights: tuple[np.float32, np.float32, np.float32],
) -> None:
    """All rows of :func:`history_clamp`'s 3x3 (``ks`` per signal).
    """
    num_signals = history.shape[0]
    height, width = depth.shape
    wr, wg, wb = luminance_weights
    for y in prange(height):
        column = np.zeros(width, dtype=F32)
        column_sq = np.empty(width, dtype=F32)
        count = np.empty(width, dtype=F32)
        total = np.empty(width, dtype=F32)
        total_sq = np.empty(width, dtype=F32)
        before = np.empty(width, dtype=F32)
        moved = np.empty(width, dtype=np.uint8)
        y0, y1 = max(y - 1, 0), min(y + 2, height)
        for yy in range(y0, y1):
            z = depth[yy]
            for x in range(width):
                column[x] += _ONE if z[x] > _ZERO else _ZERO
        _three_tap(column, count)
        z = depth[y]
        for s in range(num_signals):
            k = ks[s]
            if k <= _ZERO:
                continue
            h = history_length[s, y]
            hr, hg, hb = history[s, 0, y], history[s, 1, y], history[s, 2, y]
            for x in range(width):
                before[x] = wr * hr[x] + wg * hg[x] + wb * hb[x]
                moved[x] = 0
            for c in range(3):
                column[:] = _ZERO
                column_sq[:] = _ZERO
                for yy in range(y0, y1):
                    v = current[s, c, yy]
                    zz = depth[yy]
                    for x in range(width):
                        kept = v[x] if zz[x] > _ZERO else _ZERO
                        column[x] += kept
                        column_sq[x] += kept * kept
                _three_tap(column, total)
                _three_tap(column_sq, total_sq)
                out = history[s, c, y]
                for x in range(width):
                    n = max(count[x], _ONE)
                    mean = total[x] / n
                    sigma = np.sqrt(max(total_sq[x] / n - mean * mean, _ZERO))
                    value = out[x]
                    clamped = min(max(value, mean - k * sigma), mean + k * sigma)
                    use = z[x] > _ZERO and h[x] > _ZERO and clamped != value
                    out[x] = clamped if use else value
                    moved[x] |= use
            m1, m2 = history_moments[s, 0, y], history_moments[s, 1, y]
            for x in range(width):
                if moved[x]:
                    _follow_luminance(m1, m2, x, before[x], wr * hr[x] + wg * hg[x] + wb * hb[x])


@njit(parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
      error_model="numpy")
def heavy_tailed(moments: np.ndarray, length: np.ndarray, depth: np.ndarray,
                 mesh_id: np.ndarray, rough_low: int, rough_table: np.ndarray,
                 threshold: np.float32, out: np.ndarray) -> int:
    """``out`` (H, W) bool: the surface pixels with at least :data:`HEAVY_TAIL_MIN_HISTORY`
    frames of history whose luminance moments ``m1, m2`` (2, H, W) have a relative variance
    ``(m2 - m1^2) / m1^2`` above ``threshold`` (``m1 > 0``), except on the objects marked in
    ``rough_table`` (uint8, object ``mesh_id - rough_low``). Returns how many.

    A light made of rare bright samples (a small light's reflection, a refraction, a
    caustic) has a large relative variance; exponential noise has 1."""
    height, width = depth.shape
    entries = rough_table.size
    counts = np.zeros(height, dtype=np.int64)
    for y in prange(height):
        m1, m2, h, z = moments[0, y], moments[1, y], length[y], depth[y]
        ids, row = mesh_id[y], out[y]
        for x in range(width):
            mean = m1[x]
            heavy = (z[x] > _ZERO and h[x] >= HEAVY_TAIL_MIN_HISTORY and mean > _ZERO
                     and m2[x] - mean * mean > threshold * (mean * mean))
            if heavy:
                k = np.int64(ids[x]) - rough_low
                if k >= 0 and k < entries and rough_table[k] > 0:
                    heavy = False
            row[x] = heavy
            counts[y] += 1 if heavy else 0
    return int(counts.sum())


# Rows per band of the wider windows' kernel: fixed, so that the sums (and so the outputs)
# do not depend on the number of threads.
BAND_ROWS = 32


@njit(parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
      error_model="numpy")
def _clamp_wide_rows(history: np.ndarray, moments: np.ndarray, length: np.ndarray,
                     current: np.ndarray, depth: np.ndarray, k: np.float32, radius: int,
                     luminance_weights: tuple[np.float32, np.float32, np.float32],
                     only: np.ndarray, masked: bool) -> None:
    """One signal's history (3, H, W) clamped per channel to the mean +- ``k`` sigma of the
    current values (3, H, W) over the surface pixels of the (2 radius + 1)^2 window, its
    moments (2, H, W) following (:func:`_follow_luminance`); where it has a history and a
    surface (and, when ``masked``, where ``only`` (H, W) bool is set). In bands of
    :data:`BAND_ROWS` rows, one job each: the window's column sums
    (float64: count, values, squares) slide down the band, a row entering and one leaving,
    and each row's window sums run along it."""
    height, width = depth.shape
    wr, wg, wb = luminance_weights
    for band in prange((height + BAND_ROWS - 1) // BAND_ROWS):
        first, last = band * BAND_ROWS, min(band * BAND_ROWS + BAND_ROWS, height)
        columns = np.zeros((7, width))  # count, then sums and sums of squares of R, G, B
        window = np.empty((7, width))
        for yy in range(max(first - radius, 0), min(first + radius, height - 1) + 1):
            _slide_columns(current, depth, yy, 1.0, columns)
        for y in range(first, last):
            if y > first:
                if y + radius < height:
                    _slide_columns(current, depth, y + radius, 1.0, columns)
                if y - radius - 1 >= 0:
                    _slide_columns(current, depth, y - radius - 1, -1.0, columns)
            for row in range(7):
                row_sums(columns[row], radius, window[row])
            z, h = depth[y], length[y]
            hr, hg, hb = history[0, y], history[1, y], history[2, y]
            m1, m2 = moments[0, y], moments[1, y]
            for x in range(width):
                if z[x] <= _ZERO or h[x] <= _ZERO or (masked and not only[y, x]):
                    continue
                share = 1.0 / max(window[0, x], 1.0)
                before = wr * hr[x] + wg * hg[x] + wb * hb[x]
                moved = False
                for c in range(3):
                    mean = window[1 + c, x] * share
                    sigma = np.sqrt(F32(max(window[4 + c, x] * share - mean * mean, 0.0)))
                    mu = F32(mean)
                    value = history[c, y, x]
                    clamped = min(max(value, mu - k * sigma), mu + k * sigma)
                    if clamped != value:
                        history[c, y, x] = clamped
                        moved = True
                if moved:
                    _follow_luminance(m1, m2, x, before, wr * hr[x] + wg * hg[x] + wb * hb[x])


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
      error_model="numpy")
def _slide_columns(current: np.ndarray, depth: np.ndarray, y: int, sign: float,
                   columns: np.ndarray) -> None:
    """Add (``sign`` 1) or take away (-1) row ``y``'s surface pixels: their count, values
    and squares, per channel, to the column sums."""
    z = depth[y]
    count = columns[0]
    for x in range(z.shape[0]):
        count[x] += sign if z[x] > _ZERO else 0.0
    for c in range(3):
        values, total, squares = current[c, y], columns[1 + c], columns[4 + c]
        for x in range(z.shape[0]):
            value = np.float64(values[x]) if z[x] > _ZERO else 0.0
            total[x] += sign * value
            squares[x] += sign * (value * value)
