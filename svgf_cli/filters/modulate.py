"""Demodulation and remodulation of one signal (paper section 4: filter illumination).

Per signal and pixel a **mode** decides how the signal is filtered:

* **demodulated** (mode 0) where the signal's demodulation colour ``a`` is a plausible
  reflectance: ``max(a) >= black`` (not black) and ``max(a) <= max_reflectance`` (no
  channel above 1 + a small tolerance). The filter sees ``illumination = radiance / a'``
  with the per-channel floor ``a'_c = max(a_c, black, relative_floor * max(a))``;
* **radiance** (mode 1) elsewhere: black surfaces (dividing would turn their noise into
  huge values) and colours that are not reflectances (Cycles' ``Denoising Albedo`` reaches
  128 on mirror-like pixels): ``a' = 1``.

The modes of all signals of a pixel are one ``uint16`` mask, bit ``s`` for signal ``s``
(at most :data:`MAX_SIGNALS`; the top bit, :data:`NO_HISTORY`, marks a history pixel that
must not be resampled), so the stages that compare modes load one value per pixel.

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

from svgf_cli.filters.fastmath import FASTMATH, float32_bits
from svgf_cli.filters.values import (  # noqa: F401 - NO_HISTORY belongs to the mode mask
    NO_HISTORY,
    VALUE_LIMIT,
    is_extreme,
    is_nonfinite,
    is_usable,
)

F32 = np.float32
_ONE = F32(1.0)
_ZERO = F32(0.0)
_INF_BITS = np.int32(0x7F800000)
MAX_SIGNALS = 15  # bits of the uint16 mode mask below NO_HISTORY
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
    signal_index: int,
    out_illumination: np.ndarray,
    mode: np.ndarray,
    counts: np.ndarray,
) -> None:
    """One signal: ``out_illumination = clean(radiance) / a'`` (clamped to +-VALUE_LIMIT),
    and bit ``signal_index`` of the (H, W) uint16 ``mode`` mask (0 demodulated, 1 radiance;
    signal 0 writes the mask, later signals add their bit).

    ``counts`` (H, DEMODULATE_COUNTERS) int64 receives per row: non-finite and extreme
    radiance values, non-finite albedo values, radiance-mode surface pixels, implausible
    (above ``max_reflectance``) surface pixels and clamped illumination values. Branch-free
    over row slices, so it vectorizes.
    """
    height, width = depth.shape
    limit = VALUE_LIMIT
    bit = np.uint16(1 << signal_index)
    keep = np.uint16(0) if signal_index == 0 else ~bit
    for y in prange(height):
        a_r, a_g, a_b = albedo[0, y], albedo[1, y], albedo[2, y]
        r_r, r_g, r_b = radiance[0, y], radiance[1, y], radiance[2, y]
        o_r, o_g, o_b = out_illumination[0, y], out_illumination[1, y], out_illumination[2, y]
        z = depth[y]
        m = mode[y]
        nonfinite_radiance = 0
        extreme_radiance = 0
        nonfinite_albedo = 0
        radiance_mode = 0
        implausible = 0
        clamped = 0
        for x in range(width):
            nonfinite_albedo += is_nonfinite(a_r[x]) + is_nonfinite(a_g[x]) + is_nonfinite(a_b[x])
            ar = clean_albedo(a_r[x])
            ag = clean_albedo(a_g[x])
            ab = clean_albedo(a_b[x])
            demodulated, dr, dg, db = effective_albedo(ar, ag, ab, black, max_reflectance,
                                                       relative_floor)
            surface = z[x] > _ZERO
            radiance_mode += surface and not demodulated
            implausible += surface and max(ar, max(ag, ab)) > max_reflectance
            m[x] = (m[x] & keep) | (np.uint16(0) if demodulated else bit)
            vr = r_r[x]
            vg = r_g[x]
            vb = r_b[x]
            nonfinite_radiance += is_nonfinite(vr) + is_nonfinite(vg) + is_nonfinite(vb)
            extreme_radiance += is_extreme(vr) + is_extreme(vg) + is_extreme(vb)
            ir = clean_value(vr) / dr
            ig = clean_value(vg) / dg
            ib = clean_value(vb) / db
            clamped += (abs(ir) > limit) + (abs(ig) > limit) + (abs(ib) > limit)
            o_r[x] = min(max(ir, -limit), limit)
            o_g[x] = min(max(ig, -limit), limit)
            o_b[x] = min(max(ib, -limit), limit)
        counts[y, NONFINITE_RADIANCE] = nonfinite_radiance
        counts[y, EXTREME_RADIANCE] = extreme_radiance
        counts[y, NONFINITE_ALBEDO] = nonfinite_albedo
        counts[y, RADIANCE_MODE] = radiance_mode
        counts[y, IMPLAUSIBLE] = implausible
        counts[y, CLAMPED] = clamped


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
        z = depth[y]
        a_r, a_g, a_b = albedo[0, y], albedo[1, y], albedo[2, y]
        f_r, f_g, f_b = illumination[0, y], illumination[1, y], illumination[2, y]
        r_r, r_g, r_b = radiance[0, y], radiance[1, y], radiance[2, y]
        e_r, e_g, e_b = emission[0, y], emission[1, y], emission[2, y]
        o_r, o_g, o_b = out[0, y], out[1, y], out[2, y]
        for x in range(width):
            _, ar, ag, ab = effective_albedo(
                clean_albedo(a_r[x]), clean_albedo(a_g[x]), clean_albedo(a_b[x]), black,
                max_reflectance, relative_floor,
            )
            surface = z[x] > _ZERO
            vr = ar * f_r[x] if surface else clean_value(r_r[x])
            vg = ag * f_g[x] if surface else clean_value(r_g[x])
            vb = ab * f_b[x] if surface else clean_value(r_b[x])
            if has_emission:
                nonfinite += is_nonfinite(e_r[x]) + is_nonfinite(e_g[x]) + is_nonfinite(e_b[x])
                extreme += is_extreme(e_r[x]) + is_extreme(e_g[x]) + is_extreme(e_b[x])
                vr += clean_value(e_r[x])
                vg += clean_value(e_g[x])
                vb += clean_value(e_b[x])
            o_r[x] += vr
            o_g[x] += vg
            o_b[x] += vb
        counts[y, 0] = nonfinite
        counts[y, 1] = extreme


@njit(parallel=True, **_JIT)
def add_remodulated(alone: np.ndarray, emission: np.ndarray, has_emission: bool,
                    out: np.ndarray, counts: np.ndarray) -> None:
    """``out += alone`` (one signal as :func:`remodulate_add` gives it into zeros), with
    ``has_emission`` ``+= emission`` too, added as :func:`remodulate_add` adds it (to the
    signal's value before the sum) and counted alike into ``counts`` (H, 2): the same sum,
    bit for bit, where each signal's own radiance is wanted as well (the light layers), so
    each signal is remodulated once."""
    height, width = alone.shape[1], alone.shape[2]
    for y in prange(height):
        nonfinite = 0
        extreme = 0
        for c in range(3):
            a, e, o = alone[c, y], emission[c, y], out[c, y]
            if has_emission:
                for x in range(width):
                    nonfinite += is_nonfinite(e[x])
                    extreme += is_extreme(e[x])
                    o[x] += a[x] + clean_value(e[x])
            else:
                for x in range(width):
                    o[x] += a[x]
        counts[y, 0] = nonfinite
        counts[y, 1] = extreme


@njit(parallel=True, **_JIT)
def reflected_lights(guide: np.ndarray, max_reflectance: np.float32, out_lit: np.ndarray) -> bool:
    """``out_lit[y + 1, x + 1] = max(clean(guide[:, y, x])) > max_reflectance`` (uint8, an
    (H + 2, W + 2) plane whose one-pixel border is set to 0): where the G-buffer albedo is
    no reflectance. Returns whether any pixel is (if not, :func:`emitter_colour` would change
    nothing)."""
    height, width = guide.shape[1], guide.shape[2]
    # On the bits (fast-math may not keep NaN and Inf tests): for m > 0, clean(v) > m is
    # bits(m) < bits(v) < bits(+Inf) as int32 (negative values, NaN and Inf fall outside).
    above = float32_bits(max_reflectance)
    out_lit[0, :] = 0
    out_lit[height + 1, :] = 0
    for y in prange(height):
        g_r, g_g, g_b = guide[0, y], guide[1, y], guide[2, y]
        row = out_lit[y + 1, 1:width + 1]
        out_lit[y + 1, 0] = 0
        out_lit[y + 1, width + 1] = 0
        for x in range(width):
            r, g, b = float32_bits(g_r[x]), float32_bits(g_g[x]), float32_bits(g_b[x])
            bright = (((r > above) & (r < _INF_BITS)) | ((g > above) & (g < _INF_BITS))
                      | ((b > above) & (b < _INF_BITS)))
            row[x] = np.uint8(1) if bright else np.uint8(0)
    # Reduced outside the loop: a count or an or-reduction inside it stops it vectorizing.
    return bool(out_lit.any())


# A reflected light's image is large where more than half of a 5x5 window saw it
# (``LARGE_IMAGE_COUNT`` of 25); no pixel within ``LARGE_IMAGE_REACH`` of such a window's
# centre counts as lit. Radiance mode keeps a light's small image (a few pixels) from being
# averaged into the dark surface around it; a large image's inside is uniformly bright and
# the a-trous' luminance stop keeps it demodulated, while the mode's boundary would follow
# the random hits along its soft rim (a rough reflection at 640x360: a jagged highlight).
LARGE_IMAGE_RADIUS = 2
LARGE_IMAGE_COUNT = 13
LARGE_IMAGE_REACH = 2


@njit(parallel=True, **_JIT)
def unmark_large_images(lit: np.ndarray, counts: np.ndarray, near: np.ndarray) -> None:
    """In place on ``lit`` ((H + 2, W + 2) uint8 from :func:`reflected_lights`): 0 on every
    pixel within ``LARGE_IMAGE_REACH`` (a square) of a pixel whose (2 LARGE_IMAGE_RADIUS +
    1)^2 window, clipped by the image, holds ``LARGE_IMAGE_COUNT`` or more lit pixels.
    ``counts`` and ``near`` are (H, W) uint8 scratch planes (separable sums and maxima)."""
    height, width = counts.shape
    r, reach = LARGE_IMAGE_RADIUS, LARGE_IMAGE_REACH
    for y in prange(height):  # lit pixels of each row's window span
        _window_row(lit[y + 1, 1:width + 1], r, False, counts[y])
    for y in prange(height):  # ... summed down the window's rows: a large image's centre
        out = near[y]
        out[:] = 0
        for yy in range(max(y - r, 0), min(y + r + 1, height)):
            row = counts[yy]
            for x in range(width):
                out[x] += row[x]
        for x in range(width):
            out[x] = np.uint8(1) if out[x] >= LARGE_IMAGE_COUNT else np.uint8(0)
    for y in prange(height):  # the centres spread along the row ...
        _window_row(near[y], reach, True, counts[y])
    for y in prange(height):  # ... and down the rows: those pixels are not lit
        out = lit[y + 1, 1:width + 1]
        for yy in range(max(y - reach, 0), min(y + reach + 1, height)):
            row = counts[yy]
            for x in range(width):  # both planes hold 0 or 1: a branch-free 'and not'
                out[x] &= row[x] ^ np.uint8(1)


@njit(**_JIT)
def _window_row(row: np.ndarray, radius: int, spread: bool, out: np.ndarray) -> None:
    """``out[x]`` = the sum (or, with ``spread``, the or) of ``row[x - radius .. x +
    radius]`` clipped by the row, uint8."""
    width = row.shape[0]
    out[:] = 0
    for d in range(-radius, radius + 1):  # one shifted row at a time: vectorizes
        lo, hi = max(0, -d), min(width, width - d)
        if spread:
            for x in range(lo, hi):
                out[x] |= row[x + d]
        else:
            for x in range(lo, hi):
                out[x] += row[x + d]


# A reflected light is marked where at least this many of the pixel's 8 neighbours also
# saw it: on an object whose reflections are sharp (``filters.reflected_albedo``) one, as
# a small light's image may be a pair of pixels; elsewhere two, as a rough metal's samples
# of a light are scattered hits, a lone pixel or a pair (Cycles' rough gold bust at 4 spp:
# a pair at 26 and 18 where the reference is 2 and its 5x5 maximum 5), which marked were
# filtered only with each other and kept.
LIT_NEIGHBOURS_SHARP = 1
LIT_NEIGHBOURS_ROUGH = 2


@njit(parallel=True, **_JIT)
def emitter_colour(
    albedo: np.ndarray, guide: np.ndarray, lit: np.ndarray, depth: np.ndarray,
    mesh_id: np.ndarray, low_id: int, sharp: np.ndarray, out: np.ndarray, marked: np.ndarray,
) -> None:
    """A glossy signal's demodulation colour with reflected lights marked radiance:
    ``out = clean(guide)`` where the G-buffer albedo is no reflectance at the pixel and at
    ``LIT_NEIGHBOURS_SHARP`` or more of its 8 neighbours on a sharp object
    (``sharp[mesh_id - low_id] > 0``, uint8; ids outside the table are not),
    ``LIT_NEIGHBOURS_ROUGH`` or more elsewhere (``lit`` from
    :func:`reflected_lights`; ``clean(guide)``
    then puts the pixel in radiance mode, :func:`effective_albedo`), else ``out = albedo``.
    ``marked`` (H,) int64 receives per row the surface pixels (depth > 0) so marked.

    Why: Cycles' ``Denoising Albedo`` holds the light's emission (up to ~1000) where a
    specular path from the pixel reached a light. On a polished surface such samples form
    the light's sharp reflected image, hundreds of times brighter than the neighbours whose
    samples missed it; demodulated by the glossy colour they would be averaged with those
    neighbours (a sharp highlight blurred into a dim blob). In radiance mode they are
    filtered among themselves, as the combined signal does. A hit with fewer such neighbours
    is a sample of a rough surface's blurry reflection: it stays demodulated, so the a-trous
    spreads its light (alone in its mode it would only be clamped by the despike). A
    renderer whose albedo AOV stays a reflectance changes nothing.
    """
    height, width = albedo.shape[1], albedo.shape[2]
    size = np.int64(sharp.size)
    for y in prange(height):
        above, here, below = lit[y], lit[y + 1], lit[y + 2]
        g_r, g_g, g_b = guide[0, y], guide[1, y], guide[2, y]
        a_r, a_g, a_b = albedo[0, y], albedo[1, y], albedo[2, y]
        o_r, o_g, o_b = out[0, y], out[1, y], out[2, y]
        z, ids = depth[y], mesh_id[y]
        count = np.int32(0)
        for x in range(width):
            neighbours = (above[x] + above[x + 1] + above[x + 2] + here[x] + here[x + 2]
                          + below[x] + below[x + 1] + below[x + 2])
            k = np.int64(ids[x]) - low_id
            on_sharp = (k >= 0) & (k < size) and sharp[k] > 0  # read only inside the table
            needed = LIT_NEIGHBOURS_SHARP if on_sharp else LIT_NEIGHBOURS_ROUGH
            emitter = (here[x + 1] > 0) & (neighbours >= needed)
            o_r[x] = clean_albedo(g_r[x]) if emitter else a_r[x]
            o_g[x] = clean_albedo(g_g[x]) if emitter else a_g[x]
            o_b[x] = clean_albedo(g_b[x]) if emitter else a_b[x]
            count += np.int32(1) if emitter & (z[x] > _ZERO) else np.int32(0)
        marked[y] = count
