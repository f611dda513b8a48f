"""Temporal accumulation (paper section 4.1): backproject, test, resample, blend.

Two kernels, so each step can be tested alone:

* :func:`reproject` resamples last frame's history (illumination, moments, history length)
  at the backprojected position ``(x + motion.x, y + motion.y)`` in pixel-index space. It
  tries the 2x2 bilinear taps, each bounds-checked and tested for consistency (previous pixel
  not background, same mesh id, depth within ``depth_tolerance * (slope + depth_slack * z)``,
  normal within ``normal_tolerance * (fwidth_n + 0.01)``); the bilinear weights are
  renormalised over the taps that pass and the pixel is rejected when their sum is < 0.01.
  Failing that, a plain average over the passing taps of the 3x3 around the rounded position;
  failing that, a disocclusion (history length 0). The history length of the taps is combined
  with the *same* weights as the colour (never ``max``, which ghosts at disocclusions); a
  result within 1e-3 of a whole number of frames is that number (float rounding of the
  weights must not move a count across the variance threshold).
* :func:`accumulate` blends: ``h = min(cap, h_prev + 1)`` on success else 1,
  ``c = lerp(c_hist, c, max(alpha, 1/h))`` and the luminance moments
  ``(l, l^2)`` likewise with ``max(moments_alpha, 1/h)`` (paper equation 6).

Departures from Falcor (svgf-anchors.md section 3.1): the mesh-id test is back (the paper
has it); each tap is bounds-checked on its own; the depth slack is relative to depth
(``depth_slack * z``, default 0.002) instead of Falcor's absolute 0.01, so the test does not
depend on the scene's units; history length is resampled, not read nearest-neighbour.
"""

from __future__ import annotations

import numpy as np
from numba import get_num_threads, njit, prange

from svgf_cli.filters.fastmath import FASTMATH, luminance
from svgf_cli.filters.rows import balanced_row, balanced_row_count

F32 = np.float32
U = np.uint64
_ZERO = F32(0.0)
_ONE = F32(1.0)
_NORMAL_SLACK = F32(0.01)
_MIN_BILINEAR_WEIGHT = F32(0.01)
# History lengths are frame counts; resampling makes them fractional only where histories of
# different lengths mix. Float32 rounding of the renormalised weights leaves a footprint of
# equal counts up to a few ulps below them (3 -> 2.9999998 for ~9 % of sub-pixel positions),
# which moved such pixels below the variance threshold (h < 4) on their fourth frame.
_WHOLE_SNAP = F32(1e-3)


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, error_model="numpy")
def _whole_if_close(h: np.float32) -> np.float32:
    """``h`` rounded to the nearest whole number when it lies within 1e-3 of it."""
    whole = np.floor(h + F32(0.5))
    return whole if abs(h - whole) < _WHOLE_SNAP else h


@njit(
    inline="always", fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
    error_model="numpy",
)
def _tap_consistent(
    tx: int,
    ty: int,
    z: np.float32,
    nx: np.float32,
    ny: np.float32,
    nz: np.float32,
    mesh: np.int32,
    max_depth_diff: np.float32,
    max_normal_diff_sq: np.float32,
    prev_depth: np.ndarray,
    prev_normal: np.ndarray,
    prev_mesh_id: np.ndarray,
) -> bool:
    height, width = prev_depth.shape
    if tx < 0 or ty < 0 or tx >= width or ty >= height:
        return False
    # Unsigned from here: numba then skips its negative-index wrap-around on every load.
    ux = U(tx)
    uy = U(ty)
    z_prev = prev_depth[uy, ux]
    if z_prev <= _ZERO:
        return False
    if prev_mesh_id[uy, ux] != mesh:
        return False
    if abs(z_prev - z) > max_depth_diff:
        return False
    dx = nx - prev_normal[0, uy, ux]
    dy = ny - prev_normal[1, uy, ux]
    dz = nz - prev_normal[2, uy, ux]
    return dx * dx + dy * dy + dz * dz <= max_normal_diff_sq


def reproject(
    motion: np.ndarray,
    depth: np.ndarray,
    normal: np.ndarray,
    mesh_id: np.ndarray,
    depth_slope: np.ndarray,
    normal_width: np.ndarray,
    prev_depth: np.ndarray,
    prev_normal: np.ndarray,
    prev_mesh_id: np.ndarray,
    prev_illumination: np.ndarray,
    prev_moments: np.ndarray,
    prev_history_length: np.ndarray,
    depth_tolerance: np.float32,
    depth_slack: np.float32,
    normal_tolerance: np.float32,
    out_illumination: np.ndarray,
    out_moments: np.ndarray,
    out_history_length: np.ndarray,
) -> None:
    """Resample the history of every signal at the backprojected position.

    ``prev_illumination`` is (S, 3, H, W), ``prev_moments`` (S, 2, H, W). Writes the
    resampled history into the ``out_*`` arrays; ``out_history_length`` is the resampled
    previous history length, 0 where the history is rejected (disocclusion).
    """
    _reproject_rows(
        motion, depth, normal, mesh_id, depth_slope, normal_width, prev_depth, prev_normal,
        prev_mesh_id, prev_illumination, prev_moments, prev_history_length,
        F32(depth_tolerance), F32(depth_slack), F32(normal_tolerance), out_illumination,
        out_moments, out_history_length, np.int64(get_num_threads()),
    )


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def _reproject_rows(
    motion: np.ndarray,
    depth: np.ndarray,
    normal: np.ndarray,
    mesh_id: np.ndarray,
    depth_slope: np.ndarray,
    normal_width: np.ndarray,
    prev_depth: np.ndarray,
    prev_normal: np.ndarray,
    prev_mesh_id: np.ndarray,
    prev_illumination: np.ndarray,
    prev_moments: np.ndarray,
    prev_history_length: np.ndarray,
    depth_tolerance: np.float32,
    depth_slack: np.float32,
    normal_tolerance: np.float32,
    out_illumination: np.ndarray,
    out_moments: np.ndarray,
    out_history_length: np.ndarray,
    threads: int,
) -> None:
    """All rows of :func:`reproject`, balanced over the threads (see ``rows``)."""
    num_signals = prev_illumination.shape[0]
    height, width = depth.shape
    fwidth = F32(width)
    fheight = F32(height)
    for i in prange(balanced_row_count(height, threads)):
        y = balanced_row(i, height, threads)
        if y >= height:
            continue
        uy = U(y)
        for x in range(width):
            ux = U(x)
            z = depth[uy, ux]
            px = F32(x) + motion[0, uy, ux]
            py = F32(y) + motion[1, uy, ux]
            # Positions this far outside cannot reach a tap (and NaN motion fails every
            # comparison), which also keeps the int conversions below in range.
            reachable = (
                z > _ZERO
                and px > F32(-2.0)
                and py > F32(-2.0)
                and px < fwidth + F32(1.0)
                and py < fheight + F32(1.0)
            )
            if not reachable:
                out_history_length[uy, ux] = _ZERO
                for s in range(num_signals):
                    for c in range(3):
                        out_illumination[s, c, uy, ux] = _ZERO
                    out_moments[s, 0, uy, ux] = _ZERO
                    out_moments[s, 1, uy, ux] = _ZERO
                continue
            nx = normal[0, uy, ux]
            ny = normal[1, uy, ux]
            nz = normal[2, uy, ux]
            mesh = mesh_id[uy, ux]
            max_depth_diff = depth_tolerance * (depth_slope[uy, ux] + depth_slack * z)
            max_normal_diff = normal_tolerance * (normal_width[uy, ux] + _NORMAL_SLACK)
            max_normal_diff_sq = max_normal_diff * max_normal_diff

            fx0 = np.floor(px)
            fy0 = np.floor(py)
            x0 = int(fx0)
            y0 = int(fy0)
            fx = px - fx0
            fy = py - fy0
            w00 = (_ONE - fx) * (_ONE - fy)
            w10 = fx * (_ONE - fy)
            w01 = (_ONE - fx) * fy
            w11 = fx * fy
            if not _tap_consistent(x0, y0, z, nx, ny, nz, mesh, max_depth_diff,
                                   max_normal_diff_sq, prev_depth, prev_normal, prev_mesh_id):
                w00 = _ZERO
            if not _tap_consistent(x0 + 1, y0, z, nx, ny, nz, mesh, max_depth_diff,
                                   max_normal_diff_sq, prev_depth, prev_normal, prev_mesh_id):
                w10 = _ZERO
            if not _tap_consistent(x0, y0 + 1, z, nx, ny, nz, mesh, max_depth_diff,
                                   max_normal_diff_sq, prev_depth, prev_normal, prev_mesh_id):
                w01 = _ZERO
            if not _tap_consistent(x0 + 1, y0 + 1, z, nx, ny, nz, mesh, max_depth_diff,
                                   max_normal_diff_sq, prev_depth, prev_normal, prev_mesh_id):
                w11 = _ZERO
            weight_sum = w00 + w10 + w01 + w11
            if weight_sum >= _MIN_BILINEAR_WEIGHT:
                inv = _ONE / weight_sum
                w00 *= inv
                w10 *= inv
                w01 *= inv
                w11 *= inv
                # Taps with zero weight may lie outside the image: clamp their index.
                xa = U(min(max(x0, 0), width - 1))
                xb = U(min(max(x0 + 1, 0), width - 1))
                ya = U(min(max(y0, 0), height - 1))
                yb = U(min(max(y0 + 1, 0), height - 1))
                out_history_length[uy, ux] = _whole_if_close(
                    w00 * prev_history_length[ya, xa]
                    + w10 * prev_history_length[ya, xb]
                    + w01 * prev_history_length[yb, xa]
                    + w11 * prev_history_length[yb, xb]
                )
                # Index the 4-D arrays directly: a per-pixel sub-array view would cost an
                # atomic reference-count update, contended between threads.
                for s in range(num_signals):
                    for c in range(3):
                        out_illumination[s, c, uy, ux] = (
                            w00 * prev_illumination[s, c, ya, xa]
                            + w10 * prev_illumination[s, c, ya, xb]
                            + w01 * prev_illumination[s, c, yb, xa]
                            + w11 * prev_illumination[s, c, yb, xb]
                        )
                    for c in range(2):
                        out_moments[s, c, uy, ux] = (
                            w00 * prev_moments[s, c, ya, xa]
                            + w10 * prev_moments[s, c, ya, xb]
                            + w01 * prev_moments[s, c, yb, xa]
                            + w11 * prev_moments[s, c, yb, xb]
                        )
                continue

            # 3x3 box of consistent taps around the rounded previous position.
            cx = int(np.floor(px + F32(0.5)))
            cy = int(np.floor(py + F32(0.5)))
            count = 0
            h_sum = _ZERO
            for s in range(num_signals):
                for c in range(3):
                    out_illumination[s, c, uy, ux] = _ZERO
                out_moments[s, 0, uy, ux] = _ZERO
                out_moments[s, 1, uy, ux] = _ZERO
            for ty in range(cy - 1, cy + 2):
                for tx in range(cx - 1, cx + 2):
                    if not _tap_consistent(tx, ty, z, nx, ny, nz, mesh, max_depth_diff,
                                           max_normal_diff_sq, prev_depth, prev_normal,
                                           prev_mesh_id):
                        continue
                    count += 1
                    qy, qx = U(ty), U(tx)
                    h_sum += prev_history_length[qy, qx]
                    for s in range(num_signals):
                        for c in range(3):
                            out_illumination[s, c, uy, ux] += prev_illumination[s, c, qy, qx]
                        out_moments[s, 0, uy, ux] += prev_moments[s, 0, qy, qx]
                        out_moments[s, 1, uy, ux] += prev_moments[s, 1, qy, qx]
            if count == 0:
                out_history_length[uy, ux] = _ZERO
                continue
            inv = _ONE / F32(count)
            out_history_length[uy, ux] = _whole_if_close(h_sum * inv)
            for s in range(num_signals):
                for c in range(3):
                    out_illumination[s, c, uy, ux] *= inv
                out_moments[s, 0, uy, ux] *= inv
                out_moments[s, 1, uy, ux] *= inv


def accumulate(
    illumination: np.ndarray,
    history_illumination: np.ndarray,
    history_moments: np.ndarray,
    history_length_prev: np.ndarray,
    depth: np.ndarray,
    alpha: np.float32,
    moments_alpha: np.float32,
    history_cap: np.float32,
    out_illumination: np.ndarray,
    out_moments: np.ndarray,
    out_history_length: np.ndarray,
) -> None:
    """Exponential moving average with adaptive alpha (paper eq. 6, alpha = max(a, 1/h)).

    ``history_length_prev`` is the output of :func:`reproject` (0 = no history). Background
    pixels get history length 0 and their current illumination. The ``out_*`` arrays may be
    the history arrays themselves (the Denoiser accumulates in place); otherwise the history
    is copied into them first and :func:`accumulate_in_place` blends there.
    """
    for source, target in (
        (history_illumination, out_illumination),
        (history_moments, out_moments),
        (history_length_prev, out_history_length),
    ):
        if source is not target:
            np.copyto(target, source)
    accumulate_in_place(illumination, out_illumination, out_moments, out_history_length, depth,
                        alpha, moments_alpha, history_cap)


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def accumulate_in_place(
    illumination: np.ndarray,
    history_illumination: np.ndarray,
    history_moments: np.ndarray,
    history_length: np.ndarray,
    depth: np.ndarray,
    alpha: np.float32,
    moments_alpha: np.float32,
    history_cap: np.float32,
) -> None:
    """:func:`accumulate` overwriting the (reprojected) history arrays with the result.

    Written branch-free over row slices (a blend factor of exactly 1 where there is no
    history) so it vectorizes; the history buffers must hold finite values everywhere.
    Reading and writing the same array (rather than a separate output that may alias it)
    keeps LLVM's runtime alias checks passing, so the vector loops run.
    """
    num_signals = illumination.shape[0]
    height, width = depth.shape
    for y in prange(height):
        blend = np.empty(width, dtype=np.float32)
        blend_moments = np.empty(width, dtype=np.float32)
        h_row = history_length[y]
        z = depth[y]
        for x in range(width):
            h_prev = h_row[x]
            surface = z[x] > _ZERO
            reused = surface and h_prev > _ZERO
            h = min(history_cap, h_prev + _ONE) if reused else _ONE
            h_row[x] = h if surface else _ZERO
            inv_h = _ONE / h
            blend[x] = max(alpha, inv_h) if reused else _ONE
            blend_moments[x] = max(moments_alpha, inv_h) if reused else _ONE
        for s in range(num_signals):
            r = illumination[s, 0, y]
            g = illumination[s, 1, y]
            b = illumination[s, 2, y]
            m1 = history_moments[s, 0, y]
            m2 = history_moments[s, 1, y]
            for x in range(width):
                lum = luminance(r[x], g[x], b[x])
                a = blend_moments[x]
                m1[x] = (_ONE - a) * m1[x] + a * lum
                m2[x] = (_ONE - a) * m2[x] + a * (lum * lum)
            for c in range(3):
                current = illumination[s, c, y]
                out = history_illumination[s, c, y]
                for x in range(width):
                    a = blend[x]
                    out[x] = (_ONE - a) * out[x] + a * current[x]
