"""Lone reflected lights in a G-buffer albedo that guides demodulation by itself.

Cycles' ``Denoising Albedo`` follows glass and mirror bounces, and where such a path reached
a light it holds that light's emission (95 on the production render's glass sphere, among
neighbours at 0.14). A signal demodulated by this albedo alone (the light groups,
``filters.composable.group_frame``) is filtered there as radiance, alone in its mode, so
neither the firefly spreading nor the a-trous nor the despike reach the pixel: the one
sample of the light seen through the glass (97.75) stays whole in its filtered group, which
then takes the split of the colour from the other groups around it (dark crosses in them).

The colour's glossy signals make the call per pixel (``modulate.emitter_colour``): a lit
pixel with fewer than ``LIT_NEIGHBOURS_ROUGH`` lit neighbours is a sample of a blurry
reflection, filtered demodulated like the surface around it; lit pixels side by side are a
light's image and stay radiance. Here the same call (:func:`lone_lights`) gives a lone lit
pixel its unlit surface neighbours' mean albedo (:func:`neighbours_albedo`): its light is
then a firefly the filter spreads as it spreads the colour's.

The groups' filter keeps that firefly's energy, where the colour's drops most of it (its
glossy history clamp): around a lone light the filtered group can hold several times the
colour. There :func:`bound_by_total` holds every filtered group to at most the colour, which
they are shares of; elsewhere the two filters' levels differ smoothly and the plain ratio
split is the better one (bounded everywhere, the 640x360 ``dof`` shot's ``Combined_env``
relMSE rose 16 %: docs/cycles.md#light-groups-and-light-passes-come-out-denoised). On the
lone light itself the colour keeps more of the sample than the group's filter (which spread
it): :func:`give_to_their_groups` gives that rest to the group the sample lit.
"""

from __future__ import annotations

import numpy as np

from svgf_cli.filters.context import MAX_REFLECTANCE
from svgf_cli.filters.modulate import LIT_NEIGHBOURS_ROUGH, reflected_lights

F32 = np.float32
_OFFSETS = tuple((dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if dy or dx)
# The reach (pixels) of a lone light's firefly in the groups' filter: its spreading window
# (radius 4, ``filters.fireflies.RADIUS``) and the three a-trous steps after it (1 + 2 + 4)
# take it about 11 pixels away. A lone light weighs on the pixels around it by a tent
# reaching 2 x LONE_LIGHT_RADIUS pixels (two box sums), doubled and capped at 1: the bound
# holds fully within about half that reach and fades to nothing at its end (a hard square
# left a visible step at its edge in a 1080p frame's Combined_env).
LONE_LIGHT_RADIUS = 6
LONE_LIGHT_GAIN = 2.0

Pixels = tuple[np.ndarray, np.ndarray]  # rows, columns


def lone_lights(albedo: np.ndarray, depth: np.ndarray) -> Pixels:
    """The surface pixels (``depth > 0``) whose ``albedo`` ((3, H, W)) is no reflectance
    (a finite channel above ``MAX_REFLECTANCE``: lit) with fewer than
    ``LIT_NEIGHBOURS_ROUGH`` lit pixels among their 8 neighbours, as (rows, columns)."""
    height, width = depth.shape
    lit = np.empty((height + 2, width + 2), dtype=np.uint8)
    if not reflected_lights(albedo, F32(MAX_REFLECTANCE), lit):
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    ys, xs = np.nonzero(lit[1:-1, 1:-1])
    around = sum(lit[ys + 1 + dy, xs + 1 + dx].astype(np.intp) for dy, dx in _OFFSETS)
    lone = (around < LIT_NEIGHBOURS_ROUGH) & (depth[ys, xs] > 0.0)
    return ys[lone], xs[lone]


def neighbours_albedo(albedo: np.ndarray, depth: np.ndarray, pixels: Pixels) -> np.ndarray:
    """``albedo`` ((3, H, W) float32) where each of ``pixels`` takes the mean albedo of its 8
    neighbours that are surface pixels with a finite albedo that is a reflectance (none
    above ``MAX_REFLECTANCE``); left as it is where there are none. ``albedo`` itself when
    no pixel changes, else a new array."""
    ys, xs = pixels
    if not ys.size:
        return albedo
    height, width = depth.shape
    total = np.zeros((3, ys.size))
    count = np.zeros(ys.size)
    for dy, dx in _OFFSETS:
        y, x = ys + dy, xs + dx
        inside = (y >= 0) & (y < height) & (x >= 0) & (x < width)
        y, x = np.clip(y, 0, height - 1), np.clip(x, 0, width - 1)
        colour = albedo[:, y, x].astype(np.float64)
        finite = np.isfinite(colour).all(axis=0)
        usable = (inside & (depth[y, x] > 0.0) & finite
                  & (np.where(finite, colour, 0.0).max(axis=0) <= MAX_REFLECTANCE))
        total += np.where(usable, colour, 0.0)
        count += usable
    found = count > 0
    if not found.any():
        return albedo
    repaired = albedo.copy()
    repaired[:, ys[found], xs[found]] = (total[:, found] / count[found]).astype(F32)
    return repaired


def _box_sums(plane: np.ndarray, radius: int, axis: int) -> np.ndarray:
    """Sums of ``plane`` over windows of 2 ``radius`` + 1 along ``axis`` (zeros beyond).
    Not ``filters.shares.box_mean``: that one divides by the pixels a window covers, which
    would raise a tent where it meets the border."""
    padded = np.pad(plane, [(radius + 1, radius) if a == axis else (0, 0) for a in (0, 1)])
    running = np.cumsum(padded, axis=axis)
    size = plane.shape[axis]

    def along(start: int) -> tuple[slice, ...]:
        window = slice(start, start + size)
        return (window, slice(None)) if axis == 0 else (slice(None), window)

    return running[along(2 * radius + 1)] - running[along(0)]


def lone_light_weights(shape: tuple[int, int], pixels: Pixels
                       ) -> tuple[tuple[slice, slice], np.ndarray] | None:
    """``min(1, LONE_LIGHT_GAIN x sum over the pixels p of t(y - p_y) t(x - p_x))`` with
    the tent ``t(d) = max(0, 2 r + 1 - |d|) / (2 r + 1)`` (``r = LONE_LIGHT_RADIUS``), on
    the box of the image the tents reach (its slices, float32 weights); None without
    pixels."""
    ys, xs = pixels
    if not ys.size:
        return None
    reach = 2 * LONE_LIGHT_RADIUS
    height, width = shape
    # The box the tents reach, beyond the image too: the first box sums there feed the
    # second's inside it.
    top, left = int(ys.min()) - reach, int(xs.min()) - reach
    # Whole counts, exact in float32 (sums far below 2^24).
    counts = np.zeros((int(ys.max()) + reach + 1 - top, int(xs.max()) + reach + 1 - left), F32)
    np.add.at(counts, (ys - top, xs - left), F32(1.0))
    for axis in (0, 1):  # a tent is a box of a box
        for _ in range(2):
            counts = _box_sums(counts, LONE_LIGHT_RADIUS, axis)
    side = (2 * LONE_LIGHT_RADIUS + 1) ** 2  # a lone pixel's tent peaks at this
    rows = slice(max(top, 0), min(top + counts.shape[0], height))
    columns = slice(max(left, 0), min(left + counts.shape[1], width))
    inside = counts[rows.start - top:rows.stop - top, columns.start - left:columns.stop - left]
    return (rows, columns), np.minimum(inside * F32(LONE_LIGHT_GAIN / side), F32(1.0))


def bound_by_total(parts: np.ndarray, total: np.ndarray, pixels: Pixels) -> None:
    """In place on ``parts`` ((K, 3, H, W) filtered shares of ``total``, (3, H, W)): near
    the lone lights ``pixels``, ``p - w (p - min(p, max(total, 0)))`` with ``w`` their
    :func:`lone_light_weights`: no part above the total it is a share of."""
    found = lone_light_weights(total.shape[1:], pixels)
    if found is None:
        return
    (rows, columns), weights = found
    cap = np.maximum(total[:, rows, columns], F32(0.0))
    excess = np.empty_like(cap)
    for part in parts:  # one group at a time: one temporary, float32
        near = part[:, rows, columns]
        np.subtract(near, cap, out=excess)
        np.maximum(excess, F32(0.0), out=excess)
        excess *= weights
        near -= excess




def give_to_their_groups(parts: np.ndarray, total: np.ndarray, inputs: list[np.ndarray],
                         pixels: Pixels) -> None:
    """In place on ``parts`` ((K, 3, H, W) filtered shares of ``total``): on each lone light
    of ``pixels``, the part whose input (``inputs``, K (3, H, W) planes) holds the most light
    there (the light's own group; the first of equals) at least ``max(total, 0)`` less the
    other parts: what the colour kept of the sample is that group's, not a share of all of
    them (the other groups there kept their level, not a bright speck each).

    On the lone light alone: giving its 8 neighbours too (the pixel filter's reach) took the
    last faint specks out of a 1080p frame's ``Combined_env`` but raised the 128x72 ``dof``
    shot's ``Combined_fill`` relMSE 7 % (its reflected lights are dense: 20 a frame)."""
    ys, xs = pixels
    if not ys.size:
        return
    owner = np.argmax([inp[:, ys, xs].sum(axis=0) for inp in inputs], axis=0)
    for c in range(3):
        values = parts[:, c, ys, xs]  # (K, n)
        own = values[owner, np.arange(ys.size)]
        rest = np.maximum(total[c, ys, xs], F32(0.0)) - (values.sum(axis=0) - own)
        parts[owner, c, ys, xs] = np.maximum(own, rest)
