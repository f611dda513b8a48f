"""History gain: the reprojected history rescaled where the light changed by one factor over
a wide neighbourhood (a light switched on or off, dimmed, brightened), before anti-lag.

Anti-lag answers any change beyond the noise by shortening the history, so after a light
switches on the whole lit region restarts from one sample a pixel and is filtered spatially
for several frames. But a change that scales the light of a whole neighbourhood by one factor
leaves the history's shape right: only its level is stale. This stage measures that factor
and corrects the level instead, so the history keeps its length.

Per signal, on the cells of 2x2 pixels of :mod:`filters.antilag` and with its statistics
(the current luminance's mean ``m_c`` and the reprojected first moment's mean ``m_h`` over
the pixels with history, their difference's squared standard error ``e^2 = var / n (1 +
share)``):

* **wide window** (``GAIN_WINDOW_SCALE`` times the anti-lag radius): where ``d = m_c - m_h``
  exceeds ``sigma`` (``antilag_sigma``) standard errors plus the relative tolerance, the
  gain ``g = m_c / m_h`` (within ``[1 / GAIN_MAX, GAIN_MAX]``: beyond it the history holds
  little of the new light, which anti-lag's restart serves better), shrunk towards 1 by
  ``w = b^2 / (b^2 + e^2)`` with ``b^2 = d^2 - e^2`` (the weight of a correction of noise
  ``e^2`` for a bias ``b`` that minimises the expected squared error);
* **checks at narrower windows** (``GAIN_CHECK_SCALES``: twice the anti-lag radius, then
  the anti-lag's own): the gain holds only where the rescaled history would pass anti-lag's
  own test in each, ``(m_c - g' m_h)^2 <= k0^2 e^2 + (tolerance level)^2`` with ``k0`` the
  ramp's start (``antilag_sigma_start``): anti-lag then leaves it whole, and nowhere does a
  rescaled history lose part of its length. A change with structure (a shadow moving, a
  light's pool sliding, a light reaching only part of the window) fails a check near that
  structure and is left to anti-lag, which then sees it unaltered. What no check at one
  sample a pixel can see: a band of a few pixels along a sharp border of the change (a
  switched light's hard shadow), where every window straddles the border and agrees with
  the mixed factor; that band's history is rescaled by it.

A pixel with history in a cell where the gain holds gets its colour history and first moment
times ``g'`` and its second moment times ``g'^2`` (its relative spread kept). Anti-lag then
tests the rescaled history as any other and shortens what still disagrees.

Causal runs only: in a pass of a bidirectional run a history anti-lag shortens is refilled by
the other pass, while a gain's error (within its checks' noise, but low in frequency) is not
averaged away (measured: docs/algorithm.md#the-history-gain).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from svgf_cli.filters.antilag import MIN_SAMPLES, statistics_row_sums
from svgf_cli.filters.fastmath import FASTMATH
from svgf_cli.filters.shares import row_sums

F32 = np.float32
_ZERO = F32(0.0)
_ONE = F32(1.0)
# The wide window's radius in anti-lag radii: its level is measured over 25x the anti-lag
# window's pixels, so its noise is a fifth of the narrow window's (3 measured worse on the
# light steps, 8 no better in a first version: docs/algorithm.md#the-history-gain).
GAIN_WINDOW_SCALE = 5
# Gains beyond this factor either way are left to anti-lag (a light from nothing: no level
# to rescale). Measured: 16 within 0.003 JOD of 4 on every fixture (none has a larger
# step); 2 loses all of the light steps' gain (their factor is 0.3).
GAIN_MAX = 4.0
# The check windows' radii in anti-lag radii: its own window, where anti-lag tests next,
# and one between (less noisy: a change with structure wider than the anti-lag window but
# within its noise is caught there).
GAIN_CHECK_SCALES = (2, 1)
# Planes of the scratch: each cell's sums of anti-lag's six terms, then the gain per cell.
_SUMS = 6
_JIT = dict(fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy")


def history_gain(
    illumination: np.ndarray,
    history_illumination: np.ndarray,
    history_moments: np.ndarray,
    history_length: np.ndarray,
    depth: np.ndarray,
    luminance_weights: np.ndarray,
    radius: int,
    sigma: float,
    sigma_start: float,
    tolerance: float,
    moments_alpha: float,
    scratch: np.ndarray,
) -> int:
    """Rescale ``history_illumination`` (S, 3, H, W) and ``history_moments`` (S, 2, H, W) in
    place where the wide window's light changed by one factor that every check window
    (``radius`` in cells, and up) confirms within ``sigma_start`` standard errors (module
    docstring). ``illumination`` is the current demodulated signal (S, 3, H, W),
    ``history_length`` (S, H, W) (0: no history), ``luminance_weights`` (3,) float32,
    ``scratch`` float32 of anti-lag's ``scratch_shape``. Returns how many (signal, pixel)
    histories were rescaled."""
    cells = scratch[:, :_SUMS]
    gain = scratch[:, _SUMS]
    stationary = F32(moments_alpha / (2.0 - moments_alpha))
    # Each cell's own sums (a window of one cell), boxed below for every window size.
    statistics_row_sums(illumination, history_moments, history_length, depth,
                        luminance_weights, np.int64(0), cells)
    # Which signals have a gain: most frames change no signal's light, and skip the rest.
    active = np.ones(gain.shape[0], dtype=np.bool_)
    _window_pass(cells, np.int64(radius * GAIN_WINDOW_SCALE), False, active, stationary,
                 F32(sigma), F32(tolerance), gain)
    if not active.any():
        return 0
    for scale in GAIN_CHECK_SCALES:
        _window_pass(cells, np.int64(radius * scale), True, active, stationary,
                     F32(min(sigma_start, sigma)), F32(tolerance), gain)
    return int(_apply_gain(gain, active, history_illumination, history_moments,
                           history_length, depth))


@njit(inline="always", **_JIT)
def _window_means(sums: np.ndarray, cx: int, stationary: np.float32
                  ) -> tuple[np.float32, np.float32, np.float32, np.float32]:
    """A window's count, current and history means and their difference's squared
    standard error, from its six sums (as ``filters.antilag._window_weight``)."""
    n = F32(sums[0, cx])
    inv_n = _ONE / max(n, _ONE)
    mean_c = F32(sums[1, cx]) * inv_n
    mean_h = F32(sums[3, cx]) * inv_n
    spread = max(F32(sums[2, cx]) * inv_n - mean_c * mean_c, _ZERO)
    var = max(spread * n / max(n - _ONE, _ONE), F32(sums[4, cx]) * inv_n)
    share = max(_ONE / max(F32(sums[5, cx]) * inv_n, _ONE), stationary)
    return n, mean_c, mean_h, var * inv_n * (_ONE + share)


@njit(parallel=True, **_JIT)
def _window_pass(cells: np.ndarray, radius: int, check: bool, active: np.ndarray,
                 stationary: np.float32, sigma: np.float32, tolerance: np.float32,
                 gain: np.ndarray) -> None:
    """Per signal, the ``(2r+1)^2``-cell window sums of ``cells`` (S, 6, Hc, Wc) by running
    sums along and down the rows (float64, a ring of the rows in the window: the same cost at
    any radius), and per cell either
    (``check`` False) the wide window's shrunk gain where its change exceeds ``sigma``
    standard errors, else 1, or (``check`` True) a gain set back to 1 unless this window's
    history times it is within ``sigma`` standard errors (plus the tolerance) of its
    current mean. Signals not ``active`` are left as they are; the gain pass sets
    ``active[s]`` to whether any of signal ``s``'s cells got a gain."""
    num_signals, cells_y, cells_x = gain.shape
    k2 = sigma * sigma
    tol2 = tolerance * tolerance
    high, low = F32(GAIN_MAX), F32(1.0 / GAIN_MAX)
    least = F32(MIN_SAMPLES)
    span = 2 * radius + 1
    for s in prange(num_signals):
        if not active[s]:
            continue
        ring = np.zeros((span, _SUMS, cells_x))
        sums = np.zeros((_SUMS, cells_x))
        found = False
        boxed = np.empty(cells_x)
        for y in range(-radius, cells_y):
            entering = y + radius
            if y - radius - 1 >= 0:  # the row leaving the window
                leaving = ring[(y - radius - 1) % span]
                for t in range(_SUMS):
                    for cx in range(cells_x):
                        sums[t, cx] -= leaving[t, cx]
            if entering < cells_y:
                slot = ring[entering % span]
                for t in range(_SUMS):
                    row_sums(cells[s, t, entering], radius, boxed)
                    for cx in range(cells_x):
                        slot[t, cx] = boxed[cx]
                        sums[t, cx] += boxed[cx]
            if y < 0:
                continue
            o = gain[s, y]
            for cx in range(cells_x):
                if check and o[cx] == _ONE:
                    continue
                n, mean_c, mean_h, error2 = _window_means(sums, cx, stationary)
                if check:
                    g = o[cx]
                    rest = mean_c - g * mean_h
                    level = max(mean_c, g * mean_h)
                    if n < least or rest * rest > k2 * error2 + tol2 * level * level:
                        o[cx] = _ONE
                    continue
                diff = mean_c - mean_h
                diff2 = diff * diff
                level = max(mean_c, mean_h)
                g = _ONE
                if (n >= least and mean_h > _ZERO
                        and diff2 > k2 * error2 + tol2 * level * level):
                    ratio = mean_c / mean_h
                    if low <= ratio <= high:
                        bias2 = max(diff2 - error2, _ZERO)
                        g = _ONE + bias2 / (bias2 + error2 + F32(1e-30)) * (ratio - _ONE)
                        found = True
                o[cx] = g
        if not check:
            active[s] = found


@njit(parallel=True, **_JIT)
def _apply_gain(gain: np.ndarray, active: np.ndarray, illumination: np.ndarray,
                moments: np.ndarray, history_length: np.ndarray, depth: np.ndarray) -> int:
    """Each pixel with history times its cell's gain (second moment: its square), in the
    ``active`` signals."""
    num_signals, height, width = history_length.shape
    count = 0
    for job in prange(num_signals * height):
        s = job // height
        y = job % height
        if not active[s]:
            continue
        cells = gain[s, y // 2]
        h_row, z_row = history_length[s, y], depth[y]
        r, g_, b = illumination[s, 0, y], illumination[s, 1, y], illumination[s, 2, y]
        m1, m2 = moments[s, 0, y], moments[s, 1, y]
        row_count = 0
        for x in range(width):
            g = cells[x // 2]
            if g != _ONE and h_row[x] > _ZERO and z_row[x] > _ZERO:
                r[x] *= g
                g_[x] *= g
                b[x] *= g
                m1[x] *= g
                m2[x] *= g * g
                row_count += 1
        count += row_count
    return count
