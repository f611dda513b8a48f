"""Despike: the last guard before remodulation against fireflies the spatial filter kept.

The a-trous stops at luminance differences measured against the *centre* pixel's noise. A
fresh firefly (one bright path sample, e.g. a specular bounce that found a light) makes its
neighbours reject it, since their own noise is small, while the bright pixel keeps most of its
value: the firefly survives filtering as an isolated spike several times brighter than
everything around it (up to 20x the converged image's local maximum on glossy metal). A
firefly in the history comes back as a pair of spikes, once bilinear reprojection has split
it between two pixels. Genuine detail after filtering is either wider or a line, whose
pixels each have two bright neighbours; so a filtered pixel brighter than ``ratio`` times
its *second*-brightest neighbour is a spike of one or two pixels: :func:`despike` brings its
luminance down to that bound, hue kept. (Against the brightest neighbour alone, each pixel
of a pair shelters the other: metal kept 3.7x hot pixels, 2.8x with the second.) The cost is
at the end of a thin line and on a glint of two pixels, which are lowered to twice their
surroundings.

Only the output is changed: the colour history (fed back from an earlier iteration) keeps the
sample, so its energy still enters the temporal average, at the usual weight. Neighbours
count only when they are surface pixels filtered in the same mode (demodulated or radiance)
as the centre; a pixel without such neighbours is left alone.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from svgf_cli.filters.fastmath import FASTMATH

F32 = np.float32
_ZERO = F32(0.0)
# The luminance of a pixel that is never a neighbour (background). Finite: FASTMATH assumes
# no infinities, so a comparison with -inf may be folded away.
_NONE = F32(-np.finfo(np.float32).max)


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
      error_model="numpy")
def _neighbours(
    luminance: np.ndarray, mode: np.ndarray, depth: np.ndarray, y: int, bit: np.uint16,
    bits: np.uint16,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Over the 8 neighbours ``q`` of each pixel ``p`` of row ``y``: the largest and the
    second-largest ``luminance[q]`` among those whose ``mode`` agrees with ``p``'s in
    ``bit`` (0: all of them; background pixels hold ``_NONE``), and the bits of ``bits`` in
    which some surface neighbour's ``mode`` agrees with ``p``'s."""
    height, width = luminance.shape
    brightest = np.full(width, _NONE, dtype=F32)
    second = np.full(width, _NONE, dtype=F32)
    agreeing = np.zeros(width, dtype=np.uint16)
    centre_mode = mode[y]
    for dy in range(-1, 2):
        yy = y + dy
        if yy < 0 or yy >= height:
            continue
        lum_row = luminance[yy]
        mode_row = mode[yy]
        depth_row = depth[yy]
        for dx in range(-1, 2):
            if dy == 0 and dx == 0:
                continue
            # x + dx stays inside the row for x in [first, last).
            first = max(0, -dx)
            last = width - max(0, dx)
            for x in range(first, last):
                q = x + dx
                differing = mode_row[q] ^ centre_mode[x]
                candidate = lum_row[q] if (differing & bit) == 0 else _NONE
                second[x] = max(second[x], min(brightest[x], candidate))
                brightest[x] = max(brightest[x], candidate)
                agree = np.uint16(~differing & bits)
                agreeing[x] |= agree if depth_row[q] > _ZERO else np.uint16(0)
    return brightest, second, agreeing


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def despike(
    illumination: np.ndarray,
    mode: np.ndarray,
    depth: np.ndarray,
    ratio: np.float32,
    luminance_weights: tuple[np.float32, np.float32, np.float32],
    luminance: np.ndarray,
    clamped: np.ndarray,
) -> None:
    """In place, per signal ``s`` and surface pixel ``p``: with ``M`` the second-largest
    ``l(q)`` over the 8 neighbours ``q`` of ``p`` that are surface pixels of the same mode
    (bit ``s`` of the uint16 ``mode``; the largest where there is only one), where
    ``M >= 0`` and ``l(p) > ratio * M``, scale the rgb of ``p`` by ``ratio * M / l(p)``.

    ``illumination`` is (S, 3, H, W); ``luminance`` an (H, W) float32 scratch (a signal's
    luminance is complete before any of its pixels changes, so the result does not depend
    on the order rows run in); ``clamped`` (H, S) int64 receives the number of pixels
    changed per row and signal.
    """
    num_signals = illumination.shape[0]
    height, width = depth.shape
    wr, wg, wb = luminance_weights
    for s in range(num_signals):
        bit = np.uint16(1 << s)
        # Pass 1: the signal's luminance, background excluded once and for all.
        for y in prange(height):
            d = depth[y]
            r = illumination[s, 0, y]
            g = illumination[s, 1, y]
            b = illumination[s, 2, y]
            lum = luminance[y]
            for x in range(width):
                value = wr * r[x] + wg * g[x] + wb * b[x]
                lum[x] = value if d[x] > _ZERO else _NONE
        # Pass 2: the two brightest same-mode neighbours, then the bound.
        for y in prange(height):
            brightest, second, _ = _neighbours(luminance, mode, depth, y, bit, np.uint16(0))
            d = depth[y]
            lum = luminance[y]
            r = illumination[s, 0, y]
            g = illumination[s, 1, y]
            b = illumination[s, 2, y]
            count = 0
            for x in range(width):
                # A lone same-mode neighbour is the only reference there is.
                reference = second[x] if second[x] > _NONE else brightest[x]
                bound = ratio * reference
                if d[x] > _ZERO and reference >= _ZERO and lum[x] > bound:
                    scale = bound / lum[x]
                    r[x] *= scale
                    g[x] *= scale
                    b[x] *= scale
                    count += 1
            clamped[y, s] = count


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def despike_lone(
    radiance: np.ndarray,
    emission: np.ndarray,
    has_emission: bool,
    mode: np.ndarray,
    depth: np.ndarray,
    num_signals: int,
    ratio: np.float32,
    luminance_weights: tuple[np.float32, np.float32, np.float32],
    luminance: np.ndarray,
    clamped: np.ndarray,
) -> None:
    """In place, on the composed output ``radiance`` (3, H, W): a surface pixel ``p`` that is
    *lone* in some signal ``s`` (bit ``s`` of ``mode`` differs from that of every surface
    neighbour) has its reflected part ``l(p) - e(p)`` (``e`` the emission's luminance, 0
    without ``has_emission``) brought down to ``ratio * M`` (rgb of ``radiance - emission``
    scaled), with ``M`` the second-largest output luminance ``l(q)`` over its 8 surface
    neighbours (the largest where there is only one), where ``M >= 0``.

    :func:`despike` compares a pixel only with neighbours filtered in the same mode, and the
    a-trous never mixes modes, so a pixel whose mode no neighbour shares is neither filtered
    nor guarded: a specular sample whose G-buffer "albedo" is no reflectance (filtered as
    radiance among demodulated neighbours), or the one plausible albedo in a patch below the
    guide floor. Its output is its own sample, up to 12x the converged image's local
    maximum on the rolling-ball render. In the output the modes share one scale, so the
    neighbours are compared there. ``luminance`` is an (H, W) float32 scratch; ``clamped``
    (H,) int64 receives the number of pixels changed per row.
    """
    height, width = depth.shape
    wr, wg, wb = luminance_weights
    all_bits = np.uint16((1 << num_signals) - 1)
    for y in prange(height):
        d = depth[y]
        lum = luminance[y]
        r, g, b = radiance[0, y], radiance[1, y], radiance[2, y]
        for x in range(width):
            value = wr * r[x] + wg * g[x] + wb * b[x]
            lum[x] = value if d[x] > _ZERO else _NONE
    for y in prange(height):
        brightest, second, agreeing = _neighbours(luminance, mode, depth, y, np.uint16(0),
                                                  all_bits)
        d = depth[y]
        lum = luminance[y]
        count = 0
        for x in range(width):
            lone = (agreeing[x] & all_bits) != all_bits
            reference = second[x] if second[x] > _NONE else brightest[x]
            if not (d[x] > _ZERO and lone and reference >= _ZERO):
                continue
            glow = _ZERO
            if has_emission:
                glow = (wr * emission[0, y, x] + wg * emission[1, y, x]
                        + wb * emission[2, y, x])
            reflected = lum[x] - glow
            bound = ratio * reference
            if reflected > bound:
                scale = bound / reflected
                for c in range(3):
                    own = emission[c, y, x] if has_emission else _ZERO
                    radiance[c, y, x] = own + (radiance[c, y, x] - own) * scale
                count += 1
        clamped[y] = count
