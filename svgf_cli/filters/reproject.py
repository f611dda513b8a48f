"""Temporal accumulation (paper section 4.1): backproject, test, resample, blend.

Two kernels, so each step can be tested alone:

* :func:`reproject` resamples last frame's history of every signal (illumination, moments,
  history length) at the backprojected position ``(x + motion.x, y + motion.y)`` in
  pixel-index space. It tries the 2x2 bilinear taps, each bounds-checked and tested for
  consistency (previous pixel not background, same mesh id, depth within
  ``depth_tolerance * (slope + depth_slack * z)``, normal within
  ``normal_tolerance * (fwidth_n + 0.01)``) and, per signal, for the same demodulation mode
  as the pixel has now; the bilinear weights are renormalised over the taps that pass and the
  signal's history is rejected when their sum is < 0.01. Failing that, a plain average over
  the passing taps of the 3x3 around the rounded position; failing that, a disocclusion
  (history length 0). The history length of the taps is combined with the *same* weights as
  the colour (never ``max``, which ghosts at disocclusions); a result within 1e-3 of a whole
  number of frames is that number (float rounding of the weights must not move a count
  across the variance threshold).
* :func:`accumulate` blends each signal with its own history length:
  ``h = min(cap, h_prev + 1)`` on success else 1, ``c = lerp(c_hist, c, max(alpha, 1/h))``
  and the luminance moments ``(l, l^2)`` likewise with ``max(moments_alpha, 1/h)`` (paper
  equation 6).

Departures from Falcor (svgf-anchors.md section 3.1): the mesh-id test is back (the paper
has it); each tap is bounds-checked on its own; the depth slack is relative to depth
(``depth_slack * z``, default 0.002) instead of Falcor's absolute 0.01, so the test does not
depend on the scene's units; history length is resampled, not read nearest-neighbour.
"""

from __future__ import annotations

import numpy as np
from numba import get_num_threads, njit, prange

from svgf_cli.filters.fastmath import FASTMATH, luminance
from svgf_cli.filters.modulate import NO_HISTORY
from svgf_cli.filters.resample import catmull_rom_history, catmull_rom_weights
from svgf_cli.filters.rows import balanced_row, balanced_row_count

F32 = np.float32
U = np.uint64
_ZERO = F32(0.0)
_ONE = F32(1.0)
_NORMAL_SLACK = F32(0.01)
# Renormalised bilinear taps whose weights sum below this are no history (also the
# temporal albedo's, filters.albedo_history).
MIN_BILINEAR_WEIGHT = F32(0.01)
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
    mode: np.ndarray,
    depth_slope: np.ndarray,
    normal_width: np.ndarray,
    prev_depth: np.ndarray,
    prev_normal: np.ndarray,
    prev_mesh_id: np.ndarray,
    prev_mode: np.ndarray,
    prev_illumination: np.ndarray,
    prev_moments: np.ndarray,
    prev_history_length: np.ndarray,
    depth_tolerance: np.float32,
    depth_slack: np.float32,
    normal_tolerance: np.float32,
    out_illumination: np.ndarray,
    out_moments: np.ndarray,
    out_history_length: np.ndarray,
    catmull_rom: bool = False,
    origin: tuple[int, int] = (0, 0),
) -> None:
    """Resample the history of every signal at the backprojected position.

    ``prev_illumination`` is (S, 3, H, W), ``prev_moments`` (S, 2, H, W),
    ``prev_history_length`` (S, H, W); ``mode`` and ``prev_mode`` are the (H, W) uint16 mode
    masks (bit s: signal s; ``modulate.NO_HISTORY``: no usable history). The geometric tests
    are shared by all signals; on top, signal ``s`` accepts a tap only if the tap's stored
    mode equals the pixel's current mode for that signal (radiance and illumination history
    never mix), so each signal has its own bilinear weights, fallback and history length
    (one set of weights for all where every usable tap agrees, the common case). Writes
    the resampled history into the ``out_*`` arrays; ``out_history_length`` (S, H, W) is the
    resampled previous history length, 0 where the signal's history is rejected.

    ``catmull_rom``: where all four bilinear taps (the ones with weight) pass and every
    further tap of the 4x4 support passes the same tests with the pixel's modes, the colour
    and moments are the clamped Catmull-Rom fetch (``resample``) instead; the history length
    stays bilinear.

    ``origin``: the (row, column) of the current arrays' first pixel in last frame's image,
    for a window of this frame (the current arrays smaller than the ``prev_*`` ones).
    """
    _reproject_rows(
        motion, depth, normal, mesh_id, mode, depth_slope, normal_width, prev_depth,
        prev_normal, prev_mesh_id, prev_mode, prev_illumination, prev_moments,
        prev_history_length, F32(depth_tolerance), F32(depth_slack), F32(normal_tolerance),
        out_illumination, out_moments, out_history_length, bool(catmull_rom),
        np.int64(get_num_threads()), np.int64(origin[0]), np.int64(origin[1]),
    )


@njit(
    inline="always", fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
    error_model="numpy",
)
def _clear(
    s: int, uy: np.uint64, ux: np.uint64, out_illumination: np.ndarray, out_moments: np.ndarray,
    out_history_length: np.ndarray,
) -> None:
    """No history for signal ``s`` at the pixel."""
    out_history_length[s, uy, ux] = _ZERO
    for c in range(3):
        out_illumination[s, c, uy, ux] = _ZERO
    out_moments[s, 0, uy, ux] = _ZERO
    out_moments[s, 1, uy, ux] = _ZERO


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def _reproject_rows(
    motion: np.ndarray,
    depth: np.ndarray,
    normal: np.ndarray,
    mesh_id: np.ndarray,
    mode: np.ndarray,
    depth_slope: np.ndarray,
    normal_width: np.ndarray,
    prev_depth: np.ndarray,
    prev_normal: np.ndarray,
    prev_mesh_id: np.ndarray,
    prev_mode: np.ndarray,
    prev_illumination: np.ndarray,
    prev_moments: np.ndarray,
    prev_history_length: np.ndarray,
    depth_tolerance: np.float32,
    depth_slack: np.float32,
    normal_tolerance: np.float32,
    out_illumination: np.ndarray,
    out_moments: np.ndarray,
    out_history_length: np.ndarray,
    catmull_rom: bool,
    threads: int,
    origin_y: int,
    origin_x: int,
) -> None:
    """All rows of :func:`reproject`, balanced over the threads (see ``rows``)."""
    rows = depth.shape[0]
    for i in prange(balanced_row_count(rows, threads)):
        y = balanced_row(i, rows, threads)
        if y < rows:
            _reproject_row(
                y, motion, depth, normal, mesh_id, mode, depth_slope, normal_width, prev_depth,
                prev_normal, prev_mesh_id, prev_mode, prev_illumination, prev_moments,
                prev_history_length, depth_tolerance, depth_slack, normal_tolerance,
                out_illumination, out_moments, out_history_length, catmull_rom, origin_y, origin_x,
            )


@njit(fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy")
def _reproject_row(
    y: int,
    motion: np.ndarray,
    depth: np.ndarray,
    normal: np.ndarray,
    mesh_id: np.ndarray,
    mode: np.ndarray,
    depth_slope: np.ndarray,
    normal_width: np.ndarray,
    prev_depth: np.ndarray,
    prev_normal: np.ndarray,
    prev_mesh_id: np.ndarray,
    prev_mode: np.ndarray,
    prev_illumination: np.ndarray,
    prev_moments: np.ndarray,
    prev_history_length: np.ndarray,
    depth_tolerance: np.float32,
    depth_slack: np.float32,
    normal_tolerance: np.float32,
    out_illumination: np.ndarray,
    out_moments: np.ndarray,
    out_history_length: np.ndarray,
    catmull_rom: bool,
    origin_y: int,
    origin_x: int,
) -> None:
    """Row ``y`` of :func:`reproject` (its own function: a parallel loop compiles faster
    with its body outside)."""
    num_signals = prev_illumination.shape[0]
    columns = depth.shape[1]
    height, width = prev_depth.shape
    fwidth = F32(width)
    fheight = F32(height)
    uy = U(y)
    # Pixels whose usable taps all agree with their modes (the common case) only record
    # their taps and weights here; their signals are resampled after the row's pass,
    # one signal at a time (fewer memory streams at once than all signals per pixel).
    # 1: bilinear taps recorded; 2: and the Catmull-Rom support (``catmull_rom``).
    agreed = np.zeros(columns, dtype=np.uint8)
    tap_rows = np.empty((2, columns), dtype=np.uint64)
    tap_columns = np.empty((2, columns), dtype=np.uint64)
    tap_weights = np.empty((4, columns), dtype=np.float32)
    support_rows = np.empty((4, columns), dtype=np.uint64)
    support_columns = np.empty((4, columns), dtype=np.uint64)
    support_weights = np.empty((8, columns), dtype=np.float32)
    for x in range(columns):
        ux = U(x)
        z = depth[uy, ux]
        px = F32(x + origin_x) + motion[0, uy, ux]
        py = F32(y + origin_y) + motion[1, uy, ux]
        # Positions this far outside cannot reach a tap (the Denoiser replaces
        # non-finite motion by a far-away one), which also keeps the int conversions
        # below in range.
        reachable = (
            z > _ZERO
            and px > F32(-2.0)
            and py > F32(-2.0)
            and px < fwidth + F32(1.0)
            and py < fheight + F32(1.0)
        )
        if not reachable:
            for s in range(num_signals):
                _clear(s, uy, ux, out_illumination, out_moments, out_history_length)
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
        g00 = (_ONE - fx) * (_ONE - fy)
        g10 = fx * (_ONE - fy)
        g01 = (_ONE - fx) * fy
        g11 = fx * fy
        ok00 = _tap_consistent(x0, y0, z, nx, ny, nz, mesh, max_depth_diff,
                               max_normal_diff_sq, prev_depth, prev_normal, prev_mesh_id)
        ok10 = _tap_consistent(x0 + 1, y0, z, nx, ny, nz, mesh, max_depth_diff,
                               max_normal_diff_sq, prev_depth, prev_normal, prev_mesh_id)
        ok01 = _tap_consistent(x0, y0 + 1, z, nx, ny, nz, mesh, max_depth_diff,
                               max_normal_diff_sq, prev_depth, prev_normal, prev_mesh_id)
        ok11 = _tap_consistent(x0 + 1, y0 + 1, z, nx, ny, nz, mesh, max_depth_diff,
                               max_normal_diff_sq, prev_depth, prev_normal, prev_mesh_id)
        if not ok00:
            g00 = _ZERO
        if not ok10:
            g10 = _ZERO
        if not ok01:
            g01 = _ZERO
        if not ok11:
            g11 = _ZERO
        # Taps with zero weight may lie outside the image: clamp their index.
        xa = U(min(max(x0, 0), width - 1))
        xb = U(min(max(x0 + 1, 0), width - 1))
        ya = U(min(max(y0, 0), height - 1))
        yb = U(min(max(y0 + 1, 0), height - 1))
        m = mode[uy, ux]
        t00 = prev_mode[ya, xa]
        t10 = prev_mode[ya, xb]
        t01 = prev_mode[yb, xa]
        t11 = prev_mode[yb, xb]
        if (
            (g00 == _ZERO or t00 == m) and (g10 == _ZERO or t10 == m)
            and (g01 == _ZERO or t01 == m) and (g11 == _ZERO or t11 == m)
        ):
            # Every usable tap has the pixel's modes in every signal (the common case):
            # one set of weights for all signals.
            weight_sum = g00 + g10 + g01 + g11
            if weight_sum >= MIN_BILINEAR_WEIGHT:
                inv = _ONE / weight_sum
                agreed[ux] = 1
                tap_rows[0, ux], tap_rows[1, ux] = ya, yb
                tap_columns[0, ux], tap_columns[1, ux] = xa, xb
                tap_weights[0, ux] = g00 * inv
                tap_weights[1, ux] = g10 * inv
                tap_weights[2, ux] = g01 * inv
                tap_weights[3, ux] = g11 * inv
                # The taps a fraction uses (both columns only where fx > 0) must pass.
                inner = ok00 and (ok10 or fx == _ZERO) and (ok01 or fy == _ZERO) and (
                    ok11 or fx == _ZERO or fy == _ZERO)
                if catmull_rom and inner and _catmull_rom_support(
                    x0, y0, fx, fy, z, nx, ny, nz, mesh, m, max_depth_diff,
                    max_normal_diff_sq, prev_depth, prev_normal, prev_mesh_id, prev_mode,
                    ux, support_rows, support_columns, support_weights,
                ):
                    agreed[ux] = 2
                continue
        # Per signal: a tap counts only where its stored mode equals the pixel's (a
        # history pixel marked NO_HISTORY matches no signal).
        box_mask = -1  # the 3x3 fallback's geometric tests, once, if a signal needs them
        for s in range(num_signals):
            relevant = np.uint16(1 << s) | NO_HISTORY
            w00 = g00 if (t00 ^ m) & relevant == 0 else _ZERO
            w10 = g10 if (t10 ^ m) & relevant == 0 else _ZERO
            w01 = g01 if (t01 ^ m) & relevant == 0 else _ZERO
            w11 = g11 if (t11 ^ m) & relevant == 0 else _ZERO
            weight_sum = w00 + w10 + w01 + w11
            if weight_sum >= MIN_BILINEAR_WEIGHT:
                inv = _ONE / weight_sum
                _bilinear(s, uy, ux, ya, yb, xa, xb, w00 * inv, w10 * inv, w01 * inv,
                          w11 * inv, prev_illumination, prev_moments, prev_history_length,
                          out_illumination, out_moments, out_history_length)
                continue

            # 3x3 box of consistent taps (of the same mode) around the rounded position.
            cx = int(np.floor(px + F32(0.5)))
            cy = int(np.floor(py + F32(0.5)))
            if box_mask < 0:
                box_mask = 0
                for k in range(9):
                    if _tap_consistent(cx - 1 + k % 3, cy - 1 + k // 3, z, nx, ny, nz, mesh,
                                       max_depth_diff, max_normal_diff_sq, prev_depth,
                                       prev_normal, prev_mesh_id):
                        box_mask |= 1 << k
            _clear(s, uy, ux, out_illumination, out_moments, out_history_length)
            count = 0
            h_sum = _ZERO
            for k in range(9):
                if not (box_mask >> k) & 1:
                    continue
                qy, qx = U(cy - 1 + k // 3), U(cx - 1 + k % 3)
                if (prev_mode[qy, qx] ^ m) & relevant != 0:
                    continue
                count += 1
                h_sum += prev_history_length[s, qy, qx]
                for c in range(3):
                    out_illumination[s, c, uy, ux] += prev_illumination[s, c, qy, qx]
                out_moments[s, 0, uy, ux] += prev_moments[s, 0, qy, qx]
                out_moments[s, 1, uy, ux] += prev_moments[s, 1, qy, qx]
            if count == 0:
                continue
            inv = _ONE / F32(count)
            out_history_length[s, uy, ux] = _whole_if_close(h_sum * inv)
            for c in range(3):
                out_illumination[s, c, uy, ux] *= inv
            out_moments[s, 0, uy, ux] *= inv
            out_moments[s, 1, uy, ux] *= inv
    for s in range(num_signals):
        for x in range(columns):
            ux = U(x)
            if agreed[ux] == 1:
                _bilinear(s, uy, ux, tap_rows[0, ux], tap_rows[1, ux], tap_columns[0, ux],
                          tap_columns[1, ux], tap_weights[0, ux], tap_weights[1, ux],
                          tap_weights[2, ux], tap_weights[3, ux], prev_illumination,
                          prev_moments, prev_history_length, out_illumination,
                          out_moments, out_history_length)
            elif agreed[ux] == 2:
                _bilinear_length(s, uy, ux, tap_rows[0, ux], tap_rows[1, ux],
                                 tap_columns[0, ux], tap_columns[1, ux], tap_weights[0, ux],
                                 tap_weights[1, ux], tap_weights[2, ux], tap_weights[3, ux],
                                 prev_history_length, out_history_length)
                catmull_rom_history(s, uy, ux, support_rows, support_columns,
                                    support_weights, prev_illumination, prev_moments,
                                    out_illumination, out_moments)

@njit(
    inline="always", fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
    error_model="numpy",
)
def _catmull_rom_support(
    x0: int, y0: int, fx: np.float32, fy: np.float32, z: np.float32, nx: np.float32,
    ny: np.float32, nz: np.float32, mesh: np.int32, m: np.uint16, max_depth_diff: np.float32,
    max_normal_diff_sq: np.float32, prev_depth: np.ndarray, prev_normal: np.ndarray,
    prev_mesh_id: np.ndarray, prev_mode: np.ndarray, ux: np.uint64, rows: np.ndarray,
    columns: np.ndarray, weights: np.ndarray,
) -> bool:
    """Whether the Catmull-Rom support of ``(x0 + fx, y0 + fy)`` is all usable: every tap
    outside the bilinear 2x2 (whose taps the caller tested) passes the consistency tests
    and has the pixel's modes ``m`` in every signal. An axis without a fraction has one
    column (row): the spline's weights there are 0, 1, 0, 0. A whole-pixel position is
    left to the bilinear fetch (the same value). On success writes the support's indices
    and weights into column ``ux`` of ``rows``, ``columns`` (4, W) and ``weights`` (8, W:
    the column weights, then the row weights)."""
    if fx == _ZERO and fy == _ZERO:
        return False
    first_i, end_i = (0, 4) if fx > _ZERO else (1, 2)
    first_j, end_j = (0, 4) if fy > _ZERO else (1, 2)
    for j in range(first_j, end_j):
        for i in range(first_i, end_i):
            if 1 <= i <= 2 and 1 <= j <= 2:
                continue  # the bilinear taps
            tx = x0 - 1 + i
            ty = y0 - 1 + j
            if not _tap_consistent(tx, ty, z, nx, ny, nz, mesh, max_depth_diff,
                                   max_normal_diff_sq, prev_depth, prev_normal, prev_mesh_id):
                return False
            if prev_mode[U(ty), U(tx)] != m:
                return False
    wx0, wx1, wx2, wx3 = catmull_rom_weights(fx)
    wy0, wy1, wy2, wy3 = catmull_rom_weights(fy)
    weights[0, ux], weights[1, ux], weights[2, ux], weights[3, ux] = wx0, wx1, wx2, wx3
    weights[4, ux], weights[5, ux], weights[6, ux], weights[7, ux] = wy0, wy1, wy2, wy3
    for k in range(4):
        columns[k, ux] = U(x0 - 1 + k) if fx > _ZERO else U(x0)
        rows[k, ux] = U(y0 - 1 + k) if fy > _ZERO else U(y0)
    return True


@njit(
    inline="always", fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
    error_model="numpy",
)
def _bilinear(
    s: int, uy: np.uint64, ux: np.uint64, ya: np.uint64, yb: np.uint64, xa: np.uint64,
    xb: np.uint64, w00: np.float32, w10: np.float32, w01: np.float32, w11: np.float32,
    prev_illumination: np.ndarray, prev_moments: np.ndarray, prev_history_length: np.ndarray,
    out_illumination: np.ndarray, out_moments: np.ndarray, out_history_length: np.ndarray,
) -> None:
    """Signal ``s``'s history at the pixel: the taps with the given (normalised) weights.

    Indexes the 4-D arrays directly: a per-pixel sub-array view would cost an atomic
    reference-count update, contended between threads."""
    _bilinear_length(s, uy, ux, ya, yb, xa, xb, w00, w10, w01, w11, prev_history_length,
                     out_history_length)
    for c in range(3):
        out_illumination[s, c, uy, ux] = (
            w00 * prev_illumination[s, c, ya, xa] + w10 * prev_illumination[s, c, ya, xb]
            + w01 * prev_illumination[s, c, yb, xa] + w11 * prev_illumination[s, c, yb, xb]
        )
    for c in range(2):
        out_moments[s, c, uy, ux] = (
            w00 * prev_moments[s, c, ya, xa] + w10 * prev_moments[s, c, ya, xb]
            + w01 * prev_moments[s, c, yb, xa] + w11 * prev_moments[s, c, yb, xb]
        )


@njit(
    inline="always", fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
    error_model="numpy",
)
def _bilinear_length(
    s: int, uy: np.uint64, ux: np.uint64, ya: np.uint64, yb: np.uint64, xa: np.uint64,
    xb: np.uint64, w00: np.float32, w10: np.float32, w01: np.float32, w11: np.float32,
    prev_history_length: np.ndarray, out_history_length: np.ndarray,
) -> None:
    """Signal ``s``'s history length at the pixel: the taps with the given weights, a whole
    number where it is within 1e-3 of one."""
    out_history_length[s, uy, ux] = _whole_if_close(
        w00 * prev_history_length[s, ya, xa] + w10 * prev_history_length[s, ya, xb]
        + w01 * prev_history_length[s, yb, xa] + w11 * prev_history_length[s, yb, xb]
    )


def accumulate(
    illumination: np.ndarray,
    history_illumination: np.ndarray,
    history_moments: np.ndarray,
    history_length_prev: np.ndarray,
    depth: np.ndarray,
    alpha: np.float32,
    moments_alpha: np.float32,
    history_cap: np.float32,
    luminance_weights: tuple[np.float32, np.float32, np.float32],
    out_illumination: np.ndarray,
    out_moments: np.ndarray,
    out_history_length: np.ndarray,
) -> None:
    """Exponential moving average with adaptive alpha (paper eq. 6, alpha = max(a, 1/h)).

    ``history_length_prev`` (S, H, W) is the output of :func:`reproject` (0 = no history);
    each signal blends with its own history length. Background pixels get history length 0
    and their current illumination. The ``out_*`` arrays may be the history arrays
    themselves (the Denoiser accumulates in place); otherwise the history is copied into
    them first and :func:`accumulate_in_place` blends there.
    """
    for source, target in (
        (history_illumination, out_illumination),
        (history_moments, out_moments),
        (history_length_prev, out_history_length),
    ):
        if source is not target:
            np.copyto(target, source)
    accumulate_in_place(illumination, out_illumination, out_moments, out_history_length, depth,
                        alpha, moments_alpha, history_cap, luminance_weights)


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
    luminance_weights: tuple[np.float32, np.float32, np.float32],
) -> None:
    """:func:`accumulate` overwriting the (reprojected) history arrays with the result.

    Per signal ``s`` and pixel: ``h = min(cap, h_prev + 1)`` where there is history
    (``h_prev > 0``), else 1 (0 on background); ``c = lerp(c_hist, c, max(alpha, 1/h))`` and
    the luminance moments ``(l, l^2)`` with ``max(moments_alpha, 1/h)``. A stage that
    shortens ``history_length`` before this call (anti-lag) therefore raises that signal's
    blend factor at that pixel. Written branch-free over row slices (a blend factor of
    exactly 1 where there is no history) so it vectorizes; the history buffers must hold
    finite values everywhere. Reading and writing the same array (rather than a separate
    output that may alias it) keeps LLVM's runtime alias checks passing.
    """
    num_signals = illumination.shape[0]
    height, width = depth.shape
    for y in prange(height):
        blend = np.empty(width, dtype=np.float32)
        blend_moments = np.empty(width, dtype=np.float32)
        z = depth[y]
        for s in range(num_signals):
            h_row = history_length[s, y]
            for x in range(width):
                h_prev = h_row[x]
                surface = z[x] > _ZERO
                reused = surface and h_prev > _ZERO
                h = min(history_cap, h_prev + _ONE) if reused else _ONE
                h_row[x] = h if surface else _ZERO
                inv_h = _ONE / h
                blend[x] = max(alpha, inv_h) if reused else _ONE
                blend_moments[x] = max(moments_alpha, inv_h) if reused else _ONE
            r = illumination[s, 0, y]
            g = illumination[s, 1, y]
            b = illumination[s, 2, y]
            m1 = history_moments[s, 0, y]
            m2 = history_moments[s, 1, y]
            for x in range(width):
                lum = luminance(r[x], g[x], b[x], luminance_weights)
                a = blend_moments[x]
                m1[x] = (_ONE - a) * m1[x] + a * lum
                m2[x] = (_ONE - a) * m2[x] + a * (lum * lum)
            for c in range(3):
                current = illumination[s, c, y]
                out = history_illumination[s, c, y]
                for x in range(width):
                    a = blend[x]
                    out[x] = (_ONE - a) * out[x] + a * current[x]
