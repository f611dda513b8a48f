"""A float64 reference of the SVGF ``Denoiser``, written from the documented equations.

This is test support, not production code: plain numpy/Python in float64, loops over pixels
(or over taps, vectorised over pixels) in the most obvious order, no scratch sharing, no
fast exp/log, no bit masks, no row balancing. It is written from the paper (Schied et al.
2017), ``docs/algorithm.md``, ``docs/robustness.md`` and the kernels' docstrings, never by
transcribing a kernel, so a kernel that departs from its documentation disagrees with it.

Structure (one function per stage, so each can be compared with its kernel alone, and a
small :class:`ReferenceDenoiser` that owns float64 history, so the whole can be compared
frame by frame):

======================  =======================================================  ===========
stage                   function(s)                                              kernel(s)
======================  =======================================================  ===========
values                  :func:`apply_value_policy` (:func:`clean_value`,         values,
                        :func:`clean_albedo`, :func:`clean_depth`,               modulate
                        :func:`clean_normal`, :func:`clean_motion`)
0 geometry              :func:`unit_normals`, :func:`depth_gradients`,           gradients
                        :func:`normal_gradient`, :func:`geometry`
1 demodulation          :func:`effective_albedo` (the mode rule),                modulate
                        :func:`demodulate`
+ firefly clamp         :func:`firefly_clamp`                                    clamp
2 reprojection          :func:`tap_consistent`, :func:`reproject` (per signal,   reproject
                        mode-matched taps)
+ anti-lag hook         :meth:`ReferenceDenoiser.before_accumulation`            denoiser
+ history clamp         :func:`history_clamp`                                    clamp
+ anti-lag              :func:`antilag` (:func:`antilag_gradient_change`)         antilag
+ firefly spreading     :func:`spread_fireflies`                                 fireflies
2 accumulation          :func:`accumulate` (paper eq. 6, 1/h ramp per signal)    reproject
3 variance              :func:`temporal_variance`, :func:`spatial_variance`,     variance
                        :func:`boost_short_history`, :func:`estimate_variance`
4 a-trous               :func:`luminance_stop_guides`, :func:`atrous_iteration`  atrous
                        (paper eqs. 1-5), :func:`atrous_steps` (2^i)
history guard           :func:`reset_nonfinite_history`                          values
+ despike               :func:`despike`                                          despike
5 remodulation          :func:`remodulate`, :func:`radiance_with_background`,    modulate
                        emission added once
+ TAA                   :func:`taa_resolve`; on jittered frames                  taa
                        (:func:`jittered_samples`, :func:`plane_triples`)        jitter
======================  =======================================================  ===========

Shapes follow ``svgf_cli.frame``: colour-like planes ``(3, H, W)``, several signals
``(S, 3, H, W)``, moments ``(S, 2, H, W)``, variance and history length ``(S, H, W)``, modes
``(S, H, W)`` booleans (True: the signal is filtered as radiance at that pixel), scalar
planes ``(H, W)``; depth ``<= 0`` is background; motion is backward, in pixels (the surface
seen at pixel ``(x, y)`` was at ``(x + motion.x, y + motion.y)`` in the previous frame, in
pixel-index space). Every function accepts float32 or float64 arrays and returns float64.

Extending it (anti-lag, lobe signals, ...): add a stage function with its equation in the
docstring, a stage test against its kernel in ``tests/test_reference_stages.py``, and call
it from :meth:`ReferenceDenoiser.process` in pipeline order. Nothing here is shared between
stages except the :class:`Geometry` of the frame, so a new stage can be slotted in without
touching the others.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from svgf_cli.filters.bidirectional import (
    CONSISTENCY_SIGMA,
    GLOSSY_REFERENCE_COUNT,
    PASS_ANTILAG_SIGMA_SCALE,
    STATIC_FILTERED_SHARE,
    STATIC_MOTION,
)
from svgf_cli.filters.params import SVGFParams, antilag_radius_for, luminance_stop_scale_for
from svgf_cli.frame import Frame, Signal

F64 = np.float64
REC709 = (0.2126, 0.7152, 0.0722)  # Rec.709 luminance weights, the default colour space
B3 = np.array([1.0, 4.0, 6.0, 4.0, 1.0]) / 16.0  # the B3-spline a-trous kernel h
G3 = np.array([0.25, 0.5, 0.25])  # 1-D factor of the 3x3 Gaussian that prefilters variance
DEPTH_EPSILON = 1e-3  # w_z's depth-relative epsilon: 1e-3 z(p) (docs/algorithm.md, edges.py)
RELATIVE_DEVIATION_FLOOR = 1e-5  # w_l's deviation is at least 1e-5 l(p) ...
MIN_SCALE = 1e-20  # ... and its scale at least 1e-20 (black pixels)
SPATIAL_TINY = 1e-30  # added to the spatial variance's luminance scale (0/0 on black)
NORMAL_SLACK = 0.01  # reprojection normal test: tolerance * (fwidth_n + 0.01)
MIN_BILINEAR_WEIGHT = 0.01  # passing bilinear weights summing below this are rejected
WHOLE_SNAP = 1e-3  # a resampled history length this close to a whole count is that count
VALUE_LIMIT = 1e15  # inputs beyond it are blow-ups; demodulated values are clamped to it
MAX_REFLECTANCE = 1.05  # a demodulation colour brighter than this is not a reflectance
# A reflected light's pixel has this many lit neighbours or more (the rule off sharp
# mirrors: the reference has no reflected albedo, and its scenes no sharp mirror).
MIN_LIT_NEIGHBOURS = 2
# ... and is farther than 2 pixels (a square) from the centre of a 5x5 window of which 13
# or more pixels are lit: a light's large image stays demodulated.
LARGE_IMAGE_WINDOW, LARGE_IMAGE_COUNT, LARGE_IMAGE_REACH = 5, 13, 2
RELATIVE_ALBEDO_FLOOR = 0.02  # per-channel floor relative to the brightest channel
NO_HISTORY_MOTION = 1e15  # what non-finite motion becomes: a position far outside the image


def luminance(rgb: np.ndarray, weights: Sequence[float] = REC709) -> np.ndarray:
    """``w_r r + w_g g + w_b b`` over the colour axis (the axis of length 3 just before
    H, W), with the frame's luminance weights."""
    return np.moveaxis(np.asarray(rgb, dtype=F64), -3, -1) @ np.asarray(weights, dtype=F64)


# --------------------------------------------------------------------------- values
def usable(values: np.ndarray) -> np.ndarray:
    """Finite and ``|v| <= VALUE_LIMIT`` (NaN compares false)."""
    with np.errstate(invalid="ignore"):
        return np.abs(np.asarray(values, dtype=F64)) <= VALUE_LIMIT


def clean_value(values: np.ndarray) -> np.ndarray:
    """Radiance and emission: non-finite values and values beyond +-1e15 become 0."""
    v = np.asarray(values, dtype=F64)
    return np.where(usable(v), v, 0.0)


def clean_albedo(albedo: np.ndarray) -> np.ndarray:
    """Demodulation colours: non-finite channels become 0 (large finite ones are kept; the
    mode rule then filters such a pixel as radiance)."""
    a = np.asarray(albedo, dtype=F64)
    return np.where(np.isfinite(a), a, 0.0)


def clean_depth(depth: np.ndarray) -> np.ndarray:
    """Non-finite depth and depth beyond +-1e15 become background (0)."""
    z = np.asarray(depth, dtype=F64)
    return np.where(usable(z), z, 0.0)


def clean_normal(normal: np.ndarray) -> np.ndarray:
    """A normal with a non-finite component or one beyond +-1e15 becomes the zero normal."""
    n = np.asarray(normal, dtype=F64)
    return np.where(np.all(usable(n), axis=0)[None], n, 0.0)


def clean_motion(motion: np.ndarray) -> np.ndarray:
    """Motion with a non-finite component becomes ``(1e15, 1e15)``: no history (large
    finite motion is kept: it only means no history too)."""
    m = np.asarray(motion, dtype=F64)
    return np.where(np.all(np.isfinite(m), axis=0)[None], m, NO_HISTORY_MOTION)


def count_bad(values: np.ndarray) -> tuple[int, int]:
    """(non-finite values, finite values beyond +-1e15)."""
    v = np.asarray(values, dtype=F64)
    nonfinite = ~np.isfinite(v)
    with np.errstate(invalid="ignore"):
        extreme = np.isfinite(v) & (np.abs(v) > VALUE_LIMIT)
    return int(nonfinite.sum()), int(extreme.sum())


@dataclass
class CleanFrame:
    """A frame after the value policy, in float64: what every later stage reads.

    ``radiance`` and ``albedo`` are ``(S, 3, H, W)``: each signal's radiance (emission
    excluded) and demodulation colour; ``counts`` are the policy's counts with the keys of
    ``DenoisedFrame.counts`` (``frame.COUNT_KEYS``)."""

    names: list[str]
    radiance: np.ndarray
    albedo: np.ndarray
    emission: np.ndarray | None
    depth: np.ndarray
    normal: np.ndarray
    motion: np.ndarray
    mesh_id: np.ndarray
    weights: tuple[float, float, float]
    counts: dict[str, int] = field(default_factory=dict)
    glossy: list[bool] = field(default_factory=list)  # per signal: Signal.glossy
    guide: list[bool] = field(default_factory=list)  # per signal: Signal.guide_albedo
    mixed: list[bool] = field(default_factory=list)  # per signal: Signal.mixed
    centre_sampled: bool = False  # Frame.centre_sampled


def _count(counts: dict[str, int], kind: str, plane: str, value: int) -> None:
    counts[kind] = counts.get(kind, 0) + value
    if value:
        counts[f"{kind}.{plane}"] = counts.get(f"{kind}.{plane}", 0) + value


def apply_value_policy(frame: Frame) -> CleanFrame:
    """``docs/robustness.md`` "Inside the filter": replace and count what would overflow.

    Radiance and emission beyond +-1e15 or non-finite -> 0; non-finite albedo -> 0; bad
    depth -> background; a normal with a bad component -> the zero normal; non-finite motion
    -> no history. Counted per plane as non-finite or extreme (beyond the limit; not for
    albedo, where a large value is only implausible, nor motion, where it is harmless).
    """
    counts: dict[str, int] = {"nonfinite": 0, "extreme": 0, "history_resets": 0}
    for name, plane, extreme_counts in (("depth", frame.depth, True),
                                        ("normal", frame.normal, True),
                                        ("motion", frame.motion, False)):
        nonfinite, extreme = count_bad(plane)
        _count(counts, "nonfinite", name, nonfinite)
        _count(counts, "extreme", name, extreme if extreme_counts else 0)
    for signal in frame.signals:
        nonfinite, extreme = count_bad(signal.radiance)
        _count(counts, "nonfinite", f"radiance.{signal.name}", nonfinite)
        _count(counts, "extreme", f"radiance.{signal.name}", extreme)
        _count(counts, "nonfinite", f"albedo.{signal.name}", count_bad(signal.albedo)[0])
    emission = None
    if frame.emission is not None:
        nonfinite, extreme = count_bad(frame.emission)
        _count(counts, "nonfinite", "emission", nonfinite)
        _count(counts, "extreme", "emission", extreme)
        emission = clean_value(frame.emission)
    weights = tuple(float(w) for w in frame.luminance_weights)
    return CleanFrame(
        names=[s.name for s in frame.signals],
        radiance=np.stack([clean_value(s.radiance) for s in frame.signals]),
        albedo=np.stack([clean_albedo(s.albedo) for s in frame.signals]),
        emission=emission, depth=clean_depth(frame.depth), normal=clean_normal(frame.normal),
        motion=clean_motion(frame.motion), mesh_id=np.asarray(frame.mesh_id),
        weights=(weights[0], weights[1], weights[2]), counts=counts,
        glossy=[s.glossy for s in frame.signals],
        guide=[s.guide_albedo for s in frame.signals],
        mixed=[s.mixed for s in frame.signals],
        centre_sampled=frame.centre_sampled,
    )


# --------------------------------------------------------------------------- 0 geometry
def unit_normals(normal: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """Unit normals; background (depth <= 0) and degenerate normals (|n|^2 <= 1e-12) are 0.

    A zero normal makes ``max(0, n.n')`` vanish, so no spatial weight flows to or from it.
    """
    n = np.asarray(normal, dtype=F64)
    z = np.asarray(depth, dtype=F64)
    length_sq = np.sum(n * n, axis=0)
    keep = (z > 0.0) & (length_sq > 1e-12)
    out = np.zeros_like(n)
    out[:, keep] = n[:, keep] / np.sqrt(length_sq[keep])
    return out


def _one_sided(left_ok: bool, right_ok: bool, left: Any, right: Any,
               size: Callable[[Any], float], zero: Any) -> Any:
    """The usable one-sided difference of smaller ``size``; the left/up one on a tie."""
    if left_ok and right_ok:
        return left if size(left) <= size(right) else right
    if left_ok:
        return left
    if right_ok:
        return right
    return zero


def depth_gradients(depth: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Signed per-axis depth derivatives ``ddx``, ``ddy`` and the reprojection slope
    ``max(|ddx|, |ddy|)``.

    Per axis: the smaller (in magnitude) of the two one-sided differences, using only sides
    whose neighbour is inside the image and not background, so a silhouette does not
    inflate the slope of the surface it bounds. Background and pixels without a usable side
    get 0.
    """
    z = np.asarray(depth, dtype=F64)
    height, width = z.shape
    ddx = np.zeros_like(z)
    ddy = np.zeros_like(z)
    for y in range(height):
        for x in range(width):
            if z[y, x] <= 0.0:
                continue
            left_ok = x > 0 and z[y, x - 1] > 0.0
            right_ok = x < width - 1 and z[y, x + 1] > 0.0
            up_ok = y > 0 and z[y - 1, x] > 0.0
            down_ok = y < height - 1 and z[y + 1, x] > 0.0
            ddx[y, x] = _one_sided(
                left_ok, right_ok,
                z[y, x] - z[y, x - 1] if left_ok else 0.0,
                z[y, x + 1] - z[y, x] if right_ok else 0.0, abs, 0.0,
            )
            ddy[y, x] = _one_sided(
                up_ok, down_ok,
                z[y, x] - z[y - 1, x] if up_ok else 0.0,
                z[y + 1, x] - z[y, x] if down_ok else 0.0, abs, 0.0,
            )
    return ddx, ddy, np.maximum(np.abs(ddx), np.abs(ddy))


def normal_gradient(unit_normal: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """``length(fwidth(n))`` with ``fwidth = |ddx n| + |ddy n|`` per component.

    The per-axis difference vectors follow the same one-sided rule as the depth (the one
    with the smaller length; the left/up one on a tie). Background gets 0.
    """
    n = np.asarray(unit_normal, dtype=F64)
    z = np.asarray(depth, dtype=F64)
    height, width = z.shape
    out = np.zeros_like(z)
    zero = np.zeros(3)
    for y in range(height):
        for x in range(width):
            if z[y, x] <= 0.0:
                continue
            left_ok = x > 0 and z[y, x - 1] > 0.0
            right_ok = x < width - 1 and z[y, x + 1] > 0.0
            up_ok = y > 0 and z[y - 1, x] > 0.0
            down_ok = y < height - 1 and z[y + 1, x] > 0.0
            along_x = _one_sided(
                left_ok, right_ok,
                n[:, y, x] - n[:, y, x - 1] if left_ok else zero,
                n[:, y, x + 1] - n[:, y, x] if right_ok else zero,
                lambda v: float(v @ v), zero,
            )
            along_y = _one_sided(
                up_ok, down_ok,
                n[:, y, x] - n[:, y - 1, x] if up_ok else zero,
                n[:, y + 1, x] - n[:, y, x] if down_ok else zero,
                lambda v: float(v @ v), zero,
            )
            out[y, x] = float(np.linalg.norm(np.abs(along_x) + np.abs(along_y)))
    return out


@dataclass
class Geometry:
    """Everything the stages need from one frame's G-buffer, in float64."""

    depth: np.ndarray
    unit_normal: np.ndarray
    ddx: np.ndarray
    ddy: np.ndarray
    depth_slope: np.ndarray
    normal_width: np.ndarray

    @property
    def surface(self) -> np.ndarray:
        return self.depth > 0.0


def geometry(depth: np.ndarray, normal: np.ndarray) -> Geometry:
    """Stage 0 as a whole (on the cleaned depth and normals)."""
    z = np.asarray(depth, dtype=F64)
    unit = unit_normals(normal, z)
    ddx, ddy, slope = depth_gradients(z)
    return Geometry(z, unit, ddx, ddy, slope, normal_gradient(unit, z))


# --------------------------------------------------------------------------- 1 demodulation
def effective_albedo(albedo: np.ndarray, black: float,
                     max_reflectance: float = MAX_REFLECTANCE,
                     relative_floor: float = RELATIVE_ALBEDO_FLOOR
                     ) -> tuple[np.ndarray, np.ndarray]:
    """The mode rule and the divisor ``a'`` of one (cleaned) demodulation colour.

    Returns ``(radiance_mode, a')``. A pixel is demodulated where the brightest channel
    ``max(a)`` lies in ``[black, max_reflectance]`` (a plausible reflectance), with the
    per-channel floor ``a'_c = max(a_c, black, relative_floor * max(a))``; elsewhere (black,
    or brighter than a reflectance) it is filtered as radiance: ``a' = 1``.
    """
    a = clean_albedo(albedo)
    brightest = a.max(axis=-3, keepdims=True)
    demodulated = (brightest >= black) & (brightest <= max_reflectance)
    floor = np.maximum(black, relative_floor * brightest)
    divisor = np.where(demodulated, np.maximum(a, floor), 1.0)
    return ~demodulated[..., 0, :, :], divisor


def large_image_pixels(lit: np.ndarray) -> np.ndarray:
    """(H, W) bool: within ``LARGE_IMAGE_REACH`` (a square) of a pixel whose
    ``LARGE_IMAGE_WINDOW`` square window, clipped by the image, holds ``LARGE_IMAGE_COUNT``
    or more ``lit`` pixels (``modulate.unmark_large_images``), pixel by pixel."""
    height, width = lit.shape
    r, reach = LARGE_IMAGE_WINDOW // 2, LARGE_IMAGE_REACH
    centre = np.zeros((height, width), dtype=bool)
    for y in range(height):
        for x in range(width):
            window = lit[max(y - r, 0):y + r + 1, max(x - r, 0):x + r + 1]
            centre[y, x] = int(window.sum()) >= LARGE_IMAGE_COUNT
    near = np.zeros((height, width), dtype=bool)
    for y in range(height):
        for x in range(width):
            near[y, x] = centre[max(y - reach, 0):y + reach + 1,
                                max(x - reach, 0):x + reach + 1].any()
    return near


def reflected_lights(guide: np.ndarray) -> np.ndarray:
    """(H, W) bool: the (cleaned) G-buffer albedo is above ``MAX_REFLECTANCE`` at the pixel
    and at ``MIN_LIT_NEIGHBOURS`` or more of its 8 neighbours, none of them near a light's
    large image (``modulate.emitter_colour``, ``modulate.unmark_large_images``)."""
    above = guide.max(axis=0) > MAX_REFLECTANCE
    lit = np.pad(above & ~large_image_pixels(above), 1)
    height, width = guide.shape[1:]
    neighbours = np.zeros((height, width), dtype=np.int64)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dy or dx:
                neighbours += lit[1 + dy:1 + dy + height, 1 + dx:1 + dx + width]
    return lit[1:-1, 1:-1] & (neighbours >= MIN_LIT_NEIGHBOURS)


def demodulation_floor(params: SVGFParams, clean: CleanFrame, index: int) -> float:
    """The ``black`` of :func:`effective_albedo` for signal ``index``: ``albedo_epsilon``,
    raised to ``guide_albedo_floor`` for a signal demodulated by the G-buffer albedo."""
    if clean.guide and clean.guide[index]:
        return max(params.albedo_epsilon, params.guide_albedo_floor)
    return params.albedo_epsilon


def demodulate(radiance: np.ndarray, albedo: np.ndarray,
               black: float) -> tuple[np.ndarray, np.ndarray, int]:
    """``illumination = clean(radiance) / a'`` clamped to +-1e15 (paper section 4; the value
    policy). Returns ``(illumination, radiance_mode, clamped values)``."""
    radiance_mode, divisor = effective_albedo(albedo, black)
    illumination = clean_value(radiance) / divisor
    clamped = int(np.sum(np.abs(illumination) > VALUE_LIMIT))
    return np.clip(illumination, -VALUE_LIMIT, VALUE_LIMIT), radiance_mode, clamped


def remodulate(illumination: np.ndarray, albedo: np.ndarray, black: float) -> np.ndarray:
    """Inverse of :func:`demodulate`: ``a' * illumination`` (the same ``a'``)."""
    return effective_albedo(albedo, black)[1] * np.asarray(illumination, dtype=F64)


def radiance_with_background(radiance: np.ndarray, original: np.ndarray,
                             depth: np.ndarray) -> np.ndarray:
    """Background pixels are not filtered: their (cleaned) input radiance goes to the
    output."""
    out = np.array(radiance, dtype=F64)
    background = np.asarray(depth) <= 0.0
    out[:, background] = clean_value(original)[:, background]
    return out


# --------------------------------------------------------------------------- clamps
def _neighbours(y: int, x: int, height: int, width: int,
                include_centre: bool) -> Iterator[tuple[int, int]]:
    for yy in range(y - 1, y + 2):
        for xx in range(x - 1, x + 2):
            if not (0 <= yy < height and 0 <= xx < width):
                continue
            if (yy, xx) == (y, x) and not include_centre:
                continue
            yield yy, xx


def _scale_to_neighbour_bound(
    illumination: np.ndarray, depth: np.ndarray, weights: Sequence[float],
    counts: Callable[[int, int, int, int, int], bool],
    bound: Callable[[list[float]], float | None],
) -> tuple[np.ndarray, list[int]]:
    """Per signal ``s`` and surface pixel ``p = (y, x)``: the luminances of its in-image
    surface neighbours ``q`` with ``counts(s, y, x, yy, xx)``; where there are some,
    ``bound(values)`` is not None and ``l(p)`` exceeds it, the rgb of ``p`` is scaled down
    to it (hue kept). Returns the result and the number of pixels changed per signal."""
    c = np.asarray(illumination, dtype=F64)
    z = np.asarray(depth, dtype=F64)
    out = c.copy()
    lum = luminance(c, weights)
    num_signals, _, height, width = c.shape
    changed = [0] * num_signals
    for s in range(num_signals):
        for y in range(height):
            for x in range(width):
                if z[y, x] <= 0.0:
                    continue
                values = [lum[s, yy, xx] for yy, xx in _neighbours(y, x, height, width, False)
                          if z[yy, xx] > 0.0 and counts(s, y, x, yy, xx)]
                limit = bound(values) if values else None
                if limit is not None and lum[s, y, x] > limit:
                    out[s, :, y, x] *= limit / lum[s, y, x]
                    changed[s] += 1
    return out, changed


def firefly_clamp(illumination: np.ndarray, depth: np.ndarray, k: float,
                  weights: Sequence[float] = REC709) -> np.ndarray:
    """Clamp each surface pixel's luminance to ``mean + k sigma`` (population sigma) of its
    in-image surface neighbours, the centre left out; the rgb is scaled (hue kept).

    A limit below 0 counts as 0; a pixel without such neighbours is left alone.
    """
    out, _ = _scale_to_neighbour_bound(
        illumination, depth, weights, lambda *_: True,
        lambda values: max(float(np.mean(values) + k * np.std(values)), 0.0))
    return out


def despike(illumination: np.ndarray, radiance_mode: np.ndarray, depth: np.ndarray,
            ratio: float, weights: Sequence[float] = REC709) -> tuple[np.ndarray, list[int]]:
    """Per signal, bring a surface pixel whose luminance exceeds ``ratio`` times the
    second-largest luminance among its in-image 8 neighbours that are surface pixels of the
    same mode (the only one's, where there is one) down to that bound (rgb scaled, hue
    kept). A pixel without such neighbours, or whose reference luminance is negative, is
    left alone. Returns the result and the number of pixels changed per signal."""

    def bound(values: list[float]) -> float | None:
        reference = sorted(values)[-2] if len(values) > 1 else values[0]
        return None if reference < 0.0 else ratio * reference

    return _scale_to_neighbour_bound(
        illumination, depth, weights,
        lambda s, y, x, yy, xx: bool(radiance_mode[s, yy, xx] == radiance_mode[s, y, x]),
        bound)


def despike_lone(output: np.ndarray, emission: np.ndarray | None, radiance_mode: np.ndarray,
                 depth: np.ndarray, ratio: float, weights: Sequence[float] = REC709
                 ) -> tuple[np.ndarray, int]:
    """On the composed output (3, H, W): a surface pixel whose mode in some signal differs
    from that of every in-image surface neighbour has its reflected luminance (its
    luminance less the emission's) brought down to ``ratio`` times the second-largest
    output luminance among those neighbours (the only one's, where there is one; left alone
    where it is negative or there is none), the reflected rgb scaled. Returns the result
    and the number of pixels changed."""
    out = np.array(output, dtype=F64)
    glow = np.zeros_like(out) if emission is None else np.asarray(emission, dtype=F64)
    z = np.asarray(depth, dtype=F64)
    w = np.asarray(weights, dtype=F64)
    lum = np.einsum("c,cyx->yx", w, out)
    glow_lum = np.einsum("c,cyx->yx", w, glow)
    modes = np.asarray(radiance_mode, dtype=bool)
    height, width = z.shape
    result = out.copy()
    changed = 0
    for y in range(height):
        for x in range(width):
            if z[y, x] <= 0.0:
                continue
            near = [(yy, xx) for yy, xx in _neighbours(y, x, height, width, False)
                    if z[yy, xx] > 0.0]
            lone = any(all(modes[s, yy, xx] != modes[s, y, x] for yy, xx in near)
                       for s in range(modes.shape[0]))
            values = sorted(lum[yy, xx] for yy, xx in near)
            if not lone or not values:
                continue
            reference = values[-2] if len(values) > 1 else values[0]
            reflected = lum[y, x] - glow_lum[y, x]
            if reference < 0.0 or reflected <= ratio * reference:
                continue
            scale = ratio * reference / reflected
            result[:, y, x] = glow[:, y, x] + (out[:, y, x] - glow[:, y, x]) * scale
            changed += 1
    return result, changed


def spread_fireflies(current: np.ndarray, radiance_mode: np.ndarray, moments: np.ndarray,
                     depth: np.ndarray, spread: Sequence[bool], k: float,
                     weights: Sequence[float] = REC709, ratio: float = 4.0, radius: int = 4,
                     depth_tolerance: float = 0.1, albedo: np.ndarray | None = None,
                     guide: Sequence[bool] = (), albedo_tolerance: float = 0.25,
                     cap: bool = False) -> tuple[np.ndarray, list[int]]:
    """Per signal ``s`` with ``spread[s]``: a demodulated surface sample whose luminance
    exceeds ``L = max(m1 + k sqrt(max(m2 - m1^2, 0)), ratio * max(M, 0))`` (``m1``, ``m2``
    the history's luminance moments; ``M`` the second-largest luminance among its in-image
    8 neighbours that are demodulated surface pixels, the only one's where there is one, 0
    where there is none) is a firefly. Every firefly's rgb is scaled to ``L``; then each
    one's removed rgb is added in equal shares to the demodulated surface pixels of the
    ``(2 radius + 1)^2`` window around it (itself included) whose depth is within
    ``depth_tolerance`` of its own, relatively; for a signal with ``guide[s]`` (demodulated
    by the G-buffer albedo) also whose colour ``albedo[s]`` has a luminance within
    ``albedo_tolerance`` of the firefly's, relatively. With ``cap`` no receiver gains more
    than the firefly's bounded luminance ``L``: the shares are scaled by
    ``min(1, n L / luminance(excess))`` for ``n`` receivers (the rest is dropped). Returns
    the result and the number of fireflies per signal."""
    c = np.array(current, dtype=F64)
    z = np.asarray(depth, dtype=F64)
    m = np.asarray(moments, dtype=F64)
    lum = luminance(c, weights)
    num_signals, _, height, width = c.shape
    counts = [0] * num_signals
    for s in range(num_signals):
        if not spread[s]:
            continue
        demodulated = (z > 0.0) & ~radiance_mode[s]
        guided = bool(guide) and guide[s]
        if guided:
            assert albedo is not None
            colour = luminance(np.asarray(albedo[s], dtype=F64), weights)
        found = []
        for y in range(height):
            for x in range(width):
                if not demodulated[y, x]:
                    continue
                m1, m2 = m[s, 0, y, x], m[s, 1, y, x]
                values = sorted(lum[s, yy, xx] for yy, xx in _neighbours(y, x, height, width,
                                                                          False)
                                if demodulated[yy, xx])
                reference = values[-2] if len(values) > 1 else (values[0] if values else 0.0)
                bound = max(m1 + k * math.sqrt(max(m2 - m1 * m1, 0.0)),
                            ratio * max(reference, 0.0))
                if lum[s, y, x] > bound:
                    found.append((y, x, c[s, :, y, x] * (1.0 - bound / lum[s, y, x]), bound))
        for y, x, excess, _ in found:
            c[s, :, y, x] -= excess
        for y, x, excess, bound in found:
            ys = slice(max(y - radius, 0), y + radius + 1)
            xs = slice(max(x - radius, 0), x + radius + 1)
            receives = demodulated[ys, xs] & (np.abs(z[ys, xs] - z[y, x])
                                              <= depth_tolerance * z[y, x])
            if guided:
                receives &= np.abs(colour[ys, xs] - colour[y, x]) <= (
                    albedo_tolerance * colour[y, x])
            share = 1.0 / receives.sum()
            lost = float(np.dot(np.asarray(weights, dtype=F64), excess))
            if cap and lost > bound * receives.sum():
                share *= bound * receives.sum() / lost
            c[s][:, ys, xs] += np.where(receives, 1.0, 0.0) * (excess * share)[:, None, None]
        counts[s] = len(found)
    return c, counts


def history_clamp(history: np.ndarray, moments: np.ndarray, history_length: np.ndarray,
                  current: np.ndarray, depth: np.ndarray, k: float,
                  weights: tuple[float, float, float],
                  radius: int | list = 1) -> tuple[np.ndarray, np.ndarray]:
    """Clamp each history channel to the current 3x3 (the ``(2 radius + 1)^2`` window, one
    radius per signal or one for all, a signal's radius an int or an (H, W) array of them:
    one per pixel; in-image surface pixels, centre included)
    ``mean +- k sigma``; where anything changed, scale the moments with the
    history luminance ``l -> l'``: ``m1 l'/l``, ``min(m2 (l'/l)^2, 1e36)`` (``l'``,
    ``l'^2`` where ``l <= 0`` or ``l' > 1e6 l``). A signal's pixels without history (its
    ``h <= 0``) and background are left alone. Returns the clamped history and moments."""
    hist = np.array(history, dtype=F64)
    mom = np.array(moments, dtype=F64)
    cur = np.asarray(current, dtype=F64)
    z = np.asarray(depth, dtype=F64)
    h = np.asarray(history_length, dtype=F64)
    w = np.asarray(weights, dtype=F64)
    num_signals, _, height, width = hist.shape
    radii = [radius] * num_signals if isinstance(radius, int) else list(radius)
    for y in range(height):
        for x in range(width):
            if z[y, x] <= 0.0:
                continue
            for s in range(num_signals):
                if h[s, y, x] <= 0.0:
                    continue
                r = radii[s] if isinstance(radii[s], int) else int(radii[s][y, x])
                window = [(yy, xx) for yy in range(max(y - r, 0), min(y + r + 1, height))
                          for xx in range(max(x - r, 0), min(x + r + 1, width))
                          if z[yy, xx] > 0.0]
                before = float(w @ hist[s, :, y, x])
                for c in range(3):
                    values = np.array([cur[s, c, yy, xx] for yy, xx in window])
                    mean, sigma = values.mean(), values.std()
                    hist[s, c, y, x] = min(max(hist[s, c, y, x], mean - k * sigma),
                                           mean + k * sigma)
                after = float(w @ hist[s, :, y, x])
                if np.array_equal(hist[s, :, y, x], np.asarray(history, dtype=F64)[s, :, y, x]):
                    continue
                if before > 0.0 and after <= 1e6 * before:
                    mom[s, 0, y, x] *= after / before
                    mom[s, 1, y, x] = min(mom[s, 1, y, x] * (after / before) ** 2, 1e36)
                else:  # from black, or raised more than a millionfold
                    mom[s, :, y, x] = after, after * after
    return hist, mom


def heavy_tailed(moments: np.ndarray, length: np.ndarray, depth: np.ndarray,
                 mesh_id: np.ndarray, rough_ids: set[int], threshold: float,
                 min_history: float = 1.0) -> np.ndarray:
    """(H, W) bool: surface pixels with at least ``min_history`` frames of history whose
    luminance moments (2, H, W) have ``(m2 - m1^2) / m1^2 > threshold`` (``m1 > 0``), not
    on an object in ``rough_ids``."""
    m1 = np.asarray(moments[0], dtype=F64)
    m2 = np.asarray(moments[1], dtype=F64)
    with np.errstate(divide="ignore", invalid="ignore"):
        relative = np.where(m1 > 0.0, (m2 - m1 * m1) / (m1 * m1), 0.0)
    rough = np.isin(mesh_id, sorted(rough_ids))
    return (np.asarray(depth) > 0) & (np.asarray(length) >= min_history) & (m1 > 0.0) \
        & (relative > threshold) & ~rough


# --------------------------------------------------------------------------- 2 reprojection
@dataclass
class History:
    """One frame's persistent state, as the next frame reads it."""

    illumination: np.ndarray  # (S, 3, H, W) colour history (the feedback iteration's output)
    moments: np.ndarray  # (S, 2, H, W) integrated luminance moments (l, l^2)
    history_length: np.ndarray  # (S, H, W)
    radiance_mode: np.ndarray  # (S, H, W) the mode each signal's history was filtered in
    has_history: np.ndarray  # (H, W) False where the history guard reset the pixel
    depth: np.ndarray
    unit_normal: np.ndarray
    mesh_id: np.ndarray


def tap_consistent(tx: int, ty: int, z: float, n: np.ndarray, mesh: int,
                   depth_slope: float, normal_width: float, prev: History,
                   depth_tolerance: float, depth_slack: float, normal_tolerance: float) -> bool:
    """The paper's consistency tests for one previous-frame pixel ``(tx, ty)``.

    Inside the image; not background; the same mesh id; depth
    ``|z_prev - z| <= depth_tolerance * (slope + depth_slack * z)``; normal
    ``||n - n_prev|| <= normal_tolerance * (fwidth_n + 0.01)``.
    """
    height, width = prev.depth.shape
    if not (0 <= tx < width and 0 <= ty < height):
        return False
    z_prev = prev.depth[ty, tx]
    if z_prev <= 0.0:
        return False
    if int(prev.mesh_id[ty, tx]) != int(mesh):
        return False
    if abs(z_prev - z) > depth_tolerance * (depth_slope + depth_slack * z):
        return False
    distance = float(np.linalg.norm(n - prev.unit_normal[:, ty, tx]))
    return distance <= normal_tolerance * (normal_width + NORMAL_SLACK)


@dataclass
class Reprojected:
    """Last frame's history resampled at this frame's pixels, per signal; a signal's
    ``history_length`` 0 means rejected (disocclusion, or no tap of its current mode).
    ``path`` (S, H, W) says which branch each signal took at each pixel: 0 rejected,
    1 bilinear, 2 the 3x3 fallback, 3 Catmull-Rom (for tests that must exercise every
    branch)."""

    illumination: np.ndarray
    moments: np.ndarray
    history_length: np.ndarray
    path: np.ndarray


REJECTED, BILINEAR, FALLBACK, CATMULL_ROM = 0, 1, 2, 3


def catmull_rom_weights(t: float) -> tuple[float, float, float, float]:
    """Catmull-Rom (Keys' cubic, a = -1/2) weights of the taps at offsets -1, 0, 1, 2 from
    ``floor(p)`` for the fraction ``t``: ``k(1 + t), k(t), k(1 - t), k(2 - t)`` with
    ``k(d) = 1.5 d^3 - 2.5 d^2 + 1`` for ``d <= 1`` and ``-0.5 d^3 + 2.5 d^2 - 4 d + 2``
    for ``1 < d < 2``."""

    def k(d: float) -> float:
        if d <= 1.0:
            return 1.5 * d**3 - 2.5 * d**2 + 1.0
        return -0.5 * d**3 + 2.5 * d**2 - 4.0 * d + 2.0 if d < 2.0 else 0.0

    return k(1.0 + t), k(t), k(1.0 - t), k(2.0 - t)


def catmull_rom_fetch(plane: np.ndarray, px: float, py: float) -> float:
    """The clamped Catmull-Rom value of ``plane`` (H, W) at ``(px, py)``: the 4x4 weighted
    sum, clamped to the range of the bilinear taps that carry weight (one column where
    ``px`` is whole, one row where ``py`` is). The caller checked the taps are inside."""
    x0, y0 = math.floor(px), math.floor(py)
    wx, wy = catmull_rom_weights(px - x0), catmull_rom_weights(py - y0)
    total = sum(wy[j] * wx[i] * plane[y0 - 1 + j, x0 - 1 + i]
                for j in range(4) for i in range(4) if wx[i] != 0.0 and wy[j] != 0.0)
    inner = [plane[ty, tx] for ty in {y0, y0 + (py > y0)} for tx in {x0, x0 + (px > x0)}]
    return float(np.clip(total, min(inner), max(inner)))


def reproject(motion: np.ndarray, geom: Geometry, mesh_id: np.ndarray,
              radiance_mode: np.ndarray, prev: History, depth_tolerance: float,
              depth_slack: float, normal_tolerance: float,
              catmull_rom: bool = False) -> Reprojected:
    """Resample ``prev`` at the backprojected positions, per signal (paper 4.1).

    Per surface pixel: ``P = (x + motion.x, y + motion.y)``. A previous pixel is a usable
    tap for signal ``s`` when it passes :func:`tap_consistent`, was not reset by the history
    guard, and its history of ``s`` was filtered in the mode ``s`` has at the pixel now
    (radiance and illumination history never mix). The bilinear weights of the usable 2x2
    taps are renormalised to sum to 1, unless their sum is below 0.01, which rejects them.
    Then: the plain average of the usable taps in the 3x3 around the rounded position
    ``floor(P + 0.5)``; with none, a disocclusion of that signal. Colour, moments and
    history length are resampled with the same weights; a history length within 1e-3 of a
    whole number of frames is that number. Non-finite motion is a disocclusion.

    ``catmull_rom``: where ``P`` is not a whole pixel and every tap with a Catmull-Rom weight
    (the 4x4 around ``floor(P)``; one column where ``P.x`` is whole, one row where ``P.y``
    is) passes :func:`tap_consistent`, was not reset, and has every signal's current mode,
    each signal's colour and moments are :func:`catmull_rom_fetch` and the second moment at
    least the first squared; the history length stays bilinear.
    """
    z = geom.depth
    height, width = z.shape
    num_signals = prev.illumination.shape[0]
    mv = np.asarray(motion, dtype=F64)
    mode_now = np.asarray(radiance_mode, dtype=bool)
    illumination = np.zeros((num_signals, 3, height, width))
    moments = np.zeros((num_signals, 2, height, width))
    history_length = np.zeros((num_signals, height, width))
    path = np.full((num_signals, height, width), REJECTED, dtype=np.int8)
    for y in range(height):
        for x in range(width):
            px, py = x + mv[0, y, x], y + mv[1, y, x]
            if z[y, x] <= 0.0 or not (math.isfinite(px) and math.isfinite(py)):
                continue

            def consistent(tx: int, ty: int, x: int = x, y: int = y) -> bool:
                return tap_consistent(
                    tx, ty, z[y, x], geom.unit_normal[:, y, x], mesh_id[y, x],
                    geom.depth_slope[y, x], geom.normal_width[y, x], prev, depth_tolerance,
                    depth_slack, normal_tolerance,
                )

            x0, y0 = math.floor(px), math.floor(py)
            fx, fy = px - x0, py - y0
            taps = [(x0, y0, (1 - fx) * (1 - fy)), (x0 + 1, y0, fx * (1 - fy)),
                    (x0, y0 + 1, (1 - fx) * fy), (x0 + 1, y0 + 1, fx * fy)]
            cx, cy = math.floor(px + 0.5), math.floor(py + 0.5)
            box = [(tx, ty) for ty in range(cy - 1, cy + 2) for tx in range(cx - 1, cx + 2)]
            support = [(x0 - 1 + i, y0 - 1 + j) for j in range(4) for i in range(4)
                       if (fx > 0 or i == 1) and (fy > 0 or j == 1)]
            sharp = catmull_rom and (fx > 0 or fy > 0) and all(
                consistent(tx, ty) and bool(prev.has_history[ty, tx])
                and np.array_equal(prev.radiance_mode[:, ty, tx], mode_now[:, y, x])
                for tx, ty in support)
            for s in range(num_signals):

                def usable_tap(tx: int, ty: int, s: int = s, x: int = x, y: int = y) -> bool:
                    return (consistent(tx, ty) and bool(prev.has_history[ty, tx])
                            and bool(prev.radiance_mode[s, ty, tx]) == bool(mode_now[s, y, x]))

                passing = [(tx, ty, w) for tx, ty, w in taps if usable_tap(tx, ty)]
                total = sum(w for _, _, w in passing)
                if total >= MIN_BILINEAR_WEIGHT:
                    chosen = [(tx, ty, w / total) for tx, ty, w in passing]
                    path[s, y, x] = BILINEAR
                else:
                    found = [(tx, ty) for tx, ty in box if usable_tap(tx, ty)]
                    if not found:
                        continue
                    chosen = [(tx, ty, 1.0 / len(found)) for tx, ty in found]
                    path[s, y, x] = FALLBACK
                for tx, ty, w in chosen:
                    illumination[s, :, y, x] += w * prev.illumination[s, :, ty, tx]
                    moments[s, :, y, x] += w * prev.moments[s, :, ty, tx]
                    history_length[s, y, x] += w * prev.history_length[s, ty, tx]
                if sharp:
                    path[s, y, x] = CATMULL_ROM
                    for c in range(3):
                        illumination[s, c, y, x] = catmull_rom_fetch(
                            prev.illumination[s, c], px, py)
                    m1 = catmull_rom_fetch(prev.moments[s, 0], px, py)
                    m2 = catmull_rom_fetch(prev.moments[s, 1], px, py)
                    moments[s, :, y, x] = m1, max(m2, m1 * m1)
    whole = np.floor(history_length + 0.5)
    history_length = np.where(np.abs(history_length - whole) < WHOLE_SNAP, whole,
                              history_length)
    return Reprojected(illumination, moments, history_length, path)


# --------------------------------------------------------------------------- 2 accumulation
def accumulate(illumination: np.ndarray, reprojected_illumination: np.ndarray,
               reprojected_moments: np.ndarray, reprojected_length: np.ndarray,
               depth: np.ndarray, alpha: float, moments_alpha: float, history_cap: float,
               weights: Sequence[float] = REC709
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Paper eq. 6 with the 1/h ramp, each signal with its own history length: returns
    (illumination, moments, history length).

    Where signal ``s``'s history was reused (surface, resampled ``h_prev[s] > 0``):
    ``h = min(cap, h_prev + 1)``, ``c = lerp(c_hist, c, max(alpha, 1/h))`` and the moments
    ``(l, l^2)`` (luminance with the frame's weights) likewise with
    ``max(moments_alpha, 1/h)``. Elsewhere the current values (``h = 1``; background 0).
    """
    c = np.asarray(illumination, dtype=F64)
    c_hist = np.asarray(reprojected_illumination, dtype=F64)
    m_hist = np.asarray(reprojected_moments, dtype=F64)
    h_prev = np.asarray(reprojected_length, dtype=F64)
    surface = (np.asarray(depth) > 0.0)[None]
    reused = surface & (h_prev > 0.0)
    h = np.where(reused, np.minimum(history_cap, h_prev + 1.0), 1.0)
    a = np.where(reused, np.maximum(alpha, 1.0 / h), 1.0)[:, None]
    a_m = np.where(reused, np.maximum(moments_alpha, 1.0 / h), 1.0)[:, None]
    lum = luminance(c, weights)
    current_moments = np.stack([lum, lum * lum], axis=1)
    blend = reused[:, None]
    out_c = np.where(blend, (1.0 - a) * c_hist + a * c, c)
    out_m = np.where(blend, (1.0 - a_m) * m_hist + a_m * current_moments, current_moments)
    return out_c, out_m, np.where(surface, h, 0.0)


# --------------------------------------------------------------------------- 3 variance
def temporal_variance(moments: np.ndarray) -> np.ndarray:
    """``Var = max(0, m2 - m1^2)`` from the integrated moments."""
    m = np.asarray(moments, dtype=F64)
    return np.maximum(m[:, 1] - m[:, 0] ** 2, 0.0)


def depth_exponent(z_p: float, z_q: float, ddx_p: float, ddy_p: float, ox: float, oy: float,
                   sigma_depth: float) -> float:
    """Paper eq. 3's exponent with the projected gradient and a depth-relative epsilon:
    ``|z(p) - z(q)| / (sigma_z |grad z(p) . (q - p)| + 1e-3 z(p))``."""
    return abs(z_p - z_q) / (sigma_depth * abs(ddx_p * ox + ddy_p * oy) + DEPTH_EPSILON * z_p)


def normal_weight(n_p: np.ndarray, n_q: np.ndarray, sigma_normal: float) -> float:
    """Paper eq. 4: ``max(0, n(p).n(q)) ** sigma_n``."""
    return max(0.0, float(n_p @ n_q)) ** sigma_normal


def spatial_variance(illumination: np.ndarray, moments: np.ndarray, history_length: np.ndarray,
                     radiance_mode: np.ndarray, geom: Geometry, history_threshold: float,
                     radius: int, sigma_depth: float, sigma_luminance: float,
                     sigma_normal: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unboosted edge-aware spatial variance where a signal's ``0 < h < threshold`` (4.2).

    Returns (variance, colour, mask), each per signal. Over the in-image ``(2r+1)^2`` box
    around ``p``: ``w = w_n exp(-depth exponent - |m1(p) - m1(q)| / (sigma (|m1(p)| +
    |m1(q)|) / 2 + 1e-30))`` (a luminance stop relative to the pair's mean luminance; the
    centre has weight 1), and ``w = 0`` where ``q``'s mode for the signal differs from
    ``p``'s; weighted means of ``m1``, ``m2`` and the colour; the population variance
    ``max(0, E_w[m2] - E_w[m1]^2)`` is divided by ``1 - sum(w^2) / (h (sum w)^2)``, the
    reliability-weights (Bessel) correction for a weighted sample of h-frame averages (a
    lone sample, where that factor is 0, has no spread and stays 0). Pixels outside the mask
    keep the temporal variance and their own colour. ``h >= 1`` wherever the mask is set
    (the accumulation guarantees it).
    """
    c = np.asarray(illumination, dtype=F64)
    m = np.asarray(moments, dtype=F64)
    h = np.asarray(history_length, dtype=F64)
    mode = np.asarray(radiance_mode, dtype=bool)
    z, n = geom.depth, geom.unit_normal
    num_signals, _, height, width = c.shape
    variance = temporal_variance(m)
    colour = c.copy()
    mask = (h > 0.0) & (h < history_threshold)
    for s, y, x in zip(*np.nonzero(mask), strict=True):
        # The in-image window around p, as (taps,) arrays of q's coordinates.
        qy, qx = np.mgrid[max(0, y - radius):min(height, y + radius + 1),
                          max(0, x - radius):min(width, x + radius + 1)]
        qy, qx = qy.ravel(), qx.ravel()
        centre = (qy == y) & (qx == x)
        w_n = np.maximum(n[:, y, x] @ n[:, qy, qx], 0.0) ** sigma_normal
        depth_term = np.abs(z[y, x] - z[qy, qx]) / (
            sigma_depth * np.abs(geom.ddx[y, x] * (qx - x) + geom.ddy[y, x] * (qy - y))
            + DEPTH_EPSILON * z[y, x]
        )
        m1_p, m1_q, m2_q = m[s, 0, y, x], m[s, 0, qy, qx], m[s, 1, qy, qx]
        scale = sigma_luminance * (abs(m1_p) + np.abs(m1_q)) / 2.0 + SPATIAL_TINY
        luminance_term = np.abs(m1_p - m1_q) / scale
        w = np.where(centre, 1.0, w_n * np.exp(-(depth_term + luminance_term)))
        w = np.where(mode[s, qy, qx] == mode[s, y, x], w, 0.0)
        total = w.sum()
        mean1, mean2 = (w @ m1_q) / total, (w @ m2_q) / total
        population = max(mean2 - mean1 * mean1, 0.0)
        shrink = (w @ w) / total**2 / h[s, y, x]
        if shrink < 1.0:
            population /= 1.0 - shrink
        variance[s, y, x] = population
        colour[s, :, y, x] = c[s][:, qy, qx] @ w / total
    return variance, colour, mask


def boost_short_history(variance: np.ndarray, history_length: np.ndarray,
                        history_threshold: float) -> np.ndarray:
    """``Var *= threshold / h`` where ``0 < h < threshold`` (Falcor's 4/h), per signal."""
    h = np.asarray(history_length, dtype=F64)
    short = (h > 0.0) & (h < history_threshold)
    boost = np.where(short, history_threshold / np.where(short, h, 1.0), 1.0)
    return np.asarray(variance, dtype=F64) * boost


def estimate_variance(illumination: np.ndarray, moments: np.ndarray,
                      history_length: np.ndarray, radiance_mode: np.ndarray, geom: Geometry,
                      params: SVGFParams) -> tuple[np.ndarray, np.ndarray]:
    """Paper 4.2 as a whole: (variance, colour). The temporal variance, replaced where a
    signal's history is short by the spatial estimate times ``threshold / h``; the colour is
    the input, or with ``spatial_variance_blur_color`` the spatially filtered colour on
    those pixels. A threshold <= 1 never selects the spatial estimate."""
    threshold = float(params.variance_history_threshold)
    if threshold <= 1.0:
        return temporal_variance(moments), np.array(illumination, dtype=F64)
    variance, colour, _ = spatial_variance(
        illumination, moments, history_length, radiance_mode, geom, threshold,
        params.spatial_variance_radius, params.sigma_depth,
        params.spatial_variance_sigma_luminance, params.sigma_normal,
    )
    variance = boost_short_history(variance, history_length, threshold)
    if not params.spatial_variance_blur_color:
        colour = np.array(illumination, dtype=F64)
    return variance, colour


# --------------------------------------------------------------------------- 4 a-trous
def iteration_count(requested: int, height: int, width: int) -> int:
    """The a-trous iteration count: ``requested``, or for -1 (auto) one more per doubling of
    the shorter image side from 3 below 160 pixels up to 5 at 320 and beyond."""
    if requested != -1:
        return requested
    side = min(height, width)
    return 3 if side < 160 else 4 if side < 320 else 5


def atrous_steps(iterations: int) -> list[int]:
    """The a-trous step schedule: iteration i filters at step 2^i (1, 2, 4, 8, 16, ...)."""
    return [2**i for i in range(iterations)]


def _gaussian_3x3(values: np.ndarray,
                  usable: Callable[[tuple[slice, ...], tuple[slice, ...]], np.ndarray]
                  ) -> np.ndarray:
    """Per signal of (S, H, W) ``values``: the 3x3 Gaussian (1/4 centre, 1/8 edge, 1/16
    corner) over the taps where ``usable(source, target)`` holds (booleans for the taps q
    at ``source`` of the pixels p at ``target``), renormalised; a pixel with no such tap
    keeps its own value."""
    num_signals, height, width = values.shape
    total = np.zeros_like(values)
    weight = np.zeros_like(values)
    for oy in (-1, 0, 1):
        for ox in (-1, 0, 1):
            # q = p + (ox, oy) where that is inside the image
            target = (slice(None), slice(max(0, -oy), height - max(0, oy)),
                      slice(max(0, -ox), width - max(0, ox)))
            source = (slice(None), slice(max(0, oy), height + min(0, oy)),
                      slice(max(0, ox), width + min(0, ox)))
            g = G3[ox + 1] * G3[oy + 1] * usable(source, target)
            weight[target] += g
            total[target] += g * values[source]
    return np.where(weight > 0.0, total / np.where(weight > 0.0, weight, 1.0), values)


def luminance_stop_guides(illumination: np.ndarray, variance: np.ndarray,
                          depth: np.ndarray, sigma_luminance: float | Sequence[float],
                          weights: Sequence[float] = REC709,
                          blur_modes: np.ndarray | None = None,
                          ) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel and signal: ``l(p) = max(0, luminance)`` (the frame's weights) and
    ``1 / max(sigma_l sqrt(g3x3(Var(p)) + (1e-5 l(p))^2), 1e-20)``; ``sigma_l`` is one
    number or one per signal (glossy signals have their own).

    ``g3x3`` is the 3x3 Gaussian (1/4 centre, 1/8 edge, 1/16 corner) renormalised over the
    in-image surface pixels; a pixel with none of those keeps its own variance. The floor on
    the deviation is relative to ``l``, so scaling the input scales the output.
    ``blur_modes`` (the (S, H, W) radiance-mode booleans) given: ``l`` is ``g3x3(l)`` over
    the in-image surface pixels of the pixel's own mode (``luminance_guide_blur``).
    """
    c = np.asarray(illumination, dtype=F64)
    v = np.asarray(variance, dtype=F64)
    surface = np.broadcast_to(np.asarray(depth) > 0.0, v.shape)
    filtered = _gaussian_3x3(v, lambda source, target: surface[source])
    lum = np.maximum(luminance(c, weights), 0.0)
    if blur_modes is not None:
        modes = np.asarray(blur_modes, dtype=bool)
        lum = _gaussian_3x3(lum, lambda source, target: surface[source]
                            & (modes[source] == modes[target]))
    deviation = np.sqrt(np.maximum(filtered, 0.0) + (RELATIVE_DEVIATION_FLOOR * lum) ** 2)
    sigma = np.asarray(sigma_luminance, dtype=F64)
    if sigma.ndim == 1:
        sigma = sigma[:, None, None]
    return lum, 1.0 / np.maximum(sigma * deviation, MIN_SCALE)


def atrous_sigmas(p: SVGFParams, clean: CleanFrame, geom: Geometry) -> list[float]:
    """Each signal's sigma_l: glossy signals' own, then those mixing direct and indirect
    light, else ``sigma_luminance``; times ``luminance_stop_scale`` (auto: by image size)."""
    scale = luminance_stop_scale_for(p, *geom.depth.shape)
    return [scale * ((p.glossy_sigma_luminance or p.sigma_luminance) if glossy
                     else (p.mixed_sigma_luminance or p.sigma_luminance) if mixed
                     else p.sigma_luminance)
            for glossy, mixed in zip(clean.glossy, clean.mixed, strict=True)]


def guide_blur_modes(p: SVGFParams, radiance_mode: np.ndarray) -> np.ndarray | None:
    """The radiance modes the luminance guide is blurred within (``luminance_guide_blur``),
    or None: the guide is each pixel's own luminance."""
    return radiance_mode if p.luminance_guide_blur else None


def symmetric_stops(p: SVGFParams, clean: CleanFrame) -> list[bool]:
    """Per signal: whether its luminance stop is symmetric (``mixed_symmetric_stop``: the
    signals mixing direct and indirect light, not glossy)."""
    return [p.mixed_symmetric_stop and mixed and not glossy
            for glossy, mixed in zip(clean.glossy, clean.mixed, strict=True)]


def atrous_iteration(illumination: np.ndarray, variance: np.ndarray,
                     guide_luminance: np.ndarray, radiance_mode: np.ndarray,
                     guide_inverse_scale: np.ndarray, depth: np.ndarray, ddx: np.ndarray,
                     ddy: np.ndarray, normal: np.ndarray, step: int, sigma_depth: float,
                     sigma_normal: float, symmetric: Sequence[bool] | None = None,
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Paper eqs. 1-5 for every pixel and signal, one tap offset at a time.

    Over the in-image taps ``q = p + step (i - 2, j - 2)`` of the 5x5 B3 kernel:
    ``w = h(q) w_z w_n w_l`` with ``w_z = exp(-depth exponent)`` (eq. 3, see
    :func:`depth_exponent`), ``w_n`` (eq. 4) and
    ``w_l = exp(-|l(p) - l(q)| * guide_inverse_scale(p))`` (eq. 5; for a ``symmetric``
    signal ``* sqrt(guide_inverse_scale(p) guide_inverse_scale(q))``), and ``w = 0`` where
    the signal's mode at ``q`` differs from ``p``'s; the centre has weight ``h``.
    ``c' = sum(w c) / sum(w)`` (eq. 1), ``Var' = sum(w^2 Var) / (sum w)^2`` (eq. 2).
    Background centres (zero normal) receive weight only from themselves.
    (Vectorised over pixels, taps in an outer loop: the per-pixel form of the same sums
    took seconds per frame.)
    """
    c_in = np.asarray(illumination, dtype=F64)
    v_in = np.asarray(variance, dtype=F64)
    lum = np.asarray(guide_luminance, dtype=F64)
    mode = np.asarray(radiance_mode, dtype=bool)
    inv = np.asarray(guide_inverse_scale, dtype=F64)
    z, gx, gy = (np.asarray(a, dtype=F64) for a in (depth, ddx, ddy))
    n = np.asarray(normal, dtype=F64)
    height, width = z.shape
    py, px = np.mgrid[0:height, 0:width]
    both = np.zeros((len(v_in), 1, 1), dtype=bool)
    if symmetric is not None:
        both[:, 0, 0] = np.asarray(symmetric, dtype=bool)
    sum_w = np.zeros_like(v_in)
    sum_c = np.zeros_like(c_in)
    sum_w2v = np.zeros_like(v_in)
    for j in range(5):
        for i in range(5):
            oy, ox = (j - 2) * step, (i - 2) * step
            qy, qx = py + oy, px + ox
            inside = (qy >= 0) & (qy < height) & (qx >= 0) & (qx < width)
            qy, qx = np.clip(qy, 0, height - 1), np.clip(qx, 0, width - 1)
            h = B3[i] * B3[j]
            if (oy, ox) == (0, 0):
                w = np.full_like(v_in, h)
            else:
                cosine = np.sum(n * n[:, qy, qx], axis=0)
                w_n = np.maximum(cosine, 0.0) ** sigma_normal
                facing = inside & (w_n > 0.0)  # also keeps 0/0 away on background centres
                z_p = np.where(facing, z, 1.0)
                w_z = np.abs(z_p - z[qy, qx]) / (
                    sigma_depth * np.abs(gx * ox + gy * oy) + DEPTH_EPSILON * z_p
                )
                w_l = np.abs(lum - lum[:, qy, qx]) * np.where(
                    both, np.sqrt(inv * inv[:, qy, qx]), inv)
                same_mode = mode == mode[:, qy, qx]
                w = np.where(facing & same_mode, h * w_n * np.exp(-(w_z + w_l)), 0.0)
            sum_w += w
            sum_c += w[:, None] * c_in[:, :, qy, qx]
            sum_w2v += w * w * v_in[:, qy, qx]
    return sum_c / sum_w[:, None], sum_w2v / sum_w**2


# --------------------------------------------------------------------------- TAA
TAA_DEPTH_JUMP = 1.05
TAA_CLIP_SIGMA = 0.5


def taa_outline(depth: np.ndarray) -> np.ndarray:
    """(H, W) bool: surface pixels whose 3x3 holds a surface pixel with a background
    neighbour or a neighbour more than 5 % nearer or farther (8 neighbours, in the image)."""
    z = np.asarray(depth, dtype=F64)
    height, width = z.shape
    jump = np.zeros((height, width), dtype=bool)
    for y in range(height):
        for x in range(width):
            if z[y, x] <= 0:
                continue
            window = z[max(y - 1, 0):y + 2, max(x - 1, 0):x + 2]
            jump[y, x] = bool(np.any((window <= 0) | (window > TAA_DEPTH_JUMP * z[y, x])
                                     | (z[y, x] > TAA_DEPTH_JUMP * window)))
    outline = np.zeros_like(jump)
    for y in range(height):
        for x in range(width):
            outline[y, x] = z[y, x] > 0 and bool(jump[max(y - 1, 0):y + 2,
                                                      max(x - 1, 0):x + 2].any())
    return outline


JITTER_RATIO = 0.1
JITTER_MIN_SLOPE = 1e-4
JITTER_PLANE_NORMAL = 1e-3


def plane_triples(depth: np.ndarray, normal: np.ndarray,
                  mesh_id: np.ndarray) -> tuple[int, int]:
    """(tested, jittered) (``svgf_cli.filters.jitter``): over the row and column triples
    centred on every 4th row from row 1, of surface pixels of one mesh id whose normals
    agree within 1e-3 per component, with ``u = 1 / depth`` and slope ``g = |u[+1] -
    u[-1]| / 2`` above ``1e-4 u[0]``: the count, and how many have ``|u[-1] - 2 u[0] +
    u[+1]| > 0.1 g``."""
    z = np.asarray(depth, dtype=F64)
    n = np.asarray(normal, dtype=F64)
    height, width = z.shape
    tested = jittered = 0
    centres = range(1, height - 1, 4)  # every 4th row from row 1
    triples = [((y, x - 1), (y, x), (y, x + 1)) for y in centres for x in range(1, width - 1)]
    triples += [((y - 1, x), (y, x), (y + 1, x)) for y in centres for x in range(width)]
    for a, b, c in triples:
        if min(z[a], z[b], z[c]) <= 0 or not mesh_id[a] == mesh_id[b] == mesh_id[c]:
            continue
        if (np.abs(n[:, a[0], a[1]] - n[:, b[0], b[1]]).max() > JITTER_PLANE_NORMAL
                or np.abs(n[:, c[0], c[1]] - n[:, b[0], b[1]]).max() > JITTER_PLANE_NORMAL):
            continue
        u0, u1, u2 = 1.0 / z[a], 1.0 / z[b], 1.0 / z[c]
        slope = abs(u2 - u0) / 2.0
        if not slope > JITTER_MIN_SLOPE * u1:
            continue
        tested += 1
        jittered += int(abs(u0 - 2.0 * u1 + u2) > JITTER_RATIO * slope)
    return tested, jittered


def jittered_samples(depth: np.ndarray, normal: np.ndarray, mesh_id: np.ndarray) -> bool:
    """At least 64 plane triples, half of them off their line (:func:`plane_triples`)."""
    tested, jittered = plane_triples(depth, normal, mesh_id)
    return tested >= 64 and jittered >= 0.5 * tested


def _catmull_rom(t: float) -> np.ndarray:
    return np.array([t * (-0.5 + t * (1 - t / 2)), 1 + t * t * (-2.5 + 1.5 * t),
                     t * (0.5 + t * (2 - 1.5 * t)), t * t * (-0.5 + t / 2)])


def emission_mean(emission: np.ndarray, motion: np.ndarray, state: dict | None,
                  alpha: float, cap: float, still_motion: float = 0.01,
                  level_change: float = 0.01) -> tuple[np.ndarray, dict]:
    """filters.emission_mean in float64 numpy, functional: (this frame's emitted mean,
    the state to pass on); ``state`` None is the first frame."""
    e = emission.astype(np.float64)
    speed = np.hypot(motion[0].astype(np.float64), motion[1].astype(np.float64))
    pad = ((1, 1), (1, 1))

    def around(plane: np.ndarray, how: str) -> np.ndarray:
        fill = -np.inf if how == "max" else np.inf
        padded = np.pad(plane, pad, constant_values=fill)
        h, w = plane.shape
        windows = [padded[dy:dy + h, dx:dx + w] for dy in range(3) for dx in range(3)]
        return np.max(windows, axis=0) if how == "max" else np.min(windows, axis=0)

    still_now = around(speed, "max") <= still_motion
    level_now = around(e.max(axis=0), "max")
    if state is None:
        mean, length = e.copy(), np.ones(speed.shape)
    else:
        steady = np.abs(level_now - state["level"]) <= level_change * np.maximum(
            level_now, state["level"])
        keep = still_now & state["still"] & steady
        low = np.stack([around(c, "min") for c in e])
        high = np.stack([around(c, "max") for c in e])
        h = np.clip(state["mean"], low, high)
        length = np.where(keep, np.minimum(state["length"] + 1, cap), 1.0)
        weight = np.maximum(1.0 / length, alpha)
        mean = np.where(keep[None], h + weight[None] * (e - h), e)
    return mean, {"mean": mean, "length": length, "still": still_now, "level": level_now}


def taa_resolve(current: np.ndarray, previous: np.ndarray, motion: np.ndarray,
                depth: np.ndarray, weights: tuple[float, float, float],
                alpha: float) -> np.ndarray:
    """Temporal anti-aliasing at outlines (``svgf_cli.filters.taa``).

    On :func:`taa_outline` pixels whose backprojected position ``P = (x + motion.x,
    y + motion.y)`` lies in ``[-0.5, size - 0.5]``: ``h`` = the Catmull-Rom fetch of the
    previous output at ``P`` (4x4 taps, indices clamped, negatives to 0); in the tonemapped
    space ``T(c) = c / (1 + l(c))`` it is clipped per channel to ``mu +- 0.5 sigma`` of the
    current 3x3 (population sigma, in-image pixels), widened to hold the pixel's own
    ``T(c)``, and taken back by ``c = T / (1 - l(T))``
    (``l(T)`` at most 0.999); then ``out = alpha c + (1 - alpha) h``. Everywhere else the
    current value.
    """
    cur = np.asarray(current, dtype=F64)
    prev = np.asarray(previous, dtype=F64)
    mv = np.asarray(motion, dtype=F64)
    w = np.asarray(weights, dtype=F64)
    _, height, width = cur.shape
    outline = taa_outline(depth)
    out = cur.copy()

    def luma(c: np.ndarray) -> float:
        return max(float(w @ c), 0.0)

    for y in range(height):
        for x in range(width):
            px, py = x + mv[0, y, x], y + mv[1, y, x]
            if not outline[y, x] or not (-0.5 <= px <= width - 0.5
                                         and -0.5 <= py <= height - 0.5):
                continue
            x0, y0 = math.floor(px), math.floor(py)
            wx, wy = _catmull_rom(px - x0), _catmull_rom(py - y0)
            rows = np.clip(np.arange(y0 - 1, y0 + 3), 0, height - 1)
            cols = np.clip(np.arange(x0 - 1, x0 + 3), 0, width - 1)
            taps = prev[:, rows][:, :, cols]  # (3, 4, 4)
            history = np.maximum(np.einsum("j,i,cji->c", wy, wx, taps), 0.0)
            window = cur[:, max(y - 1, 0):y + 2, max(x - 1, 0):x + 2].reshape(3, -1)
            mapped = window / (1.0 + np.maximum(w @ window, 0.0))
            mean, sigma = mapped.mean(axis=1), mapped.std(axis=1)
            centre = cur[:, y, x] / (1.0 + luma(cur[:, y, x]))
            clipped = np.clip(history / (1.0 + luma(history)),
                              np.minimum(mean - TAA_CLIP_SIGMA * sigma, centre),
                              np.maximum(mean + TAA_CLIP_SIGMA * sigma, centre))
            history = np.maximum(clipped, 0.0) / (1.0 - min(luma(clipped), 0.999))
            out[:, y, x] = alpha * cur[:, y, x] + (1.0 - alpha) * history
    return out


# --------------------------------------------------------------------------- pixel filter
def pixel_filter(colour: np.ndarray, emission: np.ndarray, weight: float) -> np.ndarray:
    """``K (colour - emission) + emission`` with ``K`` the separable ``[w, 1 - 2w, w]``,
    edges replicated (``svgf_cli.filters.pixel_filter``)."""
    light = np.asarray(emission, dtype=F64)
    rest = np.asarray(colour, dtype=F64) - light
    kernel = np.array([weight, 1.0 - 2.0 * weight, weight])
    for axis in (2, 1):
        padded = np.pad(rest, [(1, 1) if a == axis else (0, 0) for a in range(3)], mode="edge")
        size = rest.shape[axis]
        rest = sum(k * np.take(padded, np.arange(i, i + size), axis=axis)
                   for i, k in enumerate(kernel))
    return rest + light


def edge_filter(colour: np.ndarray, mesh_id: np.ndarray, depth: np.ndarray,
                weight: float | np.ndarray) -> np.ndarray:
    """Each pair of neighbouring pixels on two surfaces (ids differ, one background, depths
    more than 5 % apart) exchanges the mean of its two pixels' ``weight`` (a number or an
    (H, W) plane) of its colour difference, rows then columns
    (``svgf_cli.filters.edge_filter``)."""
    z = np.asarray(depth, dtype=F64)
    ids = np.asarray(mesh_id)
    w = np.broadcast_to(np.asarray(weight, dtype=F64), z.shape)

    def outlines(a: tuple[slice, slice], b: tuple[slice, slice]) -> np.ndarray:
        za, zb = z[a], z[b]
        both = (za > 0.0) & (zb > 0.0)
        jump = (za > 1.05 * zb) | (zb > 1.05 * za)
        return (ids[a] != ids[b]) | ((za > 0.0) != (zb > 0.0)) | (both & jump)

    out = np.asarray(colour, dtype=F64).copy()
    for axis in (2, 1):  # rows, then columns
        first = tuple(slice(0, -1) if a == axis - 1 else slice(None) for a in range(2))
        second = tuple(slice(1, None) if a == axis - 1 else slice(None) for a in range(2))
        pair = 0.5 * (w[first] + w[second])
        flow = pair * outlines(first, second) * (out[(slice(None), *second)]
                                                 - out[(slice(None), *first)])
        out[(slice(None), *first)] += flow
        out[(slice(None), *second)] -= flow
    return out


def outline_share(mesh_id: np.ndarray, depth: np.ndarray, radius: int = 2) -> np.ndarray:
    """Per pixel, the share of the pairs (each pixel of its (2r+1)^2 window with its right and
    lower neighbour in the image) that change object or meet the background, counted."""
    ids = np.asarray(mesh_id)
    background = np.asarray(depth) <= 0.0
    height, width = ids.shape
    share = np.zeros((height, width), dtype=F64)
    for y in range(height):
        for x in range(width):
            count = pairs = 0
            for v in range(y - radius, y + radius + 1):
                for u in range(x - radius, x + radius + 1):
                    if not (0 <= v < height and 0 <= u < width):
                        continue
                    for dv, du in ((0, 1), (1, 0)):
                        vv, uu = v + dv, u + du
                        if vv < height and uu < width:
                            pairs += 1
                            count += bool(ids[v, u] != ids[vv, uu]
                                          or background[v, u] != background[vv, uu])
            share[y, x] = count / pairs
    return share


def isolated_samples(mesh_id: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """Per pixel: every one of its 4 neighbours in the image (two at least) shows another
    object or, of the two, one the background."""
    ids, background = np.asarray(mesh_id), np.asarray(depth) <= 0.0

    def alone(y: int, x: int) -> bool:
        inside = [(v, u) for v, u in ((y - 1, x), (y + 1, x), (y, x - 1), (y, x + 1))
                  if 0 <= v < ids.shape[0] and 0 <= u < ids.shape[1]]
        return len(inside) >= 2 and all(
            ids[v, u] != ids[y, x] or background[v, u] != background[y, x] for v, u in inside)

    return np.array([[alone(y, x) for x in range(ids.shape[1])] for y in range(ids.shape[0])],
                    dtype=bool).reshape(ids.shape)


def near(pixels: np.ndarray, radius: int = 2) -> np.ndarray:
    """Per pixel: one of ``pixels`` within its (2r+1)^2 window."""
    height, width = pixels.shape
    out = np.zeros((height, width), dtype=bool)
    for y in range(height):
        for x in range(width):
            out[y, x] = bool(pixels[max(y - radius, 0):y + radius + 1,
                                    max(x - radius, 0):x + radius + 1].any())
    return out


def noisy_outline_filter(colour: np.ndarray, mesh_id: np.ndarray, depth: np.ndarray,
                         base: float, noisy: float, medium: np.ndarray | None = None,
                         centre_sampled: bool = True) -> np.ndarray:
    """The edge filter (``base``), then the noisy outlines' extra weight, ``noisy`` times the
    outlines' density (0 below a share of 0.3, 1 from 0.55; on a ``centre_sampled`` frame 1
    on an isolated sample whose share is 0.15 or more, not near a ``medium`` pixel), in four
    more passes (``svgf_cli.filters.stages.edge_filter``)."""
    share = outline_share(mesh_id, depth)
    dense = np.clip((share - 0.3) / 0.25, 0.0, 1.0)
    if centre_sampled:
        lone = isolated_samples(mesh_id, depth) & (share >= 0.15)
        if medium is not None:
            lone &= ~near(medium)
        dense[lone] = 1.0
    extra = noisy * dense
    out = edge_filter(colour, mesh_id, depth, base) if base > 0.0 else colour
    if np.any(extra > 0.0):
        for _ in range(4):
            out = edge_filter(out, mesh_id, depth, extra)
    return out


# --------------------------------------------------------------------------- history guard
def reset_nonfinite_history(history: History) -> int:
    """In place: where any signal's history (colour, moments, history length) holds a
    non-finite value, reset the pixel for every signal (zeros, history length 0, no
    history for the next frame to resample). Returns how many pixels were reset."""
    bad = ~(np.all(np.isfinite(history.illumination), axis=(0, 1))
            & np.all(np.isfinite(history.moments), axis=(0, 1))
            & np.all(np.isfinite(history.history_length), axis=0))
    history.illumination[:, :, bad] = 0.0
    history.moments[:, :, bad] = 0.0
    history.history_length[:, bad] = 0.0
    history.has_history[bad] = False
    return int(bad.sum())


# --------------------------------------------------------------------------- the whole
@dataclass
class ReferenceOutput:
    """One frame's result, with the same names as ``DenoisedFrame`` and its debug layers:
    ``color``; ``variance`` (S, H, W) before the a-trous; ``history_length`` (S, H, W);
    ``radiance`` per signal name (remodulated, background restored, no emission);
    ``radiance_mode`` (S, H, W); ``counts`` as ``DenoisedFrame.counts``."""

    color: np.ndarray
    variance: np.ndarray
    history_length: np.ndarray
    radiance_mode: np.ndarray
    radiance: dict[str, np.ndarray] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)


@dataclass
class TemporalState:
    """What :meth:`ReferenceDenoiser.before_accumulation` sees (the Denoiser's anti-lag
    hook): this frame's demodulated ``current`` illumination and its ``radiance_mode``, and
    the reprojected ``history`` (per signal; history length 0 = none), which it may change."""

    current: np.ndarray
    radiance_mode: np.ndarray
    history: Reprojected
    depth: np.ndarray
    weights: tuple[float, float, float]
    glossy: list[bool] = field(default_factory=list)  # per signal: Signal.glossy


def antilag_gradient_change(mask, previous, current, radius, sigma):
    """A-SVGF gradient samples: per 2x2 cell, over the window of (2r+1)^2 cells, the relative
    change ``|sum delta| / sum max(curr, prev)`` where the mean delta exceeds ``sigma``
    standard errors of the samples (Bessel-corrected), else 0."""
    height, width = mask.shape
    cells_y, cells_x = (height + 1) // 2, (width + 1) // 2
    out = np.zeros((cells_y, cells_x))
    has = mask > 0
    delta = current.astype(np.float64) - previous.astype(np.float64)
    level = np.maximum(current, previous).astype(np.float64)
    for cy in range(cells_y):
        for cx in range(cells_x):
            window = (slice(2 * max(cy - radius, 0), 2 * (cy + radius + 1)),
                      slice(2 * max(cx - radius, 0), 2 * (cx + radius + 1)))
            v = has[window]
            n = v.sum()
            if n < 2:
                continue
            d = delta[window][v]
            if d.mean() ** 2 > sigma**2 * d.var(ddof=1) / n and level[window][v].sum() > 0:
                out[cy, cx] = min(abs(d.sum()) / level[window][v].sum(), 1.0)
    return out


def _signal_statistics(current, moments, history_length, depth, w, s):
    """Signal ``s``'s per-pixel terms for anti-lag's windows (float64): the current
    luminance, the first moment, the temporal variance ``m2 - m1^2`` (at least 0), the
    history length, and which pixels have a history on a surface."""
    lum = np.einsum("c,chw->hw", w, current[s].astype(np.float64))
    m1 = moments[s, 0].astype(np.float64)
    temporal = np.maximum(moments[s, 1].astype(np.float64) - m1 * m1, 0.0)
    valid = (history_length[s] > 0) & (depth > 0)
    return lum, m1, temporal, np.asarray(history_length[s], dtype=np.float64), valid


def antilag(current, moments, history_length, depth, weights, radius, sigma, spatial_samples,
            tolerance, moments_alpha, gradients=None, min_samples=4, sigma_start=None):
    """Anti-lag (``filters.antilag``), every cell window the obvious way: per signal, over
    the pixels with history in the (2r+1)^2 cells of 2x2 pixels around a cell, the current
    luminance's mean and Bessel-corrected variance, the reprojected first moment's mean, the
    mean temporal variance and history length; stale where the squared difference exceeds
    start^2 var/n (1 + max(1/h, a/(2-a))) + (tolerance level)^2; weight r b^2 / (b^2 +
    var / N) with b^2 = diff^2 - var/n and r the difference's standard errors' linear ramp
    from ``sigma_start`` (default ``sigma``: a step) to ``sigma`` (and the gradient
    samples' bias when given); 3x3
    cell maximum; ``h = min(h, 1/lambda - 1)``. Returns (lambda per cell (S, Hc, Wc), new
    history length (S, H, W), how many histories were shortened)."""
    w = np.asarray(weights, dtype=np.float64)
    num_signals, _, height, width = current.shape
    cells_y, cells_x = (height + 1) // 2, (width + 1) // 2
    lam = np.zeros((num_signals, cells_y, cells_x))
    new_length = np.asarray(history_length, dtype=np.float64).copy()
    stationary = moments_alpha / (2.0 - moments_alpha)
    start = sigma if sigma_start is None else min(sigma_start, sigma)
    for s in range(num_signals):
        lum, m1, temporal, length, valid = _signal_statistics(
            current, moments, history_length, depth, w, s)
        change = None
        if gradients is not None and gradients[s] is not None:
            change = antilag_gradient_change(*gradients[s], radius, sigma)
        raw = np.zeros((cells_y, cells_x))
        for cy in range(cells_y):
            for cx in range(cells_x):
                window = (slice(2 * max(cy - radius, 0), 2 * (cy + radius + 1)),
                          slice(2 * max(cx - radius, 0), 2 * (cx + radius + 1)))
                v = valid[window]
                n = v.sum()
                if n < min_samples:
                    continue
                c = lum[window][v]
                mean_c = c.mean()
                mean_h = m1[window][v].mean()
                var = max(c.var(ddof=1), temporal[window][v].mean())
                share = max(1.0 / max(length[window][v].mean(), 1.0), stationary)
                diff2 = (mean_h - mean_c) ** 2
                level = max(mean_c, mean_h)
                error2 = var / n * (1 + share)
                if diff2 > start**2 * error2 + (tolerance * level) ** 2:
                    bias2 = diff2 - var / n
                    z = np.sqrt(diff2 / error2) if error2 > 0 else np.inf
                    ramp = min((z - start) / (sigma - start), 1.0) if sigma > start else 1.0
                    raw[cy, cx] = ramp * bias2 / (bias2 + var / spatial_samples)
                if change is not None:
                    bias2 = (change[cy, cx] * mean_h) ** 2
                    if bias2 > 0:
                        raw[cy, cx] = max(raw[cy, cx], bias2 / (bias2 + var / spatial_samples))
        for cy in range(cells_y):
            for cx in range(cells_x):
                lam[s, cy, cx] = raw[max(cy - 1, 0):cy + 2, max(cx - 1, 0):cx + 2].max()
        for y in range(height):
            for x in range(width):
                best = lam[s, y // 2, x // 2]
                if valid[y, x] and best > 0:
                    new_length[s, y, x] = min(new_length[s, y, x], max(1.0 / best - 1.0, 0.0))
    shortened = int(np.count_nonzero(new_length < np.asarray(history_length) - 1e-6))
    return lam, new_length, shortened


def _window_statistics(lum, m1, temporal, length, valid, cy, cx, radius, stationary):
    """A cell's window of (2r+1)^2 cells: count, current and first-moment means and their
    difference's squared standard error (anti-lag's statistics)."""
    window = (slice(2 * max(cy - radius, 0), 2 * (cy + radius + 1)),
              slice(2 * max(cx - radius, 0), 2 * (cx + radius + 1)))
    v = valid[window]
    n = int(v.sum())
    if n == 0:
        return 0, 0.0, 0.0, 0.0
    c = lum[window][v]
    var = max(c.var(ddof=1) if n > 1 else 0.0, temporal[window][v].mean())
    share = max(1.0 / max(length[window][v].mean(), 1.0), stationary)
    return n, c.mean(), m1[window][v].mean(), var / n * (1 + share)


def history_gain(current, illumination, moments, history_length, depth, weights, radius,
                 sigma, sigma_start, tolerance, moments_alpha, scale=5, checks=(2, 1),
                 gain_max=4.0, min_samples=4):
    """The history gain (``filters.history_gain``), every window the obvious way: per
    signal and cell, over the pixels with history in the wide window (radius ``scale r``
    cells) the gain ``g = m_c / m_h`` where ``(m_c - m_h)^2 > sigma^2 e^2 + (tolerance
    level)^2`` and ``g`` lies in ``[1 / gain_max, gain_max]``, shrunk to ``1 + b^2 / (b^2 +
    e^2) (g - 1)`` with ``b^2 = (m_c - m_h)^2 - e^2``; kept where every check window (radius
    ``c r`` for ``c`` in ``checks``) has ``(m_c - g m_h)^2 <= sigma_start^2 e^2 +
    (tolerance level)^2``. Returns (illumination, moments, gain per cell (S, Hc, Wc), how
    many histories were rescaled)."""
    w = np.asarray(weights, dtype=np.float64)
    num_signals, _, height, width = current.shape
    cells_y, cells_x = (height + 1) // 2, (width + 1) // 2
    gain = np.ones((num_signals, cells_y, cells_x))
    out = np.asarray(illumination, dtype=np.float64).copy()
    out_moments = np.asarray(moments, dtype=np.float64).copy()
    stationary = moments_alpha / (2.0 - moments_alpha)
    start = min(sigma_start, sigma)
    count = 0
    for s in range(num_signals):
        lum, m1, temporal, length, valid = _signal_statistics(
            current, moments, history_length, depth, w, s)
        statistics = (lum, m1, temporal, length, valid)
        for cy in range(cells_y):
            for cx in range(cells_x):
                n, mean_c, mean_h, error2 = _window_statistics(
                    *statistics, cy, cx, scale * radius, stationary)
                diff2 = (mean_c - mean_h) ** 2
                level = max(mean_c, mean_h)
                if (n < min_samples or mean_h <= 0
                        or diff2 <= sigma**2 * error2 + (tolerance * level) ** 2):
                    continue
                ratio = mean_c / mean_h
                if not 1.0 / gain_max <= ratio <= gain_max:
                    continue
                bias2 = max(diff2 - error2, 0.0)
                g = 1.0 + bias2 / (bias2 + error2) * (ratio - 1.0)
                for check in checks:
                    n_r, mean_c_r, mean_h_r, error2_r = _window_statistics(
                        *statistics, cy, cx, check * radius, stationary)
                    level_r = max(mean_c_r, g * mean_h_r)
                    if (n_r < min_samples or (mean_c_r - g * mean_h_r) ** 2
                            > start**2 * error2_r + (tolerance * level_r) ** 2):
                        break
                else:
                    gain[s, cy, cx] = g
        for y in range(height):
            for x in range(width):
                g = gain[s, y // 2, x // 2]
                if valid[y, x] and g != 1.0:
                    out[s, :, y, x] *= g
                    out_moments[s, 0, y, x] *= g
                    out_moments[s, 1, y, x] *= g * g
                    count += 1
    return out, out_moments, gain, count


@dataclass
class FrameState:
    """A frame between the anti-lag hook and the blend: the cleaned frame, its geometry, its
    demodulated ``illumination`` and modes, and the resampled ``history`` (per signal)."""

    clean: CleanFrame
    geom: Geometry
    illumination: np.ndarray
    radiance_mode: np.ndarray
    history: Reprojected


class ReferenceDenoiser:
    """The ``Denoiser`` pipeline in float64, stage by stage; owns the history.

    Per frame: value policy -> geometry -> demodulate each signal by its own colour, with
    its mode (+ firefly clamp) -> reproject each signal (mode-matched taps) ->
    :meth:`before_accumulation` (the history gain; the history clamp; anti-lag) ->
    accumulate each signal with its own history length -> variance (+ colour blur) ->
    a-trous at steps 2^i, the output of ``feedback_iteration`` (clamped to the last
    iteration; -1 or no iterations: the colour entering the a-trous) becoming the colour
    history -> history guard -> remodulate, restore background, sum the signals, add the
    emission once -> TAA.
    """

    def __init__(self, params: SVGFParams) -> None:
        self.params = params
        self.history: History | None = None
        self.taa_previous: np.ndarray | None = None
        self.last_reprojected: Reprojected | None = None  # for tests and diagnosis
        self.rescaled: int | None = None  # the history gain's count this frame
        # temporal_albedo: each signal's colour mean (S, 3, H, W) and its length (S, H, W)
        self.albedo_mean: np.ndarray | None = None
        self.albedo_length: np.ndarray | None = None

    def before_accumulation(self, temporal: TemporalState) -> int | None:
        """Adjust the reprojected history before it is blended: the optional history gain,
        the history clamp, then anti-lag. Lowering ``temporal.history.history_length[s]``
        raises signal ``s``'s blend factor there. Returns anti-lag's count (None when it is off)."""
        p = self.params
        reprojected = temporal.history
        self.rescaled = None
        if p.antilag and p.antilag_gain:  # the history gain, before the clamp sees it
            reprojected.illumination, reprojected.moments, _, self.rescaled = history_gain(
                temporal.current, reprojected.illumination, reprojected.moments,
                reprojected.history_length, temporal.depth, temporal.weights,
                antilag_radius_for(p, *temporal.depth.shape), p.antilag_sigma,
                p.antilag_sigma_start, p.antilag_tolerance, p.moments_alpha)
        # The history clamp, one signal at a time: glossy signals at their own k.
        glossy = temporal.glossy or (False,) * reprojected.illumination.shape[0]
        for s, is_glossy in enumerate(glossy):
            k = (p.glossy_history_clamp or p.history_clamp) if is_glossy else p.history_clamp
            if k > 0.0:
                one = slice(s, s + 1)
                reprojected.illumination[one], reprojected.moments[one] = history_clamp(
                    reprojected.illumination[one], reprojected.moments[one],
                    reprojected.history_length[one], temporal.current[one], temporal.depth, k,
                    temporal.weights)
        shortened = None
        if p.antilag:
            _, length, shortened = antilag(
                temporal.current, reprojected.moments, reprojected.history_length,
                temporal.depth, temporal.weights, antilag_radius_for(p, *temporal.depth.shape),
                p.antilag_sigma,
                p.antilag_spatial_samples, p.antilag_tolerance, p.moments_alpha,
                sigma_start=p.antilag_sigma_start)
            reprojected.history_length = length
        return shortened

    def process(self, frame: Frame) -> ReferenceOutput:
        p = self.params
        clean = apply_value_policy(frame)
        counts = clean.counts
        geom = geometry(clean.depth, clean.normal)
        surface = geom.surface
        marked: dict[int, int] = {}
        if p.glossy_emitter_radiance:
            # A glossy signal is radiance where the G-buffer albedo is no reflectance (a
            # specular path reached a light) at the pixel and at two of its 8 neighbours:
            # its colour becomes that albedo there.
            guide = clean_albedo(frame.albedo)
            emitter = reflected_lights(guide)
            for index, glossy in enumerate(clean.glossy):
                if glossy:
                    marked[index] = int(np.sum(emitter & surface))
                    clean.albedo[index] = np.where(emitter, guide, clean.albedo[index])
        planes = []
        for index, name in enumerate(clean.names):
            illumination, mode, clamped = demodulate(clean.radiance[index],
                                                     clean.albedo[index],
                                                     demodulation_floor(p, clean, index))
            brightest = clean.albedo[index].max(axis=0)
            counts[f"clamped.{name}"] = clamped
            counts[f"radiance_mode.{name}"] = int(np.sum(mode & surface))
            counts[f"implausible_albedo.{name}"] = int(
                np.sum((brightest > MAX_REFLECTANCE) & surface)) - marked.get(index, 0)
            if index in marked:
                counts[f"reflected_light.{name}"] = marked[index]
            planes.append((illumination, mode))
        illumination = np.stack([c for c, _ in planes])
        radiance_mode = np.stack([m for _, m in planes])
        if p.firefly_clamp > 0.0:
            illumination = firefly_clamp(illumination, geom.depth, p.firefly_clamp,
                                         clean.weights)

        shape = illumination.shape
        if p.temporal and self.history is not None:
            reprojected = reproject(clean.motion, geom, clean.mesh_id, radiance_mode,
                                    self.history, p.depth_tolerance, p.depth_slack,
                                    p.normal_tolerance, p.history_catmull_rom)
            shortened = self.before_accumulation(TemporalState(
                illumination, radiance_mode, reprojected, geom.depth, clean.weights,
                clean.glossy))
            if shortened is not None:
                counts["antilag"] = shortened
            if self.rescaled is not None:
                counts["history_gain"] = self.rescaled
            if p.spread_fireflies > 0.0:  # against the history anti-lag left
                illumination, found = spread_fireflies(
                    illumination, radiance_mode, reprojected.moments, geom.depth,
                    [not g for g in clean.glossy], p.spread_fireflies, clean.weights,
                    albedo=clean.albedo, guide=clean.guide)
                if p.glossy_spread_fireflies:  # the glossy signals', over their 3x3
                    illumination, glossy_found = spread_fireflies(
                        illumination, radiance_mode, reprojected.moments, geom.depth,
                        list(clean.glossy), p.spread_fireflies, clean.weights, radius=1,
                        albedo=clean.albedo, guide=clean.guide, cap=True)
                    found = [a + b for a, b in zip(found, glossy_found, strict=True)]
                counts.update({f"fireflies_spread.{name}": count
                               for name, count in zip(clean.names, found, strict=True)})
            self.last_reprojected = reprojected
        else:
            reprojected = Reprojected(np.zeros(shape), np.zeros((shape[0], 2, *shape[2:])),
                                      np.zeros((shape[0], *shape[2:])),
                                      np.zeros((shape[0], *shape[2:]), np.int8))
        self.before_blend(FrameState(clean, geom, illumination, radiance_mode, reprojected))
        colour, moments, length = accumulate(
            illumination, reprojected.illumination, reprojected.moments,
            reprojected.history_length, geom.depth, p.alpha, p.moments_alpha, p.history_cap,
            clean.weights)
        if p.temporal_albedo:
            # Demodulated by this frame's colour; remodulated by its running mean.
            clean.albedo = self.temporal_albedo(clean, geom)

        accumulation = colour
        colour, variance_before_atrous, colour_history = self.filter_spatially(
            clean, geom, colour, moments, length, radiance_mode)
        colour_history = self.pass_history(clean, geom, accumulation, moments, length,
                                           radiance_mode, colour_history)
        self.history = History(np.array(colour_history), np.array(moments), np.array(length),
                               radiance_mode, np.ones(geom.depth.shape, bool), geom.depth,
                               geom.unit_normal, np.array(clean.mesh_id))
        counts["history_resets"] = reset_nonfinite_history(self.history)
        return self.compose(clean, geom, colour, variance_before_atrous, length,
                            radiance_mode, counts)

    def before_blend(self, state: FrameState) -> None:
        """Called with the frame's state after the anti-lag hook, before the blend (also on
        a frame without history); a bidirectional run reads the resampled history here."""

    def temporal_albedo(self, clean: CleanFrame, geom: Geometry) -> np.ndarray:
        """Each signal's colour as its running mean over the frames
        (:func:`accumulate_albedo`, against last frame's depth and mesh id; without history
        every tap is rejected), kept for the next frame; a glossy signal keeps its colour
        (length 0). Returns the means (S, 3, H, W)."""
        p = self.params
        count = len(clean.names)
        shape = (count, 3, *geom.depth.shape)
        if (p.temporal and self.history is not None and self.albedo_mean is not None
                and self.albedo_length is not None and self.albedo_mean.shape == shape):
            means, lengths = self.albedo_mean, self.albedo_length
            prev_depth, prev_mesh_id = self.history.depth, self.history.mesh_id
        else:
            means, lengths = np.zeros(shape), np.zeros((count, *geom.depth.shape))
            prev_depth, prev_mesh_id = geom.depth, clean.mesh_id
        results = [(np.asarray(clean.albedo[index], dtype=F64), np.zeros(geom.depth.shape))
                   if clean.glossy[index] else
                   accumulate_albedo(clean.albedo[index], means[index], lengths[index],
                                     clean.motion, geom.depth, clean.mesh_id, prev_depth,
                                     prev_mesh_id, p.alpha, p.history_cap,
                                     demodulation_floor(p, clean, index),
                                     p.albedo_catmull_rom)
                   for index in range(count)]
        self.albedo_mean = np.stack([colour for colour, _ in results])
        self.albedo_length = np.stack([length for _, length in results])
        return self.albedo_mean.copy()

    def pass_history(self, clean: CleanFrame, geom: Geometry, accumulation: np.ndarray,
                     moments: np.ndarray, length: np.ndarray, radiance_mode: np.ndarray,
                     colour_history: np.ndarray) -> np.ndarray:
        """The colour history kept for the next frame (a causal run: ``colour_history``, the
        output of ``feedback_iteration``); a bidirectional pass keeps its own."""
        return colour_history

    def filter_spatially(self, clean: CleanFrame, geom: Geometry, colour: np.ndarray,
                         moments: np.ndarray, length: np.ndarray, radiance_mode: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Variance and the a-trous of an accumulation: returns (filtered colour, variance
        entering the a-trous, the colour history: the output of ``feedback_iteration``)."""
        p = self.params
        variance, colour = estimate_variance(colour, moments, length, radiance_mode, geom, p)
        variance_before_atrous = variance
        iterations = iteration_count(p.atrous_iterations, *geom.depth.shape)
        feedback = min(p.feedback_iteration, iterations - 1)
        colour_history = unfiltered = colour
        for iteration, step in enumerate(atrous_steps(iterations)):
            guides = luminance_stop_guides(colour, variance, geom.depth,
                                           atrous_sigmas(p, clean, geom), clean.weights,
                                           guide_blur_modes(p, radiance_mode))
            colour, variance = atrous_iteration(colour, variance, guides[0], radiance_mode,
                                                guides[1], geom.depth, geom.ddx, geom.ddy,
                                                geom.unit_normal, step, p.sigma_depth,
                                                p.sigma_normal, symmetric_stops(p, clean))
            if iteration == feedback:
                colour_history = colour
        if feedback >= 0 and p.moving_feedback_share < 1.0:
            # H = w F + (1 - w) U: w = 1 where the pixel stands still, the share where it moves.
            motion = np.asarray(clean.motion, dtype=F64)
            still = (np.abs(motion[0]) < STATIC_MOTION) & (np.abs(motion[1]) < STATIC_MOTION)
            share = np.where(still, 1.0, p.moving_feedback_share)
            colour_history = unfiltered + share * (colour_history - unfiltered)
        return colour, variance_before_atrous, colour_history

    def compose(self, clean: CleanFrame, geom: Geometry, colour: np.ndarray,
                variance: np.ndarray, length: np.ndarray, radiance_mode: np.ndarray,
                counts: dict[str, int]) -> ReferenceOutput:
        """Remodulate, restore the background, sum the signals, add the emission (+ TAA)."""
        p = self.params
        variance_before_atrous = variance
        if p.despike > 0.0:
            colour, changed = despike(colour, radiance_mode, geom.depth, p.despike,
                                      clean.weights)
            for name, value in zip(clean.names, changed, strict=True):
                counts[f"despiked.{name}"] = value
        per_signal = {}
        for index, name in enumerate(clean.names):
            radiance = remodulate(colour[index], clean.albedo[index],
                                  demodulation_floor(p, clean, index))
            per_signal[name] = radiance_with_background(radiance, clean.radiance[index],
                                                        geom.depth)
        output = sum(per_signal.values())
        if clean.emission is not None:
            output = output + clean.emission
        if p.despike > 0.0:
            output, counts["despiked_lone"] = despike_lone(
                output, clean.emission, radiance_mode, geom.depth, p.despike, clean.weights)
        if p.taa or (p.taa_jittered and not clean.centre_sampled
                     and jittered_samples(geom.depth, clean.normal, clean.mesh_id)):
            if self.taa_previous is not None:
                output = taa_resolve(output, self.taa_previous, clean.motion, geom.depth,
                                     clean.weights, p.taa_alpha)
            self.taa_previous = output
        else:
            self.taa_previous = None
        weight = p.pixel_filter
        if weight == -1.0:  # auto: the header says the frame is centre-sampled
            weight = 0.05 if clean.centre_sampled else 0.0
        if weight > 0.0:
            emission = clean.emission if clean.emission is not None else np.zeros_like(output)
            output = pixel_filter(output, emission, weight)
        weight = p.edge_filter
        if weight == -1.0:  # auto, as the pixel filter
            weight = 0.05 if clean.centre_sampled else 0.0
        if weight > 0.0 or p.noisy_outline_weight > 0.0:
            output = noisy_outline_filter(output, clean.mesh_id, clean.depth, weight,
                                          p.noisy_outline_weight)
        return ReferenceOutput(output, variance_before_atrous, length, radiance_mode,
                               per_signal, counts)


# --------------------------------------------------------------------------- bidirectional
def effective_count(h: float, alpha: float) -> float:
    """``n(h)``: effective samples of an accumulation of ``h`` frames whose k-th frame is
    blended with ``a_k = max(alpha, 1/k)``: the variance share ``v_1 = 1``,
    ``v_k = (1 - a_k)^2 v_(k-1) + a_k^2``, ``n(k) = 1 / v_k``, ``n(0) = 0``; linear between
    whole counts."""
    def whole(k: int) -> float:
        share = 1.0
        for i in range(2, k + 1):
            a = max(alpha, 1.0 / i)
            share = (1.0 - a) ** 2 * share + a * a
        return 1.0 / share if k >= 1 else 0.0

    if h <= 0.0:
        return 0.0
    below = math.floor(h)
    return whole(below) + (h - below) * (whole(below + 1) - whole(below))


def combine_histories(current: np.ndarray, forward: Reprojected, reverse: Reprojected,
                      depth: np.ndarray, alpha: float, moments_alpha: float,
                      weights: Sequence[float] = REC709,
                      reference_counts: Sequence[float] | None = None, history_cap: int = 32,
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A bidirectional run's combined accumulation (``docs/bidirectional.md``): per signal
    and surface pixel, ``c = (x + n_f H_f + n_r H_r) / (1 + n_f + n_r)`` for the colour
    (counts with ``alpha``) and the moments ``(l, l^2)`` (counts with ``moments_alpha``),
    whose variance ``m2 - m1^2`` is then scaled by ``min(1, n_ref / (1 + n_f + n_r))``
    (``n_ref``: ``reference_counts[s]``, by default ``n(history_cap)`` with
    ``moments_alpha``); history length ``1 + h_f + h_r``; background: the current values,
    length 0."""
    x = np.asarray(current, dtype=F64)
    if reference_counts is None:
        reference_counts = [effective_count(history_cap, moments_alpha)] * x.shape[0]
    lum = luminance(x, weights)
    x_moments = np.stack([lum, lum * lum], axis=1)
    colour = x.copy()
    moments = x_moments.copy()
    num_signals, _, height, width = x.shape
    length = np.zeros((num_signals, height, width))
    for s in range(num_signals):
        for y in range(height):
            for px in range(width):
                if depth[y, px] <= 0.0:
                    continue
                hf = float(forward.history_length[s, y, px])
                hr = float(reverse.history_length[s, y, px])
                for alpha_, target, here, f_side, r_side in (
                    (alpha, colour, x, forward.illumination, reverse.illumination),
                    (moments_alpha, moments, x_moments, forward.moments, reverse.moments),
                ):
                    nf, nr = effective_count(hf, alpha_), effective_count(hr, alpha_)
                    target[s, :, y, px] = (here[s, :, y, px] + nf * f_side[s, :, y, px]
                                           + nr * r_side[s, :, y, px]) / (1.0 + nf + nr)
                # the variance relative to the reference count n_ref
                nf, nr = effective_count(hf, moments_alpha), effective_count(hr, moments_alpha)
                shrink = min(1.0, reference_counts[s] / (1 + nf + nr))
                m1 = moments[s, 0, y, px]
                moments[s, 1, y, px] = m1 * m1 + shrink * max(moments[s, 1, y, px] - m1 * m1, 0)
                length[s, y, px] = 1.0 + hf + hr
    return colour, moments, length


def count_to_length(n: float, alpha: float, history_cap: int = 32) -> float:
    """The inverse of :func:`effective_count` on [0, history_cap]: the length ``h`` with
    ``n(h) = n`` (linear between whole counts)."""
    if n <= 0.0:
        return 0.0
    for k in range(history_cap):
        low, high = effective_count(k, alpha), effective_count(k + 1, alpha)
        if n < high:
            return k + (n - low) / (high - low)
    return float(history_cap)


def consistent_lengths(current: np.ndarray, forward: Reprojected, reverse: Reprojected,
                       depth: np.ndarray, alpha: float, sigma: float,
                       weights: Sequence[float] = REC709, history_cap: int = 32,
                       ) -> tuple[np.ndarray, np.ndarray]:
    """The consistency test between the two sides (``docs/bidirectional.md``): where both
    sides have history and their first moments differ by more than ``sigma`` standard
    errors, ``D^2 = (m_f - m_r)^2 > sigma^2 v (1/n_f + 1/n_r)`` with the per-sample
    variance ``v = max`` of the sides' ``m2 - m1^2`` and counts ``n(h)`` (``alpha``), the
    current luminance ``l`` weighs the two: ``P_f = 1 / (1 + exp(-L))``,
    ``L = ((l - m_r)^2 - (l - m_f)^2) / (2 v)``; the less likely side keeps
    ``1 - t |2 P_f - 1|`` of its count, ``t = 1 - sigma^2 v (1/n_f + 1/n_r) / D^2``.
    Returns the two sides' lengths."""
    lum = luminance(np.asarray(current, dtype=F64), weights)
    hf_out = np.array(forward.history_length, dtype=F64)
    hr_out = np.array(reverse.history_length, dtype=F64)
    num_signals, height, width = hf_out.shape
    for s in range(num_signals):
        for y in range(height):
            for px in range(width):
                hf, hr = hf_out[s, y, px], hr_out[s, y, px]
                if depth[y, px] <= 0.0 or hf <= 0.0 or hr <= 0.0:
                    continue
                mf, mr = float(forward.moments[s, 0, y, px]), float(reverse.moments[s, 0, y, px])
                var = max(float(forward.moments[s, 1, y, px]) - mf * mf,
                          float(reverse.moments[s, 1, y, px]) - mr * mr, 0.0)
                nf, nr = effective_count(hf, alpha), effective_count(hr, alpha)
                allowed = sigma**2 * var * (1.0 / max(nf, 1.0) + 1.0 / max(nr, 1.0))
                d2 = (mf - mr) ** 2
                if d2 <= allowed:
                    continue
                strength = 1.0 - allowed / d2
                l_ = float(lum[s, y, px])
                ratio = ((l_ - mr) ** 2 - (l_ - mf) ** 2) / (2.0 * max(var, 1e-30))
                pf = 1.0 / (1.0 + math.exp(-min(max(ratio, -30.0), 30.0)))
                keep = 1.0 - strength * abs(2.0 * pf - 1.0)
                if pf < 0.5:
                    hf_out[s, y, px] = min(hf, count_to_length(keep * nf, alpha, history_cap))
                else:
                    hr_out[s, y, px] = min(hr, count_to_length(keep * nr, alpha, history_cap))
    return hf_out, hr_out


NO_MOTION = 1e9  # a derived motion's hole: leads far outside the image (no history)


def invert_motion(next_motion: np.ndarray, next_depth: np.ndarray,
                  depth_tolerance: float = 0.02) -> tuple[np.ndarray, int]:
    """Motion from frame t to t + 1 from frame t + 1's backward motion, by scattering:
    each surface pixel q of t + 1 (finite motion) lands at ``P = q + m(q)`` and splats
    ``-m(q)`` to the 2x2 pixels around P with bilinear weights; a pixel averages the
    candidates whose depth (in t + 1) is within ``depth_tolerance`` (relative) of its
    nearest one; a pixel nobody lands on is a hole (``NO_MOTION``). Returns
    (motion, holes)."""
    m = np.asarray(next_motion, dtype=F64)
    z = np.asarray(next_depth, dtype=F64)
    height, width = z.shape
    candidates: dict[tuple[int, int], list[tuple[float, float, np.ndarray]]] = {}
    for qy in range(height):
        for qx in range(width):
            if z[qy, qx] <= 0.0 or not np.all(np.isfinite(m[:, qy, qx])):
                continue
            px, py = qx + m[0, qy, qx], qy + m[1, qy, qx]
            x0, y0 = math.floor(px), math.floor(py)
            fx, fy = px - x0, py - y0
            for tx, ty, w in ((x0, y0, (1 - fx) * (1 - fy)), (x0 + 1, y0, fx * (1 - fy)),
                              (x0, y0 + 1, (1 - fx) * fy), (x0 + 1, y0 + 1, fx * fy)):
                if w > 0.0 and 0 <= tx < width and 0 <= ty < height:
                    candidates.setdefault((ty, tx), []).append((z[qy, qx], w, -m[:, qy, qx]))
    out = np.full((2, height, width), NO_MOTION)
    for (ty, tx), found in candidates.items():
        nearest = min(depth for depth, _, _ in found)
        kept = [(w, v) for depth, w, v in found if depth <= nearest * (1.0 + depth_tolerance)]
        total = sum(w for w, _ in kept)
        out[:, ty, tx] = sum(w * v for w, v in kept) / total
    return out, height * width - len(candidates)


class _Capturing(ReferenceDenoiser):
    """A pass of a bidirectional run: keeps the state of the frame before its blend."""

    def __init__(self, params: SVGFParams) -> None:
        super().__init__(params)
        self.state: FrameState | None = None

    def before_blend(self, state: FrameState) -> None:
        self.state = state

    def pass_history(self, clean: CleanFrame, geom: Geometry, accumulation: np.ndarray,
                     moments: np.ndarray, length: np.ndarray, radiance_mode: np.ndarray,
                     colour_history: np.ndarray) -> np.ndarray:
        """``H = w F + (1 - w) U``: ``U`` the colour entering the a-trous (the accumulation,
        or with ``spatial_variance_blur_color`` its blurred colour), ``F`` the first
        a-trous iteration's output, ``w = STATIC_FILTERED_SHARE`` where the pixel's motion
        is below ``STATIC_MOTION`` on both axes, else 0."""
        p = self.params
        variance, unfiltered = estimate_variance(accumulation, moments, length, radiance_mode,
                                                 geom, p)
        if iteration_count(p.atrous_iterations, *geom.depth.shape) < 1:
            return unfiltered
        guides = luminance_stop_guides(unfiltered, variance, geom.depth,
                                       atrous_sigmas(p, clean, geom), clean.weights,
                                       guide_blur_modes(p, radiance_mode))
        filtered, _ = atrous_iteration(unfiltered, variance, guides[0], radiance_mode,
                                       guides[1], geom.depth, geom.ddx, geom.ddy,
                                       geom.unit_normal, 1, p.sigma_depth, p.sigma_normal,
                                       symmetric_stops(p, clean))
        motion = np.asarray(clean.motion, dtype=F64)
        still = (np.abs(motion[0]) < STATIC_MOTION) & (np.abs(motion[1]) < STATIC_MOTION)
        share = np.where(still, STATIC_FILTERED_SHARE, 0.0)
        return unfiltered + share * (filtered - unfiltered)


def reference_bidirectional(frames: Sequence[Frame], params: SVGFParams
                            ) -> list[ReferenceOutput]:
    """Both passes of a bidirectional run, in float64: the forward pass is the causal
    reference keeping its unfiltered accumulation as history (``feedback_iteration`` -1);
    the reverse pass runs the same over the frames last to first with each frame's motion
    to the next frame (``frame.motion_next``, else :func:`invert_motion` of the later
    frame's), without gradient samples; at every frame the two resampled histories go
    through the consistency test (:func:`consistent_lengths`) and are combined with the
    frame (:func:`combine_histories`), filtered spatially and composed. Returns the outputs
    in frame order."""
    # Each pass keeps its accumulation unfiltered as its history (feedback_iteration -1).
    # Their anti-lag tests at a share of the causal significance (the other side refills).
    # The history gain runs in causal runs only.
    passes = params.replace(feedback_iteration=-1, antilag_gain=False,
                            antilag_sigma=params.antilag_sigma * PASS_ANTILAG_SIGMA_SCALE)
    forward = _Capturing(passes)
    kept = []
    kept_albedo = []  # temporal_albedo: the forward pass's colour means and lengths
    for frame in frames:
        forward.process(frame)
        assert forward.state is not None
        kept.append(forward.state.history)
        if params.temporal_albedo:
            assert forward.albedo_mean is not None and forward.albedo_length is not None
            kept_albedo.append((forward.albedo_mean.copy(), forward.albedo_length.copy()))
    reverse = _Capturing(passes)
    outputs: list[ReferenceOutput] = []
    later: Frame | None = None
    for frame, forward_history in zip(reversed(frames), reversed(kept), strict=True):
        if frame.motion_next is not None:
            motion = np.asarray(frame.motion_next, dtype=F64)
        elif later is not None:
            motion, _ = invert_motion(clean_motion(later.motion), clean_depth(later.depth))
        else:
            motion = np.full((2, *frame.depth.shape), NO_MOTION)
        reversed_frame = Frame(
            signals=[Signal(s.name, s.radiance, s.albedo, glossy=s.glossy,
                            guide_albedo=s.guide_albedo, mixed=s.mixed)
                     for s in frame.signals],
            normal=frame.normal, depth=frame.depth,
            motion=np.ascontiguousarray(motion, dtype=np.float32), mesh_id=frame.mesh_id,
            albedo=frame.albedo, emission=frame.emission,
            luminance_weights=frame.luminance_weights)
        own = reverse.process(reversed_frame)
        state = reverse.state
        assert state is not None
        forward_length, reverse_length = consistent_lengths(
            state.illumination, forward_history, state.history, state.geom.depth,
            params.alpha, CONSISTENCY_SIGMA, state.clean.weights, params.history_cap)
        colour, moments, length = combine_histories(
            state.illumination,
            dataclasses.replace(forward_history, history_length=forward_length),
            dataclasses.replace(state.history, history_length=reverse_length),
            state.geom.depth, params.alpha, params.moments_alpha, state.clean.weights,
            [GLOSSY_REFERENCE_COUNT if s.glossy else
             effective_count(params.history_cap, params.moments_alpha) for s in frame.signals])
        filtered, variance, _ = reverse.filter_spatially(
            state.clean, state.geom, colour, moments, length, state.radiance_mode)
        if params.temporal_albedo:
            # Remodulated by both passes' colour means, weighted by their sample counts.
            assert reverse.albedo_mean is not None and reverse.albedo_length is not None
            forward_mean, forward_length_albedo = kept_albedo[len(frames) - 1 - len(outputs)]
            state.clean.albedo = np.stack([
                reverse.albedo_mean[index] if state.clean.glossy[index] else
                combine_albedo(forward_mean[index], forward_length_albedo[index],
                               reverse.albedo_mean[index], reverse.albedo_length[index],
                               reverse.albedo_mean[index], params.alpha,
                               demodulation_floor(params, state.clean, index))
                for index in range(len(frame.signals))])
        outputs.append(reverse.compose(state.clean, state.geom, filtered, variance, length,
                                       state.radiance_mode, dict(own.counts)))
        later = frame
    return outputs[::-1]


# --------------------------------------------------------------------------- temporal albedo
def accumulate_albedo(albedo: np.ndarray, history: np.ndarray, history_length: np.ndarray,
                      motion: np.ndarray, depth: np.ndarray, mesh_id: np.ndarray,
                      prev_depth: np.ndarray, prev_mesh_id: np.ndarray, alpha: float,
                      cap: float, black: float,
                      catmull_rom: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``filters.albedo_history.accumulate_albedo`` of one signal: the running mean of its
    (cleaned) demodulation colour, over colours that are reflectances only (``demodulated``:
    ``effective_albedo``; a pixel whose colour is not one keeps it, ``h = 1``). The
    bilinear taps at ``(x + mx, y + my)`` that are in the image, not background, of the same
    mesh id and whose mean is a reflectance, renormalised (rejected below 0.01); the
    resampled mean clamped per channel to the current 3x3 range of foreground reflectances;
    ``h = min(cap, h_prev + 1)``, ``a = lerp(a_hist, a, max(alpha, 1/h))`` (equation 6);
    without history the mean of the 3x3 reflectances of the same mesh id weighted by a
    Gaussian of sigma 0.5 px, ``exp(-d^2 / (2 0.5^2))`` at distance ``d``, with ``h = 1``;
    either kept only where it is a reflectance (else the current colour with ``h = 1``).
    Returns ``(colour (3, H, W), length (H, W))``; in the background the current colour with
    length 0. ``catmull_rom``: where the position is not a whole pixel and every tap with a
    Catmull-Rom weight passes the taps' tests, the resampled mean is
    :func:`catmull_rom_fetch` of each channel (the length stays bilinear)."""
    a = clean_albedo(albedo)
    hist = np.asarray(history, dtype=F64)
    h_prev = np.asarray(history_length, dtype=F64)
    z = np.asarray(depth, dtype=F64)
    height, width = z.shape
    out = a.copy()
    length = np.where(z > 0.0, 1.0, 0.0)
    reflectance = ~effective_albedo(a, black)[0]
    hist_reflectance = ~effective_albedo(hist, black)[0]
    for y in range(height):
        for x in range(width):
            if z[y, x] <= 0.0 or not reflectance[y, x]:
                continue
            px, py = x + float(motion[0, y, x]), y + float(motion[1, y, x])
            if not (abs(px) < 1e7 and abs(py) < 1e7):
                px = py = -2.0  # no tap in the image
            x0, y0 = math.floor(px), math.floor(py)
            fx, fy = px - x0, py - y0
            total, colour, h = 0.0, np.zeros(3), 0.0

            def usable_tap(tx: int, ty: int, x: int = x, y: int = y) -> bool:
                return (0 <= tx < width and 0 <= ty < height and prev_depth[ty, tx] > 0.0
                        and prev_mesh_id[ty, tx] == mesh_id[y, x]
                        and bool(hist_reflectance[ty, tx]))

            for ty, wy in ((y0, 1.0 - fy), (y0 + 1, fy)):
                for tx, wx in ((x0, 1.0 - fx), (x0 + 1, fx)):
                    if not usable_tap(tx, ty):
                        continue
                    total += wx * wy
                    colour += wx * wy * hist[:, ty, tx]
                    h += wx * wy * h_prev[ty, tx]
            y_lo, y_hi = max(y - 1, 0), min(y + 2, height)
            x_lo, x_hi = max(x - 1, 0), min(x + 2, width)
            if total < 0.01 or h / total <= 0.0:
                n, weights, mean = 1.0, 0.0, np.zeros(3)
                for yy in range(y_lo, y_hi):
                    for xx in range(x_lo, x_hi):
                        if (z[yy, xx] > 0.0 and mesh_id[yy, xx] == mesh_id[y, x]
                                and reflectance[yy, xx]):
                            w = math.exp(-((yy - y) ** 2 + (xx - x) ** 2) / (2 * 0.5 ** 2))
                            weights += w
                            mean += w * a[:, yy, xx]
                mean /= weights
            else:
                usable = (z > 0.0) & reflectance
                window = a[:, y_lo:y_hi, x_lo:x_hi][:, usable[y_lo:y_hi, x_lo:x_hi]]
                resampled = colour / total
                support = [(x0 - 1 + i, y0 - 1 + j) for j in range(4) for i in range(4)
                           if (fx > 0 or i == 1) and (fy > 0 or j == 1)]
                if catmull_rom and (fx > 0 or fy > 0) and all(usable_tap(tx, ty)
                                                              for tx, ty in support):
                    resampled = np.array([catmull_rom_fetch(hist[c], px, py)
                                          for c in range(3)])
                mean = np.clip(resampled, window.min(axis=1), window.max(axis=1))
                n = min(cap, h / total + 1.0)
                mean = mean + max(alpha, 1.0 / n) * (a[:, y, x] - mean)
            if effective_albedo(mean[:, None, None], black)[0][0, 0]:
                continue  # not a reflectance
            out[:, y, x] = mean
            length[y, x] = n
    return out, length


def combine_albedo(forward: np.ndarray, forward_length: np.ndarray, reverse: np.ndarray,
                   reverse_length: np.ndarray, albedo: np.ndarray, alpha: float,
                   black: float) -> np.ndarray:
    """``filters.albedo_history.combine_albedo``: both passes' colour means weighted by
    their effective sample counts ``n(h)`` (:func:`effective_count`),
    ``(n_f a_f + n_r a_r) / (n_f + n_r)``; the reverse mean where either count is 0 or the
    combination is in another mode than this frame's colour."""
    out = np.asarray(reverse, dtype=F64).copy()
    mode_now = effective_albedo(clean_albedo(albedo), black)[0]
    height, width = albedo.shape[1:]
    for y in range(height):
        for x in range(width):
            n_f = effective_count(float(forward_length[y, x]), alpha)
            n_r = effective_count(float(reverse_length[y, x]), alpha)
            if n_f <= 0.0 or n_r <= 0.0:
                continue
            mean = (n_f * forward[:, y, x] + n_r * reverse[:, y, x]) / (n_f + n_r)
            if effective_albedo(mean[:, None, None], black)[0][0, 0] == mode_now[y, x]:
                out[:, y, x] = mean
    return out
