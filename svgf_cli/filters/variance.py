"""Per-pixel luminance variance (paper section 4.2).

* With enough history (``h >= variance_history_threshold``, 4): the temporal estimate
  ``Var = max(0, m2 - m1^2)`` from the integrated moments (:func:`temporal_variance`).
* Shorter history: :func:`spatial_variance`, a 7x7 edge-aware (depth, normal, same
  demodulation mode and a weak relative luminance stop) box-weighted estimate of the
  moments around the pixel, then
  :func:`boost_short_history` multiplies it by ``threshold / h`` (Falcor's 4/h) because a
  few frames of history are not yet averaged down and the estimate itself is noisy.

The spatial estimator is kept unboosted and close to unbiased: the weighted population
variance is divided by ``1 - sum(w^2) / (h * (sum w)^2)``, the reliability-weights
(Bessel) correction for a weighted sample of h-frame averages, so its expectation is the
per-sample noise variance even where an edge leaves only a few neighbours.

Every signal has its own history length, so each decides on its own whether it needs the
spatial estimate; the geometry weights of a tap are computed once for all signals.

Colour: the paper blurs only the variance here; Falcor also replaces the colour of
short-history pixels by the 7x7 weighted mean. ``spatial_variance_blur_color`` selects the
Falcor behaviour (on in the ``falcor`` preset); by default the colour is left to the a-trous.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from svgf_cli.filters.edges import tap_geometry
from svgf_cli.filters.fastmath import FASTMATH, fast_exp

F32 = np.float32
_ZERO = F32(0.0)
_ONE = F32(1.0)
_HALF = F32(0.5)
# Keeps 0/0 away where both moments are 0 (the stop then sees |0 - 0| / tiny = 0).
_TINY = F32(1e-30)
# Pixels of ordinary history between two short-history runs below which the runs merge.
RUN_GAP = 16


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def temporal_variance(moments: np.ndarray, out: np.ndarray) -> None:
    """``Var = max(0, m2 - m1^2)`` for every signal; moments (S, 2, H, W), out (S, H, W)."""
    num_signals = moments.shape[0]
    height, width = moments.shape[2], moments.shape[3]
    for y in prange(height):
        for s in range(num_signals):
            m1 = moments[s, 0, y]
            m2 = moments[s, 1, y]
            o = out[s, y]
            for x in range(width):
                o[x] = max(m2[x] - m1[x] * m1[x], _ZERO)


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, error_model="numpy")
def _short(h: np.float32, history_threshold: np.float32) -> bool:
    return h > _ZERO and h < history_threshold


@njit(fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy")
def _needed_row(
    history_length: np.ndarray, y: int, history_threshold: np.float32, out: np.ndarray
) -> bool:
    """``out[x]`` = 1 where some signal has ``0 < h < threshold`` in row ``y``; whether any
    pixel does (vectorized passes, one per signal, and a max)."""
    num_signals = history_length.shape[0]
    width = out.shape[0]
    h_row = history_length[0, y]
    for x in range(width):
        out[x] = _short(h_row[x], history_threshold)
    for s in range(1, num_signals):
        h_row = history_length[s, y]
        for x in range(width):
            out[x] |= _short(h_row[x], history_threshold)
    largest = np.uint8(0)
    for x in range(width):
        largest = max(largest, out[x])
    return largest != 0


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def spatial_variance(
    illumination: np.ndarray,
    moments: np.ndarray,
    history_length: np.ndarray,
    mode: np.ndarray,
    depth: np.ndarray,
    ddx: np.ndarray,
    ddy: np.ndarray,
    normal: np.ndarray,
    history_threshold: np.float32,
    radius: int,
    sigma_depth: np.float32,
    sigma_luminance: np.float32,
    squarings: int,
    sigma_normal: np.float32,
    blur_color: bool,
    out_variance: np.ndarray,
    out_illumination: np.ndarray,
) -> None:
    """Unboosted edge-aware spatial variance of the signals with ``0 < h < threshold``.

    Per signal ``s`` (own history length ``history_length[s]`` and mode, bit ``s`` of the
    (H, W) uint16 ``mode`` mask), weights:
    box kernel over (2*radius+1)^2 taps times ``w_n * exp(-depth term - |m1(p) - m1(q)| /
    (sigma_luminance * (|m1(p)| + |m1(q)|) / 2))``, and 0 between pixels of different modes.
    The luminance stop is relative to the pair's mean luminance, so it is as weak at every
    brightness as Falcor's absolute ``exp(-|dl| / 10)`` is at luminance ~1 (absolute, it
    underestimated the variance ~2x at mean luminance 10 and ~50x at 100); it is deliberately
    weak because it is not scaled by a variance (that is what is being estimated). Other
    pixels of ``out_variance`` (S, H, W) are not touched. With ``blur_color`` the weighted
    mean illumination is written to ``out_illumination`` for the same pixels (Falcor).
    """
    height, width = depth.shape
    for y in prange(height):
        # Runs of pixels where some signal needs the estimate (disocclusions: thin slivers
        # along silhouettes, ~0.3% of a moving 1080p frame). Runs closer than RUN_GAP merge,
        # so a sliver costs one short vector loop and the pixels between runs cost nothing.
        needed = np.empty(width, dtype=np.uint8)
        if not _needed_row(history_length, y, history_threshold, needed):
            continue
        x = 0
        while x < width:
            while x < width and not needed[x]:
                x += 1
            if x >= width:
                break
            first = x
            last = x
            while x < width and x - last <= RUN_GAP:
                if needed[x]:
                    last = x
                x += 1
            x = last + 1
            _spatial_variance_run(
                np.int64(y), first, last, illumination, moments, history_length, mode, depth,
                ddx, ddy, normal, history_threshold, radius, sigma_depth, sigma_luminance,
                squarings, sigma_normal, blur_color, out_variance, out_illumination,
            )


@njit(fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy")
def _spatial_variance_run(
    y: int,
    first: int,
    last: int,
    illumination: np.ndarray,
    moments: np.ndarray,
    history_length: np.ndarray,
    mode: np.ndarray,
    depth: np.ndarray,
    ddx: np.ndarray,
    ddy: np.ndarray,
    normal: np.ndarray,
    history_threshold: np.float32,
    radius: int,
    sigma_depth: np.float32,
    sigma_luminance: np.float32,
    squarings: int,
    sigma_normal: np.float32,
    blur_color: bool,
    out_variance: np.ndarray,
    out_illumination: np.ndarray,
) -> None:
    """:func:`spatial_variance` for the pixels of row ``y`` in ``[first, last]`` that need it."""
    num_signals = moments.shape[0]
    height, width = depth.shape
    half_sigma = _HALF * sigma_luminance
    run = last + 1 - first
    # Per signal: sum w, sum w^2, sum w*m1, sum w*m2, sum w*rgb.
    acc = np.zeros((num_signals, 7, run), dtype=np.float32)
    depth_exponent = np.empty(run, dtype=np.float32)
    normal_weight = np.empty(run, dtype=np.float32)
    tap_weight = np.empty(run, dtype=np.float32)
    for oy in range(-radius, radius + 1):
        yy = y + oy
        if yy < 0 or yy >= height:
            continue
        for ox in range(-radius, radius + 1):
            x0 = max(first, -ox)
            x1 = min(last + 1, width - ox)
            count = x1 - x0
            if count <= 0:
                continue
            a = x0 - first
            tap_geometry(
                depth[y, x0:x1], ddx[y, x0:x1], ddy[y, x0:x1],
                normal[0, y, x0:x1], normal[1, y, x0:x1], normal[2, y, x0:x1],
                depth[yy, x0 + ox:x1 + ox],
                normal[0, yy, x0 + ox:x1 + ox], normal[1, yy, x0 + ox:x1 + ox],
                normal[2, yy, x0 + ox:x1 + ox],
                F32(ox), F32(oy), sigma_depth, squarings, sigma_normal, _ONE,
                depth_exponent, normal_weight, count,
            )
            if ox == 0 and oy == 0:
                # The centre always counts fully, also where its normal is degenerate.
                for i in range(count):
                    depth_exponent[i] = _ZERO
                    normal_weight[i] = _ONE
            for s in range(num_signals):
                m1_p = moments[s, 0, y, x0:x1]
                m1_q = moments[s, 0, yy, x0 + ox:x1 + ox]
                m2_q = moments[s, 1, yy, x0 + ox:x1 + ox]
                mode_p = mode[y, x0:x1]
                mode_q = mode[yy, x0 + ox:x1 + ox]
                bit = np.uint16(1 << s)
                sum_w = acc[s, 0, a:a + count]
                sum_w2 = acc[s, 1, a:a + count]
                sum_m1 = acc[s, 2, a:a + count]
                sum_m2 = acc[s, 3, a:a + count]
                for i in range(count):
                    scale = half_sigma * (abs(m1_p[i]) + abs(m1_q[i])) + _TINY
                    w = normal_weight[i] * fast_exp(
                        -(depth_exponent[i] + abs(m1_p[i] - m1_q[i]) / scale)
                    )
                    w = w if (mode_p[i] ^ mode_q[i]) & bit == 0 else _ZERO
                    tap_weight[i] = w
                    sum_w[i] += w
                    sum_w2[i] += w * w
                    sum_m1[i] += w * m1_q[i]
                    sum_m2[i] += w * m2_q[i]
                if blur_color:
                    r_q = illumination[s, 0, yy, x0 + ox:x1 + ox]
                    g_q = illumination[s, 1, yy, x0 + ox:x1 + ox]
                    b_q = illumination[s, 2, yy, x0 + ox:x1 + ox]
                    sum_r = acc[s, 4, a:a + count]
                    sum_g = acc[s, 5, a:a + count]
                    sum_b = acc[s, 6, a:a + count]
                    for i in range(count):
                        w = tap_weight[i]
                        sum_r[i] += w * r_q[i]
                        sum_g[i] += w * g_q[i]
                        sum_b[i] += w * b_q[i]
    for x in range(first, last + 1):
        i = x - first
        for s in range(num_signals):
            h = history_length[s, y, x]
            if not _short(h, history_threshold):
                continue
            sum_w = acc[s, 0, i]
            inv = _ONE / sum_w
            mean1 = acc[s, 2, i] * inv
            mean2 = acc[s, 3, i] * inv
            population = max(mean2 - mean1 * mean1, _ZERO)
            # Reliability-weights correction; h-frame averages have 1/h of the spread.
            shrink = acc[s, 1, i] * inv * inv / max(h, _ONE)
            if shrink < _ONE:
                population /= _ONE - shrink
            out_variance[s, y, x] = population
            if blur_color:
                out_illumination[s, 0, y, x] = acc[s, 4, i] * inv
                out_illumination[s, 1, y, x] = acc[s, 5, i] * inv
                out_illumination[s, 2, y, x] = acc[s, 6, i] * inv


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def boost_short_history(
    variance: np.ndarray, history_length: np.ndarray, history_threshold: np.float32
) -> None:
    """In place, per signal: ``Var *= threshold / h`` where ``0 < h < threshold`` (Falcor's
    4/h). ``variance`` and ``history_length`` are (S, H, W)."""
    num_signals, height, width = history_length.shape
    for y in prange(height):
        for s in range(num_signals):
            h_row = history_length[s, y]
            v_row = variance[s, y]
            for x in range(width):
                h = h_row[x]
                if _short(h, history_threshold):
                    v_row[x] *= history_threshold / h


def estimate_variance(
    illumination: np.ndarray,
    moments: np.ndarray,
    history_length: np.ndarray,
    mode: np.ndarray,
    depth: np.ndarray,
    ddx: np.ndarray,
    ddy: np.ndarray,
    normal: np.ndarray,
    *,
    history_threshold: float,
    radius: int,
    sigma_depth: float,
    sigma_luminance: float,
    squarings: int,
    sigma_normal: float,
    out_variance: np.ndarray,
    out_illumination: np.ndarray | None = None,
) -> None:
    """Paper 4.2 as a whole: temporal variance, spatial estimate + boost for short history.

    ``history_length`` is (S, H, W) and ``mode`` the (H, W) mode mask: each signal
    decides by its own history length, and pixels of different modes never mix. With
    ``out_illumination`` (Falcor's colour blur) it receives ``illumination`` with the
    short-history pixels replaced by their spatially filtered colour.
    """
    temporal_variance(moments, out_variance)
    blur_color = out_illumination is not None
    if blur_color:
        np.copyto(out_illumination, illumination)
    if history_threshold <= 1.0:
        return
    threshold = F32(history_threshold)
    spatial_variance(
        illumination, moments, history_length, mode, depth, ddx, ddy, normal, threshold,
        radius, F32(sigma_depth), F32(sigma_luminance), squarings, F32(sigma_normal),
        blur_color, out_variance, out_illumination if blur_color else illumination,
    )
    boost_short_history(out_variance, history_length, threshold)
