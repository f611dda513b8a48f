"""Edge-avoiding a-trous wavelet filter (paper section 4.3, equations 1-5).

One iteration at step ``s`` (1, 2, 4, ...) filters every signal with the 5x5 B3-spline
kernel ``h = (1/16, 1/4, 3/8, 1/4, 1/16)`` dilated by ``s``, each tap weighted by
``w = w_z * w_n * w_l``:

* ``w_z = exp(-|z(p) - z(q)| / (sigma_z |grad z(p) . (p - q)| + eps))``  (eq. 3)
* ``w_n = max(0, n(p) . n(q)) ** sigma_n``                                (eq. 4)
* ``w_l = exp(-|l(p) - l(q)| / (sigma_l sqrt(g3x3(Var(l(p))) + (eps l(p))^2)))``  (eq. 5)
* ``w = 0`` between pixels of different demodulation modes (``filters.modulate``)

A symmetric signal (``mixed_symmetric_stop``) divides eq. 5's luminance difference by the
geometric mean of the two pixels' deviations instead of the centre's alone, so ``w_l(p, q)
= w_l(q, p)``.

``c' = sum(h w c) / sum(h w)`` (eq. 1) and the variance is carried with squared weights,
``Var' = sum(h^2 w^2 Var) / (sum h w)^2`` (eq. 2). ``g3x3`` is the 3x3 Gaussian (1/4 centre,
1/8 edge, 1/16 corner), renormalised over in-image surface pixels; it only drives w_l. The
luminance ``l`` uses the frame's luminance weights; ``eps = 1e-5`` keeps a zero variance
from making the stop infinitely strict, relative to ``l`` so that scaling the input scales
the output (the paper's absolute epsilon would not).

How it is fast: the kernel is register-blocked. For one kernel row (a fixed vertical offset)
a single vectorized loop over pixels evaluates that row's five taps with the running sums in
registers, so each centre pixel's guides and sums are loaded and stored once per kernel row,
not once per tap. The signals of a group (two or three) share ``h * w_n`` and the w_z
exponent; each signal then pays one fast polynomial exp, and its mode test is a sign compare
of the guide it loads anyway. Three signals have their own loop body: a third signal costs
far less in the same pass than filtered alone (nearly a whole pair). Taps that fall outside
the image are given weight 0 and the centre pixel's address, so the image border runs the
same vector loop as the interior.
The loop touches ~35 arrays; :func:`noalias_njit` tells LLVM the written ones never overlap
the read ones, which it cannot check cheaply at run time.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import get_num_threads, njit, prange

from svgf_cli.filters.edges import DEPTH_EPSILON, DEPTH_TINY
from svgf_cli.filters.fastmath import (
    FASTMATH,
    fast_exp,
    fast_log2,
    float32_weights,
    fma,
    luminance,
)
from svgf_cli.filters.noalias import check_disjoint, noalias_njit
from svgf_cli.filters.rows import balanced_row, balanced_row_count

F32 = np.float32
U = np.uint64  # unsigned indices: numba adds no negative-index wrap-around, loops vectorize
_ZERO = F32(0.0)
_ONE = F32(1.0)
# The luminance stop's deviation is at least this fraction of the pixel's luminance (so a
# zero variance never makes the stop infinitely strict, at any brightness) ...
RELATIVE_DEVIATION_FLOOR = F32(1e-5)
# ... and at least this (absolute; only black pixels reach it). Keeps 1/scale below 1e20, so
# |dl| * 1/scale stays finite for every |l| <= 2 * VALUE_LIMIT.
_MIN_SCALE = F32(1e-20)
# Radiance-mode guides are -(l + _MODE_OFFSET): strictly negative, so the sign is the mode.
_MODE_OFFSET = F32(1e-30)
_TINY_COSINE = F32(1e-30)
_LN2 = 0.6931471805599453  # sigma_n * ln 2 is formed once per call
# Pixels per row chunk: the accumulators and the touched row pieces stay in L1/L2.
CHUNK = 256
_B3 = np.array([1.0 / 16.0, 1.0 / 4.0, 3.0 / 8.0, 1.0 / 4.0, 1.0 / 16.0], dtype=np.float32)
# g3x3 weights are the outer product of (1/4, 1/2, 1/4): 1/16 corner, 1/8 edge, 1/4 centre.
_G1 = np.array([0.25, 0.5, 0.25], dtype=np.float32)

_JIT = dict(fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy")


def luminance_stop_guides(
    illumination: np.ndarray,
    variance: np.ndarray,
    mode: np.ndarray,
    first_signal: int,
    depth: np.ndarray,
    sigma_luminance: float | Sequence[float],
    luminance_weights: tuple[np.float32, np.float32, np.float32],
    out_luminance: np.ndarray,
    out_inverse_scale: np.ndarray,
    blur: bool = False,
    symmetric: bool | Sequence[bool] = False,
) -> None:
    """Per pixel and signal: the guide luminance and the inverse scale of eq. 5.

    ``l = max(0, luminance(c))`` with the frame's ``luminance_weights``; the guide is ``l``
    where the signal is demodulated and ``-(l + 1e-30)`` where it is filtered as radiance
    (bit ``first_signal + s`` of the (H, W) uint16 ``mode`` mask), so the a-trous reads the
    mode of a tap from the sign of the guide it loads anyway.
    ``1 / max(sigma_l sqrt(g3x3(Var) + (1e-5 l)^2), 1e-20)``: the floor on the deviation
    is relative to the luminance, so the stop does not depend on the brightness (the
    absolute 1e-20 only matters on black pixels and keeps every product finite). The 3x3
    Gaussian is renormalised over in-image surface pixels (background variance is
    meaningless); a pixel without any such neighbour keeps its own variance.
    ``S`` is 1 to 3 signals; ``sigma_luminance`` is one sigma_l for all or one per signal.
    ``blur``: the guide is ``g3x3(l)`` instead, the same Gaussian renormalised over the
    in-image surface pixels of the pixel's own mode (a pixel with none keeps ``l``). A
    one-sample ``l`` in the stop weighs each tap by its own noise: bright samples count
    less than dark ones, and the filter darkens (``luminance_guide_blur``).
    ``symmetric`` (one for all or one per signal): such a signal's plane holds
    ``-sqrt(inverse scale)``, and the a-trous stops a tap at the product of the two
    pixels' roots, the inverse of the geometric mean of their deviations
    (``mixed_symmetric_stop``; a positive value is the centre's own, eq. 5 as published).
    Outputs must not overlap the inputs (checked).
    """
    num_signals = illumination.shape[0]
    if num_signals not in (1, 2, 3):
        raise ValueError("luminance_stop_guides takes one to three signals")
    # Writable arrays always (a read-only view is another numba signature: another compile).
    sigmas = np.empty(num_signals, dtype=F32)
    sigmas[:] = sigma_luminance
    check_disjoint(
        {"out_luminance": out_luminance, "out_inverse_scale": out_inverse_scale},
        {"illumination": illumination, "variance": variance, "mode": mode, "depth": depth},
    )
    roots = np.empty(num_signals, dtype=np.bool_)
    roots[:] = symmetric
    _guide_rows(illumination, variance, mode, np.int64(first_signal), depth, sigmas,
                float32_weights(luminance_weights), out_luminance, out_inverse_scale,
                bool(blur), roots, np.int64(get_num_threads()))


@njit(parallel=True, **_JIT)
def _guide_rows(
    illumination: np.ndarray,
    variance: np.ndarray,
    mode: np.ndarray,
    first_signal: int,
    depth: np.ndarray,
    sigma_luminance: np.ndarray,
    luminance_weights: tuple[np.float32, np.float32, np.float32],
    out_luminance: np.ndarray,
    out_inverse_scale: np.ndarray,
    blur: bool,
    symmetric: np.ndarray,
    threads: int,
) -> None:
    """All rows of :func:`luminance_stop_guides` in parallel."""
    height, width = depth.shape
    for i in prange(balanced_row_count(height, threads)):
        y = balanced_row(i, height, threads)
        if y >= height:
            continue
        # Surface weight, then the weighted variance sums of the signals.
        sums = np.empty((4, width), dtype=np.float32)
        # Each signal's guide luminance on row y (blurred or not).
        guide = np.empty((illumination.shape[0], width), dtype=np.float32)
        _luminance_row(y, sums, illumination, mode, first_signal, depth, luminance_weights,
                       blur, guide)
        _guide_row(y, sums, variance, mode, first_signal, depth, sigma_luminance, guide,
                   symmetric, out_luminance, out_inverse_scale)


@noalias_njit(**_JIT)
def _luminance_row(
    y: int,
    sums: np.ndarray,
    illumination: np.ndarray,
    mode: np.ndarray,
    first_signal: int,
    depth: np.ndarray,
    luminance_weights: tuple[np.float32, np.float32, np.float32],
    blur: bool,
    guide: np.ndarray,
) -> None:
    """Row ``y`` of each signal's ``max(0, l)``, or with ``blur`` its 3x3 Gaussian over the
    in-image surface pixels of the centre's mode (``sums[0:3]`` as scratch)."""
    height, width = depth.shape
    uy = U(y)
    for s in range(illumination.shape[0]):
        _row_luminance(illumination[s], uy, luminance_weights, guide[s])
        if not blur:
            continue
        bit = first_signal + s
        for i in range(width):
            sums[0, i] = _ZERO
            sums[1, i] = _ZERO
        for dy in range(-1, 2):
            yy = y + dy
            if yy < 0 or yy >= height:
                continue
            uq = U(yy)
            # Row yy's luminance, once for its three taps (row y's is the guide's own).
            row = guide[s]
            if dy != 0:
                row = sums[2]
                _row_luminance(illumination[s], uq, luminance_weights, row)
            for dx in range(-1, 2):
                k = _G1[dx + 1] * _G1[dy + 1]
                # The taps inside the image: x + dx in [0, width).
                start = max(0, -dx)
                stop = min(width, width - dx)
                for i in range(max(0, stop - start)):
                    x = U(start + i)
                    q = U(start + i + dx)
                    same = ((mode[uq, q] ^ mode[uy, x]) >> bit) & 1 == 0
                    w = k if depth[uq, q] > _ZERO and same else _ZERO
                    sums[0, x] += w
                    sums[1, x] = fma(w, row[q], sums[1, x])
        for i in range(width):
            if sums[0, i] > _ZERO:
                guide[s, i] = sums[1, i] / sums[0, i]


@noalias_njit(**_JIT)
def _row_luminance(
    illumination: np.ndarray,
    y: np.uint64,
    luminance_weights: tuple[np.float32, np.float32, np.float32],
    out: np.ndarray,
) -> None:
    """``out[x] = max(0, l)`` of row ``y`` of one signal's (3, H, W) ``illumination``."""
    for i in range(out.shape[0]):
        x = U(i)
        out[x] = max(luminance(illumination[0, y, x], illumination[1, y, x],
                               illumination[2, y, x], luminance_weights), _ZERO)


@noalias_njit(**_JIT)
def _guide_row(
    y: int,
    sums: np.ndarray,
    variance: np.ndarray,
    mode: np.ndarray,
    first_signal: int,
    depth: np.ndarray,
    sigma_luminance: np.ndarray,
    guide: np.ndarray,
    symmetric: np.ndarray,
    out_luminance: np.ndarray,
    out_inverse_scale: np.ndarray,
) -> None:
    """Row ``y``: the three taps of each 3x3 kernel row in one loop (as in the a-trous),
    with the row's ``guide`` luminance per signal (a ``symmetric`` signal's inverse scale
    written as its negated square root).

    One or two signals fill ``sums[1]`` and ``sums[2]`` (a single signal twice), a third
    also ``sums[3]``.
    """
    num_signals = variance.shape[0]
    second = min(num_signals, 2) - 1
    three = num_signals == 3
    height, width = depth.shape
    for i in range(width):
        sums[0, i] = _ZERO
        sums[1, i] = _ZERO
        sums[2, i] = _ZERO
        sums[3, i] = _ZERO
    for dy in range(-1, 2):
        yy = y + dy
        if yy < 0 or yy >= height:
            continue
        uq = U(yy)
        # Between the cuts at x = 1 and x = w - 1 the left and right taps are either inside
        # the image or not; outside ones read the centre with weight 0.
        cut_low = min(1, width)
        cut_high = max(cut_low, width - 1)
        for segment in range(3):
            start = 0 if segment == 0 else (cut_low if segment == 1 else cut_high)
            stop = cut_low if segment == 0 else (cut_high if segment == 1 else width)
            if stop <= start:
                continue
            left = -1 if start >= 1 else 0
            right = 1 if stop < width else 0
            k_left = _G1[0] * _G1[dy + 1] if left != 0 else _ZERO
            k_centre = _G1[1] * _G1[dy + 1]
            k_right = _G1[2] * _G1[dy + 1] if right != 0 else _ZERO
            for i in range(stop - start):
                x = start + i
                q0 = U(x + left)
                q1 = U(x)
                q2 = U(x + right)
                s0 = k_left if depth[uq, q0] > _ZERO else _ZERO
                s1 = k_centre if depth[uq, q1] > _ZERO else _ZERO
                s2 = k_right if depth[uq, q2] > _ZERO else _ZERO
                sums[0, q1] += s0 + s1 + s2
                sums[1, q1] += fma(s0, variance[0, uq, q0], fma(
                    s1, variance[0, uq, q1], s2 * variance[0, uq, q2]))
                sums[2, q1] += fma(s0, variance[second, uq, q0], fma(
                    s1, variance[second, uq, q1], s2 * variance[second, uq, q2]))
                if three:
                    sums[3, q1] += fma(s0, variance[2, uq, q0], fma(
                        s1, variance[2, uq, q1], s2 * variance[2, uq, q2]))
    uy = U(y)
    for s in range(num_signals):
        sigma = sigma_luminance[s]
        for i in range(width):
            x = U(i)
            lum = guide[s, x]
            radiance_mode = (mode[uy, x] >> (first_signal + s)) & 1 != 0
            out_luminance[s, uy, x] = -(lum + _MODE_OFFSET) if radiance_mode else lum
            weight = sums[0, x]
            own = variance[s, uy, x]
            filtered = sums[1 + s, x] / weight if weight > _ZERO else own
            floor = RELATIVE_DEVIATION_FLOOR * lum
            scale = sigma * np.sqrt(max(filtered, _ZERO) + floor * floor)
            out_inverse_scale[s, uy, x] = _ONE / max(scale, _MIN_SCALE)
        if symmetric[s]:
            row = out_inverse_scale[s, uy]
            for i in range(width):
                row[i] = -np.sqrt(row[i])


def zero_signals(illumination: np.ndarray, variance: np.ndarray) -> np.ndarray:
    """Per signal of (S, 3, H, W) ``illumination`` and (S, H, W) ``variance``: whether both
    are +0.0 on every pixel (every bit 0; -0.0 does not count).

    Such a signal needs no a-trous: its weights are non-negative and finite (wherever the
    geometry is, as every other signal's output needs), so each sum of eqs. 1-2 is +0 and
    so is every iteration's output. The scan stops at the first row that is not zero (a
    lit signal costs its leading black rows).
    """
    width = illumination.shape[-1]
    zero = np.zeros(illumination.shape[0], dtype=bool)
    for s in range(illumination.shape[0]):
        zero[s] = (_zero_bits(illumination[s].view(np.uint32).reshape(-1, width))
                   and _zero_bits(variance[s].view(np.uint32).reshape(-1, width)))
    return zero


@njit(**_JIT)
def _zero_bits(rows: np.ndarray) -> bool:
    """True where every element of the (R, W) uint32 ``rows`` is 0, row by row."""
    for r in range(rows.shape[0]):
        bits = np.uint32(0)
        for x in range(rows.shape[1]):
            bits |= rows[r, x]
        if bits != 0:
            return False
    return True


def atrous_iteration(
    illumination: np.ndarray,
    variance: np.ndarray,
    guide_luminance: np.ndarray,
    guide_inverse_scale: np.ndarray,
    depth: np.ndarray,
    ddx: np.ndarray,
    ddy: np.ndarray,
    normal: np.ndarray,
    step: int,
    sigma_depth: float,
    sigma_normal: float,
    propagate_variance: bool,
    out_illumination: np.ndarray,
    out_variance: np.ndarray,
) -> None:
    """One a-trous iteration at ``step`` over (S, 3, H, W) illumination and (S, H, W) variance.

    ``S`` is 1 to 3 signals (the Denoiser filters its signals in groups of two or three,
    which share the geometric weights). ``guide_*`` come
    from :func:`luminance_stop_guides` for the same input: a tap whose guide has another
    sign than the centre's (another demodulation mode) gets weight 0 for that signal.
    Background pixels (zero normal) receive no weight from surfaces and pass through
    unchanged. Without
    ``propagate_variance`` (the last iteration: nothing reads its variance) ``out_variance``
    is not touched. Outputs must not overlap any input (checked).
    """
    num_signals = illumination.shape[0]
    if num_signals not in (1, 2, 3):
        raise ValueError("atrous_iteration filters one to three signals")
    written = {"out_illumination": out_illumination}
    if propagate_variance:
        written["out_variance"] = out_variance
    check_disjoint(written, {
        "illumination": illumination, "variance": variance, "guide_luminance": guide_luminance,
        "guide_inverse_scale": guide_inverse_scale, "depth": depth, "ddx": ddx, "ddy": ddy,
        "normal": normal,
    })
    _atrous_rows(
        illumination, variance, guide_luminance, guide_inverse_scale, depth, ddx, ddy, normal,
        np.int64(step), F32(sigma_depth), F32(sigma_normal * _LN2), bool(propagate_variance),
        out_illumination, out_variance, np.int64(get_num_threads()),
    )


@njit(parallel=True, **_JIT)
def _atrous_rows(
    illumination: np.ndarray,
    variance: np.ndarray,
    guide_luminance: np.ndarray,
    guide_inverse_scale: np.ndarray,
    depth: np.ndarray,
    ddx: np.ndarray,
    ddy: np.ndarray,
    normal: np.ndarray,
    step: int,
    sigma_depth: np.float32,
    normal_log_scale: np.float32,
    propagate_variance: bool,
    out_illumination: np.ndarray,
    out_variance: np.ndarray,
    threads: int,
) -> None:
    """All rows of :func:`atrous_iteration` in parallel, one scratch block per row.

    ``normal_log_scale`` is ``sigma_n ln 2`` (so ``w_n = exp(normal_log_scale log2(cos))``),
    multiplied once here rather than once per tap.
    """
    height = depth.shape[0]
    for i in prange(balanced_row_count(height, threads)):
        y = balanced_row(i, height, threads)
        if y >= height:
            continue
        # Per signal: sum w, sum w r, sum w g, sum w b, sum w^2 Var.
        sums = np.empty((3, 5, CHUNK), dtype=np.float32)
        if illumination.shape[0] == 3:
            _atrous_row3(
                y, sums, illumination, variance, guide_luminance, guide_inverse_scale,
                depth, ddx, ddy, normal, step, sigma_depth, normal_log_scale,
                propagate_variance, out_illumination, out_variance,
            )
        else:
            _atrous_row(
                y, sums, illumination, variance, guide_luminance, guide_inverse_scale,
                depth, ddx, ddy, normal, step, sigma_depth, normal_log_scale,
                propagate_variance, out_illumination, out_variance,
            )


@noalias_njit(**_JIT)
def _atrous_row(
    y: int,
    sums: np.ndarray,
    illumination: np.ndarray,
    variance: np.ndarray,
    guide_luminance: np.ndarray,
    guide_inverse_scale: np.ndarray,
    depth: np.ndarray,
    ddx: np.ndarray,
    ddy: np.ndarray,
    normal: np.ndarray,
    step: int,
    sigma_depth: np.float32,
    normal_log_scale: np.float32,
    propagate_variance: bool,
    out_illumination: np.ndarray,
    out_variance: np.ndarray,
) -> None:
    """Row ``y``: chunks of ``CHUNK`` pixels, kernel rows, then per-tap-validity segments.

    The loop always filters two signals. A single signal is read as both (``second`` = 0);
    the duplicate sums are identical and discarded. One compiled loop body instead of two
    (or four with numba flag specialisations) keeps compile time and code paths down.
    Three signals have a row function of their own, :func:`_atrous_row3`, the same steps
    around the triple loop body: one function holding both bodies measured ~5% slower for
    pairs, and the shared steps factored into inlined helpers ~8% slower for triples.
    """
    num_signals = illumination.shape[0]
    second = num_signals - 1
    height, width = depth.shape
    # Only the span between the first and last surface pixel of the row is filtered;
    # background outside it passes through (sky rows cost nothing).
    z_row = depth[y]
    first = 0
    while first < width and z_row[first] <= _ZERO:
        first += 1
    last = width
    while last > first and z_row[last - 1] <= _ZERO:
        last -= 1
    for s in range(num_signals):
        for x in range(0, first):
            for c in range(3):
                out_illumination[s, c, y, x] = illumination[s, c, y, x]
        for x in range(last, width):
            for c in range(3):
                out_illumination[s, c, y, x] = illumination[s, c, y, x]
        if propagate_variance:
            for x in range(0, first):
                out_variance[s, y, x] = variance[s, y, x]
            for x in range(last, width):
                out_variance[s, y, x] = variance[s, y, x]
    centre = _B3[2] * _B3[2]
    bounds = np.empty(6, dtype=np.int64)
    offsets = np.empty(5, dtype=np.int64)
    kernel = np.empty(5, dtype=np.float32)
    for chunk_start in range(first, last, CHUNK):
        chunk_end = min(last, chunk_start + CHUNK)
        for t in range(2):
            s = t * second
            for i in range(chunk_end - chunk_start):
                x = U(chunk_start + i)
                sums[t, 0, i] = centre
                sums[t, 1, i] = centre * illumination[s, 0, y, x]
                sums[t, 2, i] = centre * illumination[s, 1, y, x]
                sums[t, 3, i] = centre * illumination[s, 2, y, x]
                sums[t, 4, i] = (centre * centre) * variance[s, y, x]
        # Tap validity changes at x = s, 2s, w - 2s and w - s (in any order when w < 4s);
        # between consecutive bounds every tap is either inside the image or not.
        bounds[0] = chunk_start
        bounds[1] = step
        bounds[2] = 2 * step
        bounds[3] = width - 2 * step
        bounds[4] = width - step
        bounds[5] = chunk_end
        for i in range(1, 5):
            bounds[i] = min(max(bounds[i], chunk_start), chunk_end)
        bounds[1:5].sort()
        for oy in range(-2, 3):
            yy = y + oy * step
            if yy < 0 or yy >= height:
                continue
            for segment in range(5):
                start = bounds[segment]
                count = bounds[segment + 1] - start
                if count <= 0:
                    continue
                for k in range(5):
                    offset = (k - 2) * step
                    inside = start + offset >= 0 and start + count - 1 + offset < width
                    # Outside taps (and the centre, already in the sums) read the centre
                    # pixel with weight 0: same loop, no branch, nothing added.
                    offsets[k] = offset if inside else 0
                    real = inside and not (oy == 0 and k == 2)
                    kernel[k] = _B3[k] * _B3[oy + 2] if real else _ZERO
                _segment(
                    sums, illumination, variance, guide_luminance, guide_inverse_scale, depth,
                    ddx, ddy, normal, y, yy, start, count, start - chunk_start, step, oy,
                    offsets, kernel, sigma_depth, normal_log_scale, second,
                )
        for s in range(num_signals):
            for i in range(chunk_end - chunk_start):
                x = U(chunk_start + i)
                inverse = _ONE / sums[s, 0, i]
                out_illumination[s, 0, y, x] = sums[s, 1, i] * inverse
                out_illumination[s, 1, y, x] = sums[s, 2, i] * inverse
                out_illumination[s, 2, y, x] = sums[s, 3, i] * inverse
            if propagate_variance:
                for i in range(chunk_end - chunk_start):
                    x = U(chunk_start + i)
                    inverse = _ONE / sums[s, 0, i]
                    out_variance[s, y, x] = sums[s, 4, i] * (inverse * inverse)



@noalias_njit(**_JIT)
def _atrous_row3(
    y: int,
    sums: np.ndarray,
    illumination: np.ndarray,
    variance: np.ndarray,
    guide_luminance: np.ndarray,
    guide_inverse_scale: np.ndarray,
    depth: np.ndarray,
    ddx: np.ndarray,
    ddy: np.ndarray,
    normal: np.ndarray,
    step: int,
    sigma_depth: np.float32,
    normal_log_scale: np.float32,
    propagate_variance: bool,
    out_illumination: np.ndarray,
    out_variance: np.ndarray,
) -> None:
    """:func:`_atrous_row` for three signals (the loop body :func:`_segment3`); keep the
    two in step."""
    num_signals = illumination.shape[0]
    height, width = depth.shape
    # Only the span between the first and last surface pixel of the row is filtered;
    # background outside it passes through (sky rows cost nothing).
    z_row = depth[y]
    first = 0
    while first < width and z_row[first] <= _ZERO:
        first += 1
    last = width
    while last > first and z_row[last - 1] <= _ZERO:
        last -= 1
    for s in range(num_signals):
        for x in range(0, first):
            for c in range(3):
                out_illumination[s, c, y, x] = illumination[s, c, y, x]
        for x in range(last, width):
            for c in range(3):
                out_illumination[s, c, y, x] = illumination[s, c, y, x]
        if propagate_variance:
            for x in range(0, first):
                out_variance[s, y, x] = variance[s, y, x]
            for x in range(last, width):
                out_variance[s, y, x] = variance[s, y, x]
    centre = _B3[2] * _B3[2]
    bounds = np.empty(6, dtype=np.int64)
    offsets = np.empty(5, dtype=np.int64)
    kernel = np.empty(5, dtype=np.float32)
    for chunk_start in range(first, last, CHUNK):
        chunk_end = min(last, chunk_start + CHUNK)
        for s in range(3):
            for i in range(chunk_end - chunk_start):
                x = U(chunk_start + i)
                sums[s, 0, i] = centre
                sums[s, 1, i] = centre * illumination[s, 0, y, x]
                sums[s, 2, i] = centre * illumination[s, 1, y, x]
                sums[s, 3, i] = centre * illumination[s, 2, y, x]
                sums[s, 4, i] = (centre * centre) * variance[s, y, x]
        # Tap validity changes at x = s, 2s, w - 2s and w - s (in any order when w < 4s);
        # between consecutive bounds every tap is either inside the image or not.
        bounds[0] = chunk_start
        bounds[1] = step
        bounds[2] = 2 * step
        bounds[3] = width - 2 * step
        bounds[4] = width - step
        bounds[5] = chunk_end
        for i in range(1, 5):
            bounds[i] = min(max(bounds[i], chunk_start), chunk_end)
        bounds[1:5].sort()
        for oy in range(-2, 3):
            yy = y + oy * step
            if yy < 0 or yy >= height:
                continue
            for segment in range(5):
                start = bounds[segment]
                count = bounds[segment + 1] - start
                if count <= 0:
                    continue
                for k in range(5):
                    offset = (k - 2) * step
                    inside = start + offset >= 0 and start + count - 1 + offset < width
                    # Outside taps (and the centre, already in the sums) read the centre
                    # pixel with weight 0: same loop, no branch, nothing added.
                    offsets[k] = offset if inside else 0
                    real = inside and not (oy == 0 and k == 2)
                    kernel[k] = _B3[k] * _B3[oy + 2] if real else _ZERO
                _segment3(
                    sums, illumination, variance, guide_luminance, guide_inverse_scale, depth,
                    ddx, ddy, normal, y, yy, start, count, start - chunk_start, step, oy,
                    offsets, kernel, sigma_depth, normal_log_scale,
                )
        for s in range(num_signals):
            for i in range(chunk_end - chunk_start):
                x = U(chunk_start + i)
                inverse = _ONE / sums[s, 0, i]
                out_illumination[s, 0, y, x] = sums[s, 1, i] * inverse
                out_illumination[s, 1, y, x] = sums[s, 2, i] * inverse
                out_illumination[s, 2, y, x] = sums[s, 3, i] * inverse
            if propagate_variance:
                for i in range(chunk_end - chunk_start):
                    x = U(chunk_start + i)
                    inverse = _ONE / sums[s, 0, i]
                    out_variance[s, y, x] = sums[s, 4, i] * (inverse * inverse)



@njit(inline="always", **_JIT)
def _segment(
    sums: np.ndarray,
    illumination: np.ndarray,
    variance: np.ndarray,
    guide_luminance: np.ndarray,
    guide_inverse_scale: np.ndarray,
    depth: np.ndarray,
    ddx: np.ndarray,
    ddy: np.ndarray,
    normal: np.ndarray,
    y: int,
    yy: int,
    start: int,
    count: int,
    sums_start: int,
    step: int,
    oy: int,
    offsets: np.ndarray,
    kernel: np.ndarray,
    sigma_depth: np.float32,
    normal_log_scale: np.float32,
    second: int,
) -> None:
    """Add one kernel row's five taps to ``sums`` for ``count`` pixels from ``start``."""
    o0, o1, o2, o3, o4 = offsets[0], offsets[1], offsets[2], offsets[3], offsets[4]
    h0, h1, h2, h3, h4 = kernel[0], kernel[1], kernel[2], kernel[3], kernel[4]
    fy = F32(oy * step)
    f0, f1, f3, f4 = F32(-2 * step), F32(-step), F32(step), F32(2 * step)
    uy = U(y)
    uq = U(yy)
    for i in range(count):
        x = start + i
        px = U(x)
        a = U(sums_start + i)
        zp = depth[uy, px]
        centre = (
            zp, DEPTH_EPSILON * zp + DEPTH_TINY, ddx[uy, px], ddy[uy, px] * fy,
            normal[0, uy, px], normal[1, uy, px], normal[2, uy, px],
            guide_luminance[0, uy, px], guide_inverse_scale[0, uy, px],
            guide_luminance[second, uy, px], guide_inverse_scale[second, uy, px],
        )
        acc = (
            sums[0, 0, a], sums[0, 1, a], sums[0, 2, a], sums[0, 3, a], sums[0, 4, a],
            sums[1, 0, a], sums[1, 1, a], sums[1, 2, a], sums[1, 3, a], sums[1, 4, a],
        )
        acc = _tap(acc, centre, illumination, variance, guide_luminance, guide_inverse_scale,
                   depth, normal, uq,
                   U(x + o0), h0, f0, sigma_depth, normal_log_scale, second)
        acc = _tap(acc, centre, illumination, variance, guide_luminance, guide_inverse_scale,
                   depth, normal, uq,
                   U(x + o1), h1, f1, sigma_depth, normal_log_scale, second)
        acc = _tap(acc, centre, illumination, variance, guide_luminance, guide_inverse_scale,
                   depth, normal, uq,
                   U(x + o2), h2, _ZERO, sigma_depth, normal_log_scale, second)
        acc = _tap(acc, centre, illumination, variance, guide_luminance, guide_inverse_scale,
                   depth, normal, uq,
                   U(x + o3), h3, f3, sigma_depth, normal_log_scale, second)
        acc = _tap(acc, centre, illumination, variance, guide_luminance, guide_inverse_scale,
                   depth, normal, uq,
                   U(x + o4), h4, f4, sigma_depth, normal_log_scale, second)
        sums[0, 0, a], sums[0, 1, a], sums[0, 2, a], sums[0, 3, a], sums[0, 4, a] = acc[:5]
        sums[1, 0, a], sums[1, 1, a], sums[1, 2, a], sums[1, 3, a], sums[1, 4, a] = acc[5:]


@njit(**_JIT)
def _tap(
    acc: tuple,
    centre: tuple,
    illumination: np.ndarray,
    variance: np.ndarray,
    guide_luminance: np.ndarray,
    guide_inverse_scale: np.ndarray,
    depth: np.ndarray,
    normal: np.ndarray,
    uq: np.uint64,
    qx: np.uint64,
    kernel: np.float32,
    offset_x: np.float32,
    sigma_depth: np.float32,
    normal_log_scale: np.float32,
    second: int,
) -> tuple:
    """One tap: eqs. 3-5 for both signals and their weighted sums (eqs. 1-2).

    ``w_n = cos ** sigma_n`` enters as ``sigma_n ln(cos)`` in the one exponent (fast_log2,
    absolute error < 1e-6: relative error ~1e-4 on w_n at sigma_n = 128), branch-free for
    any sigma_n.
    """
    zp, depth_floor, gx, gy, nx, ny, nz, lum0, inv0, lum1, inv1 = centre
    projected = abs(fma(gx, offset_x, gy))
    depth_exponent = abs(zp - depth[uq, qx]) / fma(sigma_depth, projected, depth_floor)
    cosine = fma(nx, normal[0, uq, qx], fma(ny, normal[1, uq, qx], nz * normal[2, uq, qx]))
    # w_n w_z w_l = exp(sigma_n ln(cos) - z term - l term): one exp per signal, the
    # normal power joins the exponent (w_n = 0 where cos <= 0, as max(0, .) gives).
    log_normal = normal_log_scale * fast_log2(max(cosine, _TINY_COSINE))
    shared = log_normal - depth_exponent
    weight = kernel if cosine > _ZERO else _ZERO
    guide0 = guide_luminance[0, uq, qx]
    guide1 = guide_luminance[second, uq, qx]
    # A symmetric signal's (negative) roots: the product of the two pixels'. Loaded for
    # every signal: a load under the condition would keep the loop from vectorizing.
    root0 = guide_inverse_scale[0, uq, qx]
    root1 = guide_inverse_scale[second, uq, qx]
    inv0 = inv0 if inv0 > _ZERO else inv0 * root0
    inv1 = inv1 if inv1 > _ZERO else inv1 * root1
    w0 = weight * fast_exp(shared - abs(lum0 - guide0) * inv0)
    w1 = weight * fast_exp(shared - abs(lum1 - guide1) * inv1)
    # The guide's sign is the demodulation mode: modes never exchange weight.
    w0 = w0 if (guide0 < _ZERO) == (lum0 < _ZERO) else _ZERO
    w1 = w1 if (guide1 < _ZERO) == (lum1 < _ZERO) else _ZERO
    return (
        acc[0] + w0,
        fma(w0, illumination[0, 0, uq, qx], acc[1]),
        fma(w0, illumination[0, 1, uq, qx], acc[2]),
        fma(w0, illumination[0, 2, uq, qx], acc[3]),
        fma(w0 * w0, variance[0, uq, qx], acc[4]),
        acc[5] + w1,
        fma(w1, illumination[second, 0, uq, qx], acc[6]),
        fma(w1, illumination[second, 1, uq, qx], acc[7]),
        fma(w1, illumination[second, 2, uq, qx], acc[8]),
        fma(w1 * w1, variance[second, uq, qx], acc[9]),
    )


@njit(inline="always", **_JIT)
def _segment3(
    sums: np.ndarray,
    illumination: np.ndarray,
    variance: np.ndarray,
    guide_luminance: np.ndarray,
    guide_inverse_scale: np.ndarray,
    depth: np.ndarray,
    ddx: np.ndarray,
    ddy: np.ndarray,
    normal: np.ndarray,
    y: int,
    yy: int,
    start: int,
    count: int,
    sums_start: int,
    step: int,
    oy: int,
    offsets: np.ndarray,
    kernel: np.ndarray,
    sigma_depth: np.float32,
    normal_log_scale: np.float32,
) -> None:
    """:func:`_segment` for three signals: one kernel row's five taps, all three at once."""
    o0, o1, o2, o3, o4 = offsets[0], offsets[1], offsets[2], offsets[3], offsets[4]
    h0, h1, h2, h3, h4 = kernel[0], kernel[1], kernel[2], kernel[3], kernel[4]
    fy = F32(oy * step)
    f0, f1, f3, f4 = F32(-2 * step), F32(-step), F32(step), F32(2 * step)
    uy = U(y)
    uq = U(yy)
    for i in range(count):
        x = start + i
        px = U(x)
        a = U(sums_start + i)
        zp = depth[uy, px]
        centre = (
            zp, DEPTH_EPSILON * zp + DEPTH_TINY, ddx[uy, px], ddy[uy, px] * fy,
            normal[0, uy, px], normal[1, uy, px], normal[2, uy, px],
            guide_luminance[0, uy, px], guide_inverse_scale[0, uy, px],
            guide_luminance[1, uy, px], guide_inverse_scale[1, uy, px],
            guide_luminance[2, uy, px], guide_inverse_scale[2, uy, px],
        )
        acc = (
            sums[0, 0, a], sums[0, 1, a], sums[0, 2, a], sums[0, 3, a], sums[0, 4, a],
            sums[1, 0, a], sums[1, 1, a], sums[1, 2, a], sums[1, 3, a], sums[1, 4, a],
            sums[2, 0, a], sums[2, 1, a], sums[2, 2, a], sums[2, 3, a], sums[2, 4, a],
        )
        acc = _tap3(acc, centre, illumination, variance, guide_luminance, guide_inverse_scale,
                    depth, normal, uq,
                    U(x + o0), h0, f0, sigma_depth, normal_log_scale)
        acc = _tap3(acc, centre, illumination, variance, guide_luminance, guide_inverse_scale,
                    depth, normal, uq,
                    U(x + o1), h1, f1, sigma_depth, normal_log_scale)
        acc = _tap3(acc, centre, illumination, variance, guide_luminance, guide_inverse_scale,
                    depth, normal, uq,
                    U(x + o2), h2, _ZERO, sigma_depth, normal_log_scale)
        acc = _tap3(acc, centre, illumination, variance, guide_luminance, guide_inverse_scale,
                    depth, normal, uq,
                    U(x + o3), h3, f3, sigma_depth, normal_log_scale)
        acc = _tap3(acc, centre, illumination, variance, guide_luminance, guide_inverse_scale,
                    depth, normal, uq,
                    U(x + o4), h4, f4, sigma_depth, normal_log_scale)
        sums[0, 0, a], sums[0, 1, a], sums[0, 2, a], sums[0, 3, a], sums[0, 4, a] = acc[:5]
        sums[1, 0, a], sums[1, 1, a], sums[1, 2, a], sums[1, 3, a], sums[1, 4, a] = acc[5:10]
        sums[2, 0, a], sums[2, 1, a], sums[2, 2, a], sums[2, 3, a], sums[2, 4, a] = acc[10:]


@njit(**_JIT)
def _tap3(
    acc: tuple,
    centre: tuple,
    illumination: np.ndarray,
    variance: np.ndarray,
    guide_luminance: np.ndarray,
    guide_inverse_scale: np.ndarray,
    depth: np.ndarray,
    normal: np.ndarray,
    uq: np.uint64,
    qx: np.uint64,
    kernel: np.float32,
    offset_x: np.float32,
    sigma_depth: np.float32,
    normal_log_scale: np.float32,
) -> tuple:
    """:func:`_tap` for three signals (eqs. 1-5, the same arithmetic per signal)."""
    zp, depth_floor, gx, gy, nx, ny, nz, lum0, inv0, lum1, inv1, lum2, inv2 = centre
    projected = abs(fma(gx, offset_x, gy))
    depth_exponent = abs(zp - depth[uq, qx]) / fma(sigma_depth, projected, depth_floor)
    cosine = fma(nx, normal[0, uq, qx], fma(ny, normal[1, uq, qx], nz * normal[2, uq, qx]))
    log_normal = normal_log_scale * fast_log2(max(cosine, _TINY_COSINE))
    shared = log_normal - depth_exponent
    weight = kernel if cosine > _ZERO else _ZERO
    guide0 = guide_luminance[0, uq, qx]
    guide1 = guide_luminance[1, uq, qx]
    guide2 = guide_luminance[2, uq, qx]
    root0 = guide_inverse_scale[0, uq, qx]
    root1 = guide_inverse_scale[1, uq, qx]
    root2 = guide_inverse_scale[2, uq, qx]
    inv0 = inv0 if inv0 > _ZERO else inv0 * root0
    inv1 = inv1 if inv1 > _ZERO else inv1 * root1
    inv2 = inv2 if inv2 > _ZERO else inv2 * root2
    w0 = weight * fast_exp(shared - abs(lum0 - guide0) * inv0)
    w1 = weight * fast_exp(shared - abs(lum1 - guide1) * inv1)
    w2 = weight * fast_exp(shared - abs(lum2 - guide2) * inv2)
    w0 = w0 if (guide0 < _ZERO) == (lum0 < _ZERO) else _ZERO
    w1 = w1 if (guide1 < _ZERO) == (lum1 < _ZERO) else _ZERO
    w2 = w2 if (guide2 < _ZERO) == (lum2 < _ZERO) else _ZERO
    return (
        acc[0] + w0,
        fma(w0, illumination[0, 0, uq, qx], acc[1]),
        fma(w0, illumination[0, 1, uq, qx], acc[2]),
        fma(w0, illumination[0, 2, uq, qx], acc[3]),
        fma(w0 * w0, variance[0, uq, qx], acc[4]),
        acc[5] + w1,
        fma(w1, illumination[1, 0, uq, qx], acc[6]),
        fma(w1, illumination[1, 1, uq, qx], acc[7]),
        fma(w1, illumination[1, 2, uq, qx], acc[8]),
        fma(w1 * w1, variance[1, uq, qx], acc[9]),
        acc[10] + w2,
        fma(w2, illumination[2, 0, uq, qx], acc[11]),
        fma(w2, illumination[2, 1, uq, qx], acc[12]),
        fma(w2, illumination[2, 2, uq, qx], acc[13]),
        fma(w2 * w2, variance[2, uq, qx], acc[14]),
    )
