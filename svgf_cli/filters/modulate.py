"""Demodulation and remodulation of one signal (paper section 4: filter illumination).

Per signal and pixel a **mode** decides how the signal is filtered:

* **demodulated** (mode 0) where the signal's demodulation colour ``a`` is a plausible
  reflectance: ``max(a) >= black`` (not black) and ``max(a) <= max_reflectance`` (no
  channel above 1 + a small tolerance). The filter sees ``illumination = radiance / a'``
  with the per-channel floor ``a'_c = max(a_c, black, relative_floor * max(a))``;
* **radiance** (mode 1) elsewhere: black surfaces (dividing would turn their noise into
  huge values) and colours that are not reflectances (Cycles' ``Denoising Albedo`` reaches
  128 on mirror-like pixels): ``a' = 1``.

Remodulation multiplies by the same ``a'`` (an exact inverse: a constant input stays
constant). Why the floor is relative: remodulating pixel ``p`` scales a neighbour ``q``'s
contribution by ``a'_p / a'_q`` per channel, so with an absolute floor of 1e-3 a
saturated colour's dark channel multiplies whatever does not follow the albedo there (a
white highlight in the radiance, an antialiased edge) by up to 1000 before it leaks into its
neighbours; ``relative_floor`` bounds that gain to ``1 / relative_floor`` within a pixel's
colour (see ``bench/demodulation_floor.py`` for the measurement behind the default).

Pixels of different modes never exchange weight within a signal (the a-trous guides carry
the mode in the sign of the guide luminance, the spatial variance compares modes) nor
history (reprojection rejects a tap whose stored mode differs), so radiance and
illumination never mix.

Values (``filters.values``): non-finite and beyond-limit radiance become 0, non-finite
albedo channels 0, and the demodulated illumination is clamped to ``+-VALUE_LIMIT``; each
is counted per row.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from svgf_cli.filters.fastmath import FASTMATH
from svgf_cli.filters.values import VALUE_LIMIT, is_nonfinite, is_usable

F32 = np.float32
_ONE = F32(1.0)
_ZERO = F32(0.0)
DEMODULATED = np.uint8(0)
RADIANCE = np.uint8(1)
# Counters written per row by demodulate (columns of ``counts``).
NONFINITE_RADIANCE, EXTREME_RADIANCE, NONFINITE_ALBEDO, RADIANCE_MODE, IMPLAUSIBLE, CLAMPED = (
    range(6)
)
DEMODULATE_COUNTERS = 6

_JIT = dict(fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy")


@njit(inline="always", **_JIT)
def clean_value(v: np.float32) -> np.float32:
    """The value policy for radiance and emission: usable values pass, others become 0."""
    return v if is_usable(v) else _ZERO


@njit(inline="always", **_JIT)
def clean_albedo(v: np.float32) -> np.float32:
    """Non-finite albedo channels become 0 (large finite ones make the pixel radiance mode)."""
    return _ZERO if is_nonfinite(v) else v


@njit(inline="always", **_JIT)
def effective_albedo(
    ar: np.float32,
    ag: np.float32,
    ab: np.float32,
    black: np.float32,
    max_reflectance: np.float32,
    relative_floor: np.float32,
) -> tuple[bool, np.float32, np.float32, np.float32]:
    """``(demodulated, a'_r, a'_g, a'_b)`` of one (cleaned) demodulation colour."""
    brightest = max(ar, max(ag, ab))
    if not (brightest >= black and brightest <= max_reflectance):
        return False, _ONE, _ONE, _ONE
    floor = max(black, relative_floor * brightest)
    return True, max(ar, floor), max(ag, floor), max(ab, floor)


@njit(parallel=True, **_JIT)
def demodulate(
    radiance: np.ndarray,
    albedo: np.ndarray,
    depth: np.ndarray,
    black: np.float32,
    max_reflectance: np.float32,
    relative_floor: np.float32,
    out_illumination: np.ndarray,
    out_mode: np.ndarray,
    counts: np.ndarray,
) -> None:
    """One signal: ``out_illumination = clean(radiance) / a'`` (clamped to +-VALUE_LIMIT)
    and ``out_mode`` (0 demodulated, 1 radiance), both (3, H, W) / (H, W).

    ``counts`` (H, DEMODULATE_COUNTERS) int64 receives per row: non-finite and extreme
    radiance values, non-finite albedo values, radiance-mode surface pixels, implausible
    (above ``max_reflectance``) surface pixels and clamped illumination values.
    """
    height, width = depth.shape
    limit = VALUE_LIMIT
    for y in prange(height):
        row = np.zeros(DEMODULATE_COUNTERS, dtype=np.int64)
        for x in range(width):
            surface = depth[y, x] > _ZERO
            ar = clean_albedo(albedo[0, y, x])
            ag = clean_albedo(albedo[1, y, x])
            ab = clean_albedo(albedo[2, y, x])
            row[NONFINITE_ALBEDO] += (
                is_nonfinite(albedo[0, y, x]) + is_nonfinite(albedo[1, y, x])
                + is_nonfinite(albedo[2, y, x])
            )
            demodulated, dr, dg, db = effective_albedo(ar, ag, ab, black, max_reflectance,
                                                       relative_floor)
            out_mode[y, x] = DEMODULATED if demodulated else RADIANCE
            if surface and not demodulated:
                row[RADIANCE_MODE] += 1
                if max(ar, max(ag, ab)) > max_reflectance:
                    row[IMPLAUSIBLE] += 1
            for c, divisor in ((0, dr), (1, dg), (2, db)):
                v = radiance[c, y, x]
                if not is_usable(v):
                    if is_nonfinite(v):
                        row[NONFINITE_RADIANCE] += 1
                    else:
                        row[EXTREME_RADIANCE] += 1
                    v = _ZERO
                illumination = v / divisor
                if abs(illumination) > limit:
                    row[CLAMPED] += 1
                    illumination = min(max(illumination, -limit), limit)
                out_illumination[c, y, x] = illumination
        for k in range(DEMODULATE_COUNTERS):
            counts[y, k] = row[k]


@njit(parallel=True, **_JIT)
def remodulate(
    illumination: np.ndarray,
    albedo: np.ndarray,
    black: np.float32,
    max_reflectance: np.float32,
    relative_floor: np.float32,
    out: np.ndarray,
) -> None:
    """Inverse of :func:`demodulate`: ``out = a' * illumination`` (one signal, no emission)."""
    height, width = illumination.shape[1], illumination.shape[2]
    for y in prange(height):
        for x in range(width):
            _, ar, ag, ab = effective_albedo(
                clean_albedo(albedo[0, y, x]), clean_albedo(albedo[1, y, x]),
                clean_albedo(albedo[2, y, x]), black, max_reflectance, relative_floor,
            )
            out[0, y, x] = ar * illumination[0, y, x]
            out[1, y, x] = ag * illumination[1, y, x]
            out[2, y, x] = ab * illumination[2, y, x]


@njit(parallel=True, **_JIT)
def remodulate_add(
    illumination: np.ndarray,
    radiance: np.ndarray,
    albedo: np.ndarray,
    depth: np.ndarray,
    emission: np.ndarray,
    has_emission: bool,
    black: np.float32,
    max_reflectance: np.float32,
    relative_floor: np.float32,
    out: np.ndarray,
    counts: np.ndarray,
) -> None:
    """``out +=`` :func:`remodulate` of one signal on surface pixels and ``+= radiance``
    (cleaned, unfiltered) on background (depth <= 0); with ``has_emission`` also
    ``+= emission`` everywhere (cleaned; ``counts`` (H, 2) receives its non-finite and
    extreme values per row). Remodulation, background restore, the sum of the signals and
    the emission in one pass, without a full-frame temporary per signal."""
    height, width = illumination.shape[1], illumination.shape[2]
    for y in prange(height):
        nonfinite = 0
        extreme = 0
        for x in range(width):
            er = eg = eb = _ZERO
            if has_emission:
                for c in range(3):
                    v = emission[c, y, x]
                    if not is_usable(v):
                        if is_nonfinite(v):
                            nonfinite += 1
                        else:
                            extreme += 1
                er = clean_value(emission[0, y, x])
                eg = clean_value(emission[1, y, x])
                eb = clean_value(emission[2, y, x])
            if depth[y, x] <= _ZERO:
                out[0, y, x] += clean_value(radiance[0, y, x]) + er
                out[1, y, x] += clean_value(radiance[1, y, x]) + eg
                out[2, y, x] += clean_value(radiance[2, y, x]) + eb
                continue
            _, ar, ag, ab = effective_albedo(
                clean_albedo(albedo[0, y, x]), clean_albedo(albedo[1, y, x]),
                clean_albedo(albedo[2, y, x]), black, max_reflectance, relative_floor,
            )
            out[0, y, x] += ar * illumination[0, y, x] + er
            out[1, y, x] += ag * illumination[1, y, x] + eg
            out[2, y, x] += ab * illumination[2, y, x] + eb
        counts[y, 0] = nonfinite
        counts[y, 1] = extreme
