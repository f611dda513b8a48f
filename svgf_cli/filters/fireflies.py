"""Firefly spreading: a sample that is an outlier in time *and* in space hands its excess
energy to the surface around it, before it enters the temporal average.

A 1-spp firefly (a diffuse path that found a caustic or a small bright reflection) carries
energy the converged image spreads over many pixels; arriving in one pixel it is hundreds
of times brighter than its surroundings. Accumulated at weight alpha it stays several
frames, and the first a-trous iterations, which accept it along an edge, smear it into a
short bright streak that the output despike reads as a line (the tracer's glossy scene: 7x
the converged image's local maximum). Clamping the sample removes the spike but also its
energy: on the same scene relMSE rose 11 %, since that energy is part of the answer.

So the sample is bounded and the excess is *redistributed*, not dropped: per signal, a
surface sample ``p`` in the demodulated mode with luminance ``l(p)`` above

    L(p) = max(m1(p) + k * sqrt(max(m2(p) - m1(p)^2, 0)), ratio * M(p))

(``m1``, ``m2`` the reprojected history's luminance moments after anti-lag, ``M`` the
second-largest current luminance among its 8 same-mode surface neighbours: outlier against
its own past *and* against its neighbours; a lighting change raises the neighbours too) is
scaled down to ``L(p)`` (hue kept), and its excess rgb ``c(p) (1 - L(p) / l(p))`` is shared
equally among the surface pixels ``q`` of the ``(2 RADIUS + 1)^2`` window around ``p``
(``p`` included) in the same mode with ``|z(q) - z(p)| <= DEPTH_TOLERANCE z(p)``; for a
signal demodulated by the G-buffer albedo also ``|a(q) - a(p)| <= ALBEDO_TOLERANCE a(p)``
(``a`` the luminance of its colour: the same material, see ``ALBEDO_TOLERANCE``). The
signal's demodulated light over the image is unchanged; only where it sits moves by a few
pixels, which the converged image also spreads it over.

A glossy signal's firefly is shared over its 3x3 alone (``GLOSSY_RADIUS``, when asked), and
no receiver gains more than the firefly keeps, ``L(p)`` in luminance (the rest of the excess
is dropped): there a lone bright sample is most often a rare hit of a small highlight or of
its glow (a light seen in a polished or refracting surface, which one sample in a few dozen
finds), whose converged image is a few pixels wide; the 9x9 would smear it into a square,
and left alone its energy is dropped by the glossy history clamp, whose 3x3 rarely holds
another hit. The cap keeps a genuine firefly (a rare path whose light belongs far wider) or
a thin object's highlight from becoming a bright 3x3 block.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from svgf_cli.filters.fastmath import FASTMATH

F32 = np.float32
_ZERO = F32(0.0)
_ONE = F32(1.0)
# The luminance of a background pixel, never a neighbour. Finite: FASTMATH assumes no
# infinities, so a comparison with -inf may be folded away.
_BACKGROUND = F32(-np.finfo(np.float32).max)
# The window the excess is shared over: 9x9, wide enough that a firefly hundreds of times
# its surroundings ends below 3x their level (7x7 left the glossy scene at 3.4x).
RADIUS = 4
# A receiving pixel's depth within this fraction of the firefly's: the same surface.
DEPTH_TOLERANCE = F32(0.1)
# For a signal demodulated by the G-buffer albedo (``guide``), also its colour's luminance
# within this fraction of the firefly's. The excess is shared as demodulated light, which
# each receiver's colour remodulates. That is right for a reflectance (the illumination is
# what is smooth), but the G-buffer albedo is no reflectance of the glossy light such a
# signal carries: a glint over a dark checker square (0.06), shared onto a light one
# (0.48), came back eight times brighter (7.5x the reference's local maximum).
ALBEDO_TOLERANCE = F32(0.25)
ANY_COLOUR = F32(1e30)  # no colour test (finite: times a colour it must not overflow)
# How many times its second-brightest same-mode neighbour a sample must be.
NEIGHBOUR_RATIO = F32(4.0)
# A glossy signal's window: the 3x3. Measured (docs/algorithm.md, "Glossy fireflies"):
# the 9x9 turned a 1-pixel reflected highlight of the 128x72 metal fixture into a 9x9 square
# 16 times its surroundings (relMSE of that frame 0.04 -> 0.52).
GLOSSY_RADIUS = 1


@njit(
    parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy"
)
def _bounds(
    illumination: np.ndarray,
    moments: np.ndarray,
    mode: np.ndarray,
    depth: np.ndarray,
    bit: np.uint16,
    k: np.float32,
    ratio: np.float32,
    luminance_weights: tuple[np.float32, np.float32, np.float32],
    keep: np.ndarray,
    flagged: np.ndarray,
) -> None:
    """One signal: ``keep[y, x] = L(p) / l(p)`` where ``p`` is a firefly, else 1; the
    number of fireflies per row in ``flagged``.

    The temporal test comes first and is cheap; only the few samples that pass it look at
    their neighbours (every sample does on a frame without history)."""
    height, width = depth.shape
    wr, wg, wb = luminance_weights
    for y in prange(height):
        d = depth[y]
        r, g, b = illumination[0, y], illumination[1, y], illumination[2, y]
        m1 = moments[0, y]
        m2 = moments[1, y]
        own = mode[y]
        out = keep[y]
        # How far each sample is above its temporal bound (<= 0: not a firefly).
        for x in range(width):
            lum = wr * r[x] + wg * g[x] + wb * b[x]
            margin = lum - (m1[x] + k * np.sqrt(max(m2[x] - m1[x] * m1[x], _ZERO)))
            out[x] = margin if d[x] > _ZERO and (own[x] & bit) == 0 else -_ONE
        count = 0
        for x in range(width):
            margin = out[x]
            out[x] = _ONE
            if margin <= _ZERO:
                continue
            first = _BACKGROUND
            second = _BACKGROUND
            for yy in range(max(y - 1, 0), min(y + 2, height)):
                for xx in range(max(x - 1, 0), min(x + 2, width)):
                    if (yy == y and xx == x) or depth[yy, xx] <= _ZERO or (
                            mode[yy, xx] & bit) != 0:
                        continue
                    value = (wr * illumination[0, yy, xx] + wg * illumination[1, yy, xx]
                             + wb * illumination[2, yy, xx])
                    second = max(second, min(first, value))
                    first = max(first, value)
            # A lone same-mode neighbour is the only reference there is (as in despike).
            reference = second if second > _BACKGROUND else first
            lum = wr * r[x] + wg * g[x] + wb * b[x]
            bound = max(lum - margin, ratio * max(reference, _ZERO))
            if lum > bound:
                out[x] = bound / lum
                count += 1
        flagged[y] = count


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, error_model="numpy")
def _receives(zq: np.float32, z: np.float32, mode_q: np.uint16, bit: np.uint16,
              aq: np.float32, a: np.float32, tolerance: np.float32) -> bool:
    """Whether a pixel at depth ``zq`` in mode ``mode_q`` with demodulation-colour luminance
    ``aq`` shares a firefly at depth ``z`` with colour luminance ``a``."""
    return (zq > _ZERO and (mode_q & bit) == 0 and abs(zq - z) <= DEPTH_TOLERANCE * z
            and abs(aq - a) <= tolerance * a)


@njit(fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy")
def _share(
    illumination: np.ndarray,
    albedo: np.ndarray,
    albedo_tolerance: np.float32,
    luminance_weights: tuple[np.float32, np.float32, np.float32],
    mode: np.ndarray,
    depth: np.ndarray,
    bit: np.uint16,
    keep: np.ndarray,
    flagged: np.ndarray,
    radius: np.int64,
    capped: bool,
) -> int:
    """One signal: bound every firefly, then share each one's excess over its
    ``(2 radius + 1)^2`` window (``capped``: at most the firefly's bound to each receiver).
    Serial, in row order (fireflies are rare), so the sums are the same on every run; every
    excess is taken before any is shared, so the result does not depend on that order."""
    height, width = depth.shape
    total = 0
    for y in range(height):
        total += flagged[y]
    ys = np.empty(total, dtype=np.int64)
    xs = np.empty(total, dtype=np.int64)
    excess = np.empty((total, 3), dtype=F32)
    kept_luminance = np.empty(total, dtype=F32)
    wr, wg, wb = luminance_weights
    i = 0
    for y in range(height):
        if flagged[y] == 0:
            continue
        for x in range(width):
            if keep[y, x] < _ONE:
                ys[i] = y
                xs[i] = x
                for c in range(3):
                    value = illumination[c, y, x]
                    kept = value * keep[y, x]
                    excess[i, c] = value - kept
                    illumination[c, y, x] = kept
                kept_luminance[i] = (wr * illumination[0, y, x] + wg * illumination[1, y, x]
                                     + wb * illumination[2, y, x])
                i += 1
    for i in range(total):
        y, x = ys[i], xs[i]
        z = depth[y, x]
        a = wr * albedo[0, y, x] + wg * albedo[1, y, x] + wb * albedo[2, y, x]
        y0, y1 = max(y - radius, 0), min(y + radius + 1, height)
        x0, x1 = max(x - radius, 0), min(x + radius + 1, width)
        receivers = 0
        for yy in range(y0, y1):
            for xx in range(x0, x1):
                aq = wr * albedo[0, yy, xx] + wg * albedo[1, yy, xx] + wb * albedo[2, yy, xx]
                if _receives(depth[yy, xx], z, mode[yy, xx], bit, aq, a, albedo_tolerance):
                    receivers += 1
        share = _ONE / F32(receivers)  # p itself always receives
        if capped:  # each receiver gains at most the firefly's own bound
            lost = wr * excess[i, 0] + wg * excess[i, 1] + wb * excess[i, 2]
            most = max(kept_luminance[i], _ZERO) * F32(receivers)
            if lost > most:
                share *= most / lost
        for yy in range(y0, y1):
            for xx in range(x0, x1):
                aq = wr * albedo[0, yy, xx] + wg * albedo[1, yy, xx] + wb * albedo[2, yy, xx]
                if _receives(depth[yy, xx], z, mode[yy, xx], bit, aq, a, albedo_tolerance):
                    for c in range(3):
                        illumination[c, yy, xx] += excess[i, c] * share
    return total


def spread_fireflies(
    illumination: np.ndarray,
    albedo: list[np.ndarray],
    guide: tuple[bool, ...],
    moments: np.ndarray,
    mode: np.ndarray,
    depth: np.ndarray,
    radii: tuple[int, ...],
    k: float,
    luminance_weights: tuple[np.float32, np.float32, np.float32],
    keep: np.ndarray,
    capped: tuple[bool, ...] = (),
) -> list[int]:
    """In place on the current samples ``illumination`` (S, 3, H, W): per signal ``s`` with
    ``radii[s] > 0``, bound each firefly to ``L(p)`` and share its excess over the
    ``(2 radii[s] + 1)^2`` window around it (the module docstring's rule); ``moments``
    (S, 2, H, W) are the reprojected history's, ``albedo`` the signals' demodulation
    colours (3, H, W) each and ``guide`` whether each is the G-buffer albedo
    (``Signal.guide_albedo``), ``mode`` the (H, W) uint16 modes (bit ``s`` set: radiance).
    ``keep`` is an (H, W) float32 scratch plane. A signal with ``capped[s]`` gives each
    receiver at most the firefly's bound ``L(p)`` (luminance) and drops the rest. Returns
    the number of fireflies per signal."""
    height = depth.shape[0]
    flagged = np.zeros(height, dtype=np.int64)
    counts = []
    for s, radius in enumerate(radii):
        if radius <= 0:
            counts.append(0)
            continue
        bit = np.uint16(1 << s)
        _bounds(illumination[s], moments[s], mode, depth, bit, F32(k), NEIGHBOUR_RATIO,
                luminance_weights, keep, flagged)
        tolerance = ALBEDO_TOLERANCE if guide[s] else ANY_COLOUR
        counts.append(int(_share(illumination[s], albedo[s], tolerance, luminance_weights,
                                 mode, depth, bit, keep, flagged, np.int64(radius),
                                 bool(capped) and capped[s])))
    return counts
