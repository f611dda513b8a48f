"""Edge-avoiding a-trous wavelet filter (paper section 4.3, equations 1-5).

One iteration at step ``s`` (1, 2, 4, ...) filters every signal with the 5x5 B3-spline
kernel ``h = (1/16, 1/4, 3/8, 1/4, 1/16)`` dilated by ``s``, each tap weighted by
``w = w_z * w_n * w_l``:

* ``w_z = exp(-|z(p) - z(q)| / (sigma_z |grad z(p) . (p - q)| + eps))``  (eq. 3)
* ``w_n = max(0, n(p) . n(q)) ** sigma_n``                                (eq. 4)
* ``w_l = exp(-|l(p) - l(q)| / (sigma_l sqrt(g3x3(Var(l(p)))) + eps))``  (eq. 5)

``c' = sum(h w c) / sum(h w)`` (eq. 1) and the variance is carried with squared weights,
``Var' = sum(h^2 w^2 Var) / (sum h w)^2`` (eq. 2). ``g3x3`` is the 3x3 Gaussian (1/4 centre,
1/8 edge, 1/16 corner), renormalised over in-image surface pixels; it only drives w_l.

Direct and indirect share the geometry: ``h * w_n`` and the w_z exponent are computed once
per tap and both signals' luminance stops are applied in the same pass (``exp`` of the summed
exponents, one fast polynomial exp per signal and tap).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from svgf_cli.filters.edges import tap_geometry
from svgf_cli.filters.fastmath import FASTMATH, fast_exp, luminance

F32 = np.float32
_ZERO = F32(0.0)
_ONE = F32(1.0)
_VARIANCE_EPSILON = F32(1e-10)
# Pixels per row chunk. Smaller chunks keep the buffers in L1 but pay more per-tap slicing
# overhead; measured here 2048 (a whole 1080p row) was fastest.
CHUNK = 2048
_B3 = np.array([1.0 / 16.0, 1.0 / 4.0, 3.0 / 8.0, 1.0 / 4.0, 1.0 / 16.0], dtype=np.float32)
# g3x3 weights are the outer product of (1/4, 1/2, 1/4): 1/16 corner, 1/8 edge, 1/4 centre.
_G1 = np.array([0.25, 0.5, 0.25], dtype=np.float32)


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def luminance_stop_guides(
    illumination: np.ndarray,
    variance: np.ndarray,
    depth: np.ndarray,
    sigma_luminance: np.float32,
    out_luminance: np.ndarray,
    out_inverse_scale: np.ndarray,
) -> None:
    """Per pixel and signal: ``l(p)`` and ``1 / (sigma_l sqrt(g3x3(Var)) + eps)`` (eq. 5).

    The 3x3 Gaussian is renormalised over in-image surface pixels (background variance is
    meaningless); a pixel without any such neighbour keeps its own variance.
    """
    num_signals = illumination.shape[0]
    height, width = depth.shape
    for y in prange(height):
        total = np.zeros((num_signals, width), dtype=np.float32)
        weight = np.zeros(width, dtype=np.float32)
        surface = np.empty(width, dtype=np.float32)
        for dy in range(-1, 2):
            yy = y + dy
            if yy < 0 or yy >= height:
                continue
            for dx in range(-1, 2):
                x0 = max(0, -dx)
                x1 = min(width, width - dx)
                count = x1 - x0
                k = _G1[dy + 1] * _G1[dx + 1]
                z_q = depth[yy, x0 + dx:x1 + dx]
                w = weight[x0:x1]
                for i in range(count):
                    surface[i] = k if z_q[i] > _ZERO else _ZERO
                    w[i] += surface[i]
                for s in range(num_signals):
                    v_q = variance[s, yy, x0 + dx:x1 + dx]
                    t = total[s, x0:x1]
                    for i in range(count):
                        t[i] += surface[i] * v_q[i]
        for s in range(num_signals):
            r = illumination[s, 0, y]
            g = illumination[s, 1, y]
            b = illumination[s, 2, y]
            lum = out_luminance[s, y]
            for x in range(width):
                lum[x] = luminance(r[x], g[x], b[x])
            own = variance[s, y]
            t = total[s]
            inv_scale = out_inverse_scale[s, y]
            for x in range(width):
                filtered = t[x] / weight[x] if weight[x] > _ZERO else own[x]
                inv_scale[x] = _ONE / (
                    sigma_luminance * np.sqrt(max(filtered, _ZERO) + _VARIANCE_EPSILON)
                )


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
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
    sigma_depth: np.float32,
    squarings: int,
    sigma_normal: np.float32,
    propagate_variance: bool,
    out_illumination: np.ndarray,
    out_variance: np.ndarray,
) -> None:
    """One a-trous iteration at ``step`` over (S, 3, H, W) illumination and (S, H, W) variance.

    ``guide_*`` come from :func:`luminance_stop_guides` for the same input. Background
    pixels (zero normal) receive no weight from surfaces and pass through unchanged.
    Without ``propagate_variance`` (the last iteration: nothing reads its variance)
    ``out_variance`` is not touched and the squared-weight variance sums are skipped.
    Rows are processed in chunks of ``CHUNK`` pixels (bounded scratch memory);
    each inner loop touches few arrays (LLVM gives up vectorizing a loop that would need
    many runtime alias checks).
    """
    for y in prange(depth.shape[0]):
        # np.int64: the parfor index is uint64 in the gufunc but int64 when typed first,
        # which would compile the row function twice.
        _atrous_row(
            np.int64(y), illumination, variance, guide_luminance, guide_inverse_scale, depth,
            ddx, ddy, normal, step, sigma_depth, squarings, sigma_normal, propagate_variance,
            out_illumination, out_variance,
        )


@njit(fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy")
def _atrous_row(
    y: int,
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
    squarings: int,
    sigma_normal: np.float32,
    propagate_variance: bool,
    out_illumination: np.ndarray,
    out_variance: np.ndarray,
) -> None:
    """Row ``y`` of :func:`atrous_iteration` (a plain function so LLVM sees simple loops)."""
    num_signals = illumination.shape[0]
    height, width = depth.shape
    centre = _B3[2] * _B3[2]
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
    if first >= last:
        return
    # Per signal: sum w, sum w r, sum w g, sum w b, sum w^2 Var.
    acc = np.empty((num_signals, 5, CHUNK), dtype=np.float32)
    depth_exponent = np.empty(CHUNK, dtype=np.float32)
    normal_weight = np.empty(CHUNK, dtype=np.float32)
    tap_weight = np.empty(CHUNK, dtype=np.float32)
    for chunk_start in range(first, last, CHUNK):
        chunk_end = min(last, chunk_start + CHUNK)
        n = chunk_end - chunk_start
        for s in range(num_signals):
            sum_w = acc[s, 0]
            sum_r = acc[s, 1]
            sum_g = acc[s, 2]
            sum_b = acc[s, 3]
            r = illumination[s, 0, y, chunk_start:chunk_end]
            g = illumination[s, 1, y, chunk_start:chunk_end]
            b = illumination[s, 2, y, chunk_start:chunk_end]
            for i in range(n):
                sum_w[i] = centre
                sum_r[i] = centre * r[i]
                sum_g[i] = centre * g[i]
                sum_b[i] = centre * b[i]
            if propagate_variance:
                sum_v = acc[s, 4]
                v = variance[s, y, chunk_start:chunk_end]
                for i in range(n):
                    sum_v[i] = (centre * centre) * v[i]
        for oy in range(-2, 3):
            yy = y + oy * step
            if yy < 0 or yy >= height:
                continue
            for ox in range(-2, 3):
                if ox == 0 and oy == 0:
                    continue
                d = ox * step
                x0 = max(chunk_start, -d)
                x1 = min(chunk_end, width - d)
                count = x1 - x0
                if count <= 0:
                    continue
                a0 = x0 - chunk_start
                tap_geometry(
                    depth[y, x0:x1], ddx[y, x0:x1], ddy[y, x0:x1],
                    normal[0, y, x0:x1], normal[1, y, x0:x1], normal[2, y, x0:x1],
                    depth[yy, x0 + d:x1 + d],
                    normal[0, yy, x0 + d:x1 + d], normal[1, yy, x0 + d:x1 + d],
                    normal[2, yy, x0 + d:x1 + d],
                    F32(d), F32(oy * step), sigma_depth, squarings, sigma_normal,
                    _B3[ox + 2] * _B3[oy + 2], depth_exponent, normal_weight, count,
                )
                for s in range(num_signals):
                    l_p = guide_luminance[s, y, x0:x1]
                    inv_p = guide_inverse_scale[s, y, x0:x1]
                    l_q = guide_luminance[s, yy, x0 + d:x1 + d]
                    sum_w = acc[s, 0, a0:a0 + count]
                    for i in range(count):
                        w = normal_weight[i] * fast_exp(
                            -(depth_exponent[i] + abs(l_p[i] - l_q[i]) * inv_p[i])
                        )
                        tap_weight[i] = w
                        sum_w[i] += w
                    r_q = illumination[s, 0, yy, x0 + d:x1 + d]
                    g_q = illumination[s, 1, yy, x0 + d:x1 + d]
                    b_q = illumination[s, 2, yy, x0 + d:x1 + d]
                    sum_r = acc[s, 1, a0:a0 + count]
                    sum_g = acc[s, 2, a0:a0 + count]
                    sum_b = acc[s, 3, a0:a0 + count]
                    for i in range(count):
                        w = tap_weight[i]
                        sum_r[i] += w * r_q[i]
                        sum_g[i] += w * g_q[i]
                        sum_b[i] += w * b_q[i]
                    if propagate_variance:
                        values = variance[s, yy, x0 + d:x1 + d]
                        sums = acc[s, 4, a0:a0 + count]
                        for i in range(count):
                            sums[i] += (tap_weight[i] * tap_weight[i]) * values[i]
        for s in range(num_signals):
            sum_w = acc[s, 0]
            sum_r = acc[s, 1]
            sum_g = acc[s, 2]
            sum_b = acc[s, 3]
            o_r = out_illumination[s, 0, y, chunk_start:chunk_end]
            o_g = out_illumination[s, 1, y, chunk_start:chunk_end]
            o_b = out_illumination[s, 2, y, chunk_start:chunk_end]
            for i in range(n):
                inv = _ONE / sum_w[i]
                o_r[i] = sum_r[i] * inv
                o_g[i] = sum_g[i] * inv
                o_b[i] = sum_b[i] * inv
            if propagate_variance:
                sum_v = acc[s, 4]
                o_v = out_variance[s, y, chunk_start:chunk_end]
                for i in range(n):
                    inv = _ONE / sum_w[i]
                    o_v[i] = sum_v[i] * (inv * inv)
