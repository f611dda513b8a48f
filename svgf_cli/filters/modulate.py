"""Albedo demodulation and remodulation (paper section 4: filter illumination, not radiance).

``illumination = (signal - emission) / max(albedo, eps)`` per channel, so texture detail never
reaches the filter; after filtering ``radiance = max(albedo, eps) * illumination + emission``.
Remodulating with the same floored albedo makes the pair an exact inverse (a constant input
stays constant even where one albedo channel is below ``eps``). Pixels whose albedo is below
``eps`` in every channel (black or metallic surfaces) are not demodulated at all: dividing
by the floor would turn their noise into huge illumination values, so they are filtered as
radiance (albedo treated as 1) - and only among themselves: :func:`filter_normals` negates
their normal for the edge-stopping weights, so ``max(0, n.n')`` is 0 between a demodulated
and a non-demodulated pixel and radiance never mixes with illumination.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from svgf_cli.filters.fastmath import FASTMATH, luminance

F32 = np.float32
_ONE = F32(1.0)
_ZERO = F32(0.0)


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, error_model="numpy")
def _effective_albedo(
    ar: np.float32, ag: np.float32, ab: np.float32, eps: np.float32
) -> tuple[np.float32, np.float32, np.float32]:
    if ar < eps and ag < eps and ab < eps:
        return _ONE, _ONE, _ONE
    return max(ar, eps), max(ag, eps), max(ab, eps)


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def demodulate(
    signal: np.ndarray,
    emission: np.ndarray,
    has_emission: bool,
    albedo: np.ndarray,
    eps: np.float32,
    out: np.ndarray,
) -> None:
    """Write the illumination ``(signal - emission) / max(albedo, eps)`` of one (3, H, W)
    signal into ``out``; ``emission`` is ignored unless ``has_emission``."""
    height, width = signal.shape[1], signal.shape[2]
    for y in prange(height):
        for x in range(width):
            er = eg = eb = _ZERO
            if has_emission:
                er = emission[0, y, x]
                eg = emission[1, y, x]
                eb = emission[2, y, x]
            ar, ag, ab = _effective_albedo(albedo[0, y, x], albedo[1, y, x], albedo[2, y, x], eps)
            out[0, y, x] = (signal[0, y, x] - er) / ar
            out[1, y, x] = (signal[1, y, x] - eg) / ag
            out[2, y, x] = (signal[2, y, x] - eb) / ab


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def remodulate(
    illumination: np.ndarray,
    emission: np.ndarray,
    has_emission: bool,
    albedo: np.ndarray,
    eps: np.float32,
    out: np.ndarray,
) -> None:
    """Inverse of :func:`demodulate`: ``out = max(albedo, eps) * illumination + emission``."""
    height, width = illumination.shape[1], illumination.shape[2]
    for y in prange(height):
        for x in range(width):
            er = eg = eb = _ZERO
            if has_emission:
                er = emission[0, y, x]
                eg = emission[1, y, x]
                eb = emission[2, y, x]
            ar, ag, ab = _effective_albedo(albedo[0, y, x], albedo[1, y, x], albedo[2, y, x], eps)
            out[0, y, x] = ar * illumination[0, y, x] + er
            out[1, y, x] = ag * illumination[1, y, x] + eg
            out[2, y, x] = ab * illumination[2, y, x] + eb


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def restore_background(radiance: np.ndarray, original: np.ndarray, depth: np.ndarray) -> None:
    """Background pixels (depth <= 0) are not filtered: copy their input radiance back."""
    height, width = depth.shape
    for y in prange(height):
        for x in range(width):
            if depth[y, x] <= _ZERO:
                radiance[0, y, x] = original[0, y, x]
                radiance[1, y, x] = original[1, y, x]
                radiance[2, y, x] = original[2, y, x]


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def luminance_plane(rgb: np.ndarray, out: np.ndarray) -> None:
    """Rec.709 luminance of a (3, H, W) image into an (H, W) plane."""
    height, width = rgb.shape[1], rgb.shape[2]
    for y in prange(height):
        r = rgb[0, y]
        g = rgb[1, y]
        b = rgb[2, y]
        o = out[y]
        for x in range(width):
            o[x] = luminance(r[x], g[x], b[x])


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def filter_normals(
    unit_normal: np.ndarray, albedo: np.ndarray, eps: np.float32, out: np.ndarray
) -> None:
    """Normals for the spatial weights: negated where the pixel is not demodulated."""
    height, width = unit_normal.shape[1], unit_normal.shape[2]
    for y in prange(height):
        for x in range(width):
            sign = _ONE
            if albedo[0, y, x] < eps and albedo[1, y, x] < eps and albedo[2, y, x] < eps:
                sign = -_ONE
            out[0, y, x] = sign * unit_normal[0, y, x]
            out[1, y, x] = sign * unit_normal[1, y, x]
            out[2, y, x] = sign * unit_normal[2, y, x]


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def remodulate_add(
    illumination: np.ndarray,
    signal: np.ndarray,
    emission: np.ndarray,
    has_emission: bool,
    albedo: np.ndarray,
    eps: np.float32,
    depth: np.ndarray,
    out: np.ndarray,
) -> None:
    """``out +=`` :func:`remodulate` of one signal on surface pixels, ``+= signal`` on
    background (depth <= 0): remodulation, background restore and the sum of the signals in
    one pass, without a full-frame temporary per signal."""
    height, width = illumination.shape[1], illumination.shape[2]
    for y in prange(height):
        for x in range(width):
            if depth[y, x] <= _ZERO:
                out[0, y, x] += signal[0, y, x]
                out[1, y, x] += signal[1, y, x]
                out[2, y, x] += signal[2, y, x]
                continue
            er = eg = eb = _ZERO
            if has_emission:
                er = emission[0, y, x]
                eg = emission[1, y, x]
                eb = emission[2, y, x]
            ar, ag, ab = _effective_albedo(albedo[0, y, x], albedo[1, y, x], albedo[2, y, x], eps)
            out[0, y, x] += ar * illumination[0, y, x] + er
            out[1, y, x] += ag * illumination[1, y, x] + eg
            out[2, y, x] += ab * illumination[2, y, x] + eb
