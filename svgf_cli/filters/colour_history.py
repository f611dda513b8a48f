"""Anti-aliased demodulation colours: each signal's colour accumulated over time.

A renderer that shoots one camera ray per pixel samples the colour passes (``DiffCol``,
``GlossCol``, an albedo AOV) at one point of the pixel: Cycles and ``svgf trace`` at the
pixel centre. A texture edge inside the pixel comes out all one side, while a many-sample
render (a renderer's reference, the converged frame a compositor expects) averages the
colour over the pixel's filter footprint. Remodulating the filtered light by the one-point
colour puts that aliasing back into every edge of every texture: on the Cycles ``roll``
fixture (a checker floor under a moving camera) 84 % of the squared error is on such edges.

When the camera or the object moves, the point a pixel samples moves over the surface from
frame to frame, so the colour reprojected and blended like the light (paper equation 6)
converges to the footprint's average; where nothing moves it stays the one-point colour.

* :func:`accumulate_colours` (temporal; every distinct colour of a frame in one pass, the
  geometric tests once per pixel): ``c_acc = lerp(clamp(c_prev(p + m)), c, alpha)``. The
  previous accumulation is read at the backprojected position with the reprojection's
  bilinear taps and geometric tests (the same surface only), and clamped per
  channel to the current colour's 3x3 min/max (a texture that changes cannot ghost); no
  usable tap, or a colour that is no reflectance (radiance mode), takes the current colour.
* :func:`antialias_remodulation` (at composition, per signal, after the usual
  remodulation by ``c'``): the remodulated value ``f * c_acc'`` replaces ``f * c'``,
  clamped per channel to the range of ``f_q * c'_q`` over the 3x3 neighbourhood (an
  average over the footprint lies within the values that make it up), so a colour that
  does not fit the filtered light there (light that does not follow the colour: a
  reflection over a dark texel) cannot brighten a pixel beyond its neighbours. Only where
  the accumulated colour differs from the current one and both give the demodulated mode;
  elsewhere the output is left exactly as remodulated.
"""

from __future__ import annotations

import numpy as np
from numba import get_num_threads, njit, prange

from svgf_cli.filters.fastmath import FASTMATH
from svgf_cli.filters.modulate import clean_albedo, effective_albedo
from svgf_cli.filters.reproject import tap_consistent
from svgf_cli.filters.rows import balanced_row, balanced_row_count

F32 = np.float32
U = np.uint64
_ZERO = F32(0.0)
_ONE = F32(1.0)
_NORMAL_SLACK = F32(0.01)
_MIN_BILINEAR_WEIGHT = F32(0.01)
_JIT = dict(fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy")


def accumulate_colours(
    motion: np.ndarray,
    depth: np.ndarray,
    normal: np.ndarray,
    mesh_id: np.ndarray,
    depth_slope: np.ndarray,
    normal_width: np.ndarray,
    prev_depth: np.ndarray,
    prev_normal: np.ndarray,
    prev_mesh_id: np.ndarray,
    prev_colours: np.ndarray,
    colours: tuple[np.ndarray, ...],
    slots: np.ndarray,
    blacks: np.ndarray,
    alpha: np.float32,
    depth_tolerance: np.float32,
    depth_slack: np.float32,
    normal_tolerance: np.float32,
    max_reflectance: np.float32,
    relative_floor: np.float32,
    out: np.ndarray,
) -> None:
    """For each (3, H, W) colour ``colours[i]``, into ``out[slots[i]]``:
    ``lerp(clamp_3x3(bilinear(prev_colours[slots[i]], p + motion)), colour, alpha)``, with the
    reprojection's taps and tests (``filters.reproject``); the colour itself (cleaned) where
    no tap passes, on background and where it or the result is no reflectance under its
    rules (``blacks[i]``, ``max_reflectance``, ``relative_floor``:
    ``modulate.effective_albedo``)."""
    _accumulate_rows(
        motion, depth, normal, mesh_id, depth_slope, normal_width, prev_depth, prev_normal,
        prev_mesh_id, prev_colours, colours, slots.astype(np.int64), blacks.astype(F32),
        F32(alpha), F32(depth_tolerance), F32(depth_slack), F32(normal_tolerance),
        F32(max_reflectance), F32(relative_floor), out, np.int64(get_num_threads()),
    )


@njit(parallel=True, **_JIT)
def _accumulate_rows(
    motion: np.ndarray,
    depth: np.ndarray,
    normal: np.ndarray,
    mesh_id: np.ndarray,
    depth_slope: np.ndarray,
    normal_width: np.ndarray,
    prev_depth: np.ndarray,
    prev_normal: np.ndarray,
    prev_mesh_id: np.ndarray,
    prev_colours: np.ndarray,
    colours: tuple[np.ndarray, ...],
    slots: np.ndarray,
    blacks: np.ndarray,
    alpha: np.float32,
    depth_tolerance: np.float32,
    depth_slack: np.float32,
    normal_tolerance: np.float32,
    max_reflectance: np.float32,
    relative_floor: np.float32,
    out: np.ndarray,
    threads: int,
) -> None:
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
            reachable = (z > _ZERO and px > F32(-2.0) and py > F32(-2.0)
                         and px < fwidth + _ONE and py < fheight + _ONE)
            # The bilinear taps that pass the geometric tests, once for every colour.
            weight_sum = _ZERO
            x0 = 0
            y0 = 0
            w00 = w10 = w01 = w11 = _ZERO
            if reachable:
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
                if w00 > _ZERO and not tap_consistent(
                        x0, y0, z, nx, ny, nz, mesh, max_depth_diff, max_normal_diff_sq,
                        prev_depth, prev_normal, prev_mesh_id):
                    w00 = _ZERO
                if w10 > _ZERO and not tap_consistent(
                        x0 + 1, y0, z, nx, ny, nz, mesh, max_depth_diff, max_normal_diff_sq,
                        prev_depth, prev_normal, prev_mesh_id):
                    w10 = _ZERO
                if w01 > _ZERO and not tap_consistent(
                        x0, y0 + 1, z, nx, ny, nz, mesh, max_depth_diff, max_normal_diff_sq,
                        prev_depth, prev_normal, prev_mesh_id):
                    w01 = _ZERO
                if w11 > _ZERO and not tap_consistent(
                        x0 + 1, y0 + 1, z, nx, ny, nz, mesh, max_depth_diff,
                        max_normal_diff_sq, prev_depth, prev_normal, prev_mesh_id):
                    w11 = _ZERO
                weight_sum = w00 + w10 + w01 + w11
            usable = weight_sum >= _MIN_BILINEAR_WEIGHT
            inv = _ONE / weight_sum if usable else _ZERO
            # Taps of zero weight may lie outside the image: clamp their index.
            xa = U(min(max(x0, 0), width - 1))
            xb = U(min(max(x0 + 1, 0), width - 1))
            ya = U(min(max(y0, 0), height - 1))
            yb = U(min(max(y0 + 1, 0), height - 1))
            for k in range(len(colours)):
                colour = colours[k]
                s = slots[k]
                cr = clean_albedo(colour[0, uy, ux])
                cg = clean_albedo(colour[1, uy, ux])
                cb = clean_albedo(colour[2, uy, ux])
                out[s, 0, uy, ux] = cr
                out[s, 1, uy, ux] = cg
                out[s, 2, uy, ux] = cb
                if not usable or not effective_albedo(cr, cg, cb, blacks[k], max_reflectance,
                                                      relative_floor)[0]:
                    continue
                hr = (w00 * prev_colours[s, 0, ya, xa] + w10 * prev_colours[s, 0, ya, xb]
                      + w01 * prev_colours[s, 0, yb, xa] + w11 * prev_colours[s, 0, yb, xb]) * inv
                hg = (w00 * prev_colours[s, 1, ya, xa] + w10 * prev_colours[s, 1, ya, xb]
                      + w01 * prev_colours[s, 1, yb, xa] + w11 * prev_colours[s, 1, yb, xb]) * inv
                hb = (w00 * prev_colours[s, 2, ya, xa] + w10 * prev_colours[s, 2, ya, xb]
                      + w01 * prev_colours[s, 2, yb, xa] + w11 * prev_colours[s, 2, yb, xb]) * inv
                if hr == cr and hg == cg and hb == cb:
                    continue  # the history agrees: the result is the colour itself
                # The current colour's 3x3 range (surface pixels): a texture that changed, or
                # a history from a surface the tests let through, cannot ghost.
                lo_r = hi_r = cr
                lo_g = hi_g = cg
                lo_b = hi_b = cb
                for qy in range(max(y - 1, 0), min(y + 2, height)):
                    for qx in range(max(x - 1, 0), min(x + 2, width)):
                        vy, vx = U(qy), U(qx)
                        if depth[vy, vx] <= _ZERO:
                            continue
                        vr = clean_albedo(colour[0, vy, vx])
                        vg = clean_albedo(colour[1, vy, vx])
                        vb = clean_albedo(colour[2, vy, vx])
                        lo_r, hi_r = min(lo_r, vr), max(hi_r, vr)
                        lo_g, hi_g = min(lo_g, vg), max(hi_g, vg)
                        lo_b, hi_b = min(lo_b, vb), max(hi_b, vb)
                hr = min(max(hr, lo_r), hi_r)
                hg = min(max(hg, lo_g), hi_g)
                hb = min(max(hb, lo_b), hi_b)
                ar = hr + alpha * (cr - hr)
                ag = hg + alpha * (cg - hg)
                ab = hb + alpha * (cb - hb)
                if effective_albedo(ar, ag, ab, blacks[k], max_reflectance, relative_floor)[0]:
                    out[s, 0, uy, ux] = ar
                    out[s, 1, uy, ux] = ag
                    out[s, 2, uy, ux] = ab


@njit(parallel=True, **_JIT)
def antialias_remodulation(
    illumination: np.ndarray,
    colour: np.ndarray,
    accumulated: np.ndarray,
    depth: np.ndarray,
    black: np.float32,
    max_reflectance: np.float32,
    relative_floor: np.float32,
    out: np.ndarray,
) -> None:
    """``out += clamp(f * acc', lo, hi) - f * c'`` per channel: one signal's (3, H, W)
    remodulated value ``f * c'`` (already in ``out``, from ``modulate.remodulate_add``)
    becomes ``f * acc'`` bounded by ``[lo, hi]``, the range of ``f_q * c'_q`` over the 3x3
    neighbours ``q`` (surface pixels demodulated by their colour, the pixel included).
    ``f`` is the signal's filtered light, ``c'`` and ``acc'`` the effective point-sampled
    and accumulated colours (``modulate.effective_albedo``). Only on surface pixels where
    the accumulated colour differs from the colour, both are in the demodulated mode, and
    in the channels where ``acc' != c'``: elsewhere ``out`` is not touched."""
    height, width = depth.shape
    for y in prange(height):
        uy = U(y)
        for x in range(width):
            ux = U(x)
            if depth[uy, ux] <= _ZERO:
                continue
            raw_r = clean_albedo(colour[0, uy, ux])
            raw_g = clean_albedo(colour[1, uy, ux])
            raw_b = clean_albedo(colour[2, uy, ux])
            acc_r = clean_albedo(accumulated[0, uy, ux])
            acc_g = clean_albedo(accumulated[1, uy, ux])
            acc_b = clean_albedo(accumulated[2, uy, ux])
            if acc_r == raw_r and acc_g == raw_g and acc_b == raw_b:
                continue  # nothing to anti-alias (most pixels): skip the neighbourhood
            ok, c_r, c_g, c_b = effective_albedo(raw_r, raw_g, raw_b, black, max_reflectance,
                                                 relative_floor)
            ok_acc, a_r, a_g, a_b = effective_albedo(acc_r, acc_g, acc_b, black,
                                                     max_reflectance, relative_floor)
            if not (ok and ok_acc):
                continue
            f_r = illumination[0, uy, ux]
            f_g = illumination[1, uy, ux]
            f_b = illumination[2, uy, ux]
            lo_r = hi_r = f_r * c_r
            lo_g = hi_g = f_g * c_g
            lo_b = hi_b = f_b * c_b
            for qy in range(max(y - 1, 0), min(y + 2, height)):
                for qx in range(max(x - 1, 0), min(x + 2, width)):
                    vy, vx = U(qy), U(qx)
                    if depth[vy, vx] <= _ZERO:
                        continue
                    q_ok, q_r, q_g, q_b = effective_albedo(
                        clean_albedo(colour[0, vy, vx]), clean_albedo(colour[1, vy, vx]),
                        clean_albedo(colour[2, vy, vx]), black, max_reflectance,
                        relative_floor)
                    if not q_ok:
                        continue
                    v_r = illumination[0, vy, vx] * q_r
                    v_g = illumination[1, vy, vx] * q_g
                    v_b = illumination[2, vy, vx] * q_b
                    lo_r, hi_r = min(lo_r, v_r), max(hi_r, v_r)
                    lo_g, hi_g = min(lo_g, v_g), max(hi_g, v_g)
                    lo_b, hi_b = min(lo_b, v_b), max(hi_b, v_b)
            if a_r != c_r:
                out[0, uy, ux] += min(max(f_r * a_r, lo_r), hi_r) - f_r * c_r
            if a_g != c_g:
                out[1, uy, ux] += min(max(f_g * a_g, lo_g), hi_g) - f_g * c_g
            if a_b != c_b:
                out[2, uy, ux] += min(max(f_b * a_b, lo_b), hi_b) - f_b * c_b
