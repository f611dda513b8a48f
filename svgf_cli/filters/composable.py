"""Composable light layers: every light pass and light group of a frame denoised, adding up
to the denoised colour by construction (docs/output.md#light-layers).

Two decompositions of one colour (the light passes, the light groups) must not give two
colours, so neither is filtered into a colour of its own: the colour is the Denoiser's (its
signals filtered as always, bit-identical), and each decomposition is that colour split per
pixel and channel by shares, the same weights for every layer of the set (as Arnold's noice
applies one set of weights to every AOV):

* **light groups**: each group is filtered as a signal of a second Denoiser (its own
  history, variance and anti-lag: a group switching on is a lighting change of that group
  alone), and the filtered groups ``f_k``, with the colour's pixel filter applied as the
  colour's filter applies it (:func:`spill_groups`), give the shares:
  ``g_k = C * f_k / sum_j f_j``.
* **light passes**: each pass belongs to the filtered signal built from it (Cycles' ``DiffDir``
  to ``diffuse_direct``...); a signal holding several passes (``specular``: glossy and
  transmission, direct and indirect) is split by the passes' stored light averaged over the
  pixels that have its colour pass (a 9x9 tent), times the pixel's own colour pass; the passes are
  then scaled together so that they add up to ``C - emission`` (the pixel filter and despike
  stages act on the colour after the signals are summed), and a pass stored divided by its
  colour is divided back. Where that colour is 0, next to a pixel where it is not, such a
  pass is its neighbours' light over their colour (a converged render's pixel filter reaches
  one pixel past the 1-spp colour's edge; it adds nothing there). On medium pixels it
  carries light only next to a sample that reached the surface (:func:`colour_cover`). A
  colour pass written anew takes the colour's noisy outline exchanges where the G-buffer is
  noise (:func:`spilled_colours`), as the signals it divides do.

Where the shares' denominator is (near) 0 while the colour is not, the input layers'
averaged shares are used (box-filtered for the groups, over the tent for a signal's
passes), and where those are 0 too, each layer's light over the frame
(a layer black in the frame gets none). Light the colour's filters spilled onto a pixel
without a colour pass beside one (a wire's glint onto the sky) is carried by a sliver of that
colour pass (:func:`lend_slivers`); the light no light pass has goes to the emission passes.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from svgf_cli.filters.edge_filter import OutlineSpill
from svgf_cli.filters.engine import PipelineFilter
from svgf_cli.filters.halfres import halve_frame, upsample
from svgf_cli.filters.lone_lights import (
    Pixels,
    bound_by_total,
    give_to_their_groups,
    lone_lights,
    neighbours_albedo,
)
from svgf_cli.filters.medium import MEDIUM_DEPTH
from svgf_cli.filters.params import SVGFParams, params_for_samples
from svgf_cli.filters.pass_shares import PassShares
from svgf_cli.filters.pixel_filter import pixel_filter, pixel_filter_weight
from svgf_cli.filters.shares import (
    any_nonzero,
    box_mean,
    claim_share,
    coloured,
    covered_average,
    covered_pixel_filter_kernel,
    covered_spread,
    divide_where_coloured,
    fill_from_neighbours,
    find_slivers,
    lend_sliver,
    sliver_claims,
    split_plain_rows,
    split_shares,
    subtract_product,
    touching,
)
from svgf_cli.frame import DenoisedFrame, Frame, LightLayer, LightLayers, Signal

F32 = np.float32
# Box radius of the fallback shares (pixels): 7x7. Measured on testdata/cycles/production
# (bench/light_layers.py), when it also averaged the passes splitting a signal: radius 2 left
# GlossInd's temporal error above the input's (0.063 against 0.057), radius 4 GlossDir's
# relMSE at 0.30x the input's; radius 3: 0.28x and 0.0565.
SHARE_RADIUS = 3
# The passes splitting one filtered signal are averaged over a tent, two box means of this
# radius (a 9x9 window, weights (5 - |dy|) (5 - |dx|)): a 7x7 box left a lone bright sample's
# share as a flat square (cycles/dof's GlossInd: blocks). Tent radius 2 against that box,
# relMSE / temporal error (bench/light_layers.py): dof GlossInd 0.168 -> 0.156 / 0.068 ->
# 0.062, GlossDir 0.361 -> 0.349; production GlossDir 0.204 -> 0.192, GlossInd temporal
# 0.045 -> 0.040; radius 3 (13x13) blurred GlossDir (dof 0.440, production 0.208).
SHARE_TENT_RADIUS = 2
# How many samples the tent's weights are worth (1 / sum of the squared weights): 54.
_TENT = 2 * SHARE_TENT_RADIUS + 1 - np.abs(np.arange(-2 * SHARE_TENT_RADIUS,
                                                     2 * SHARE_TENT_RADIUS + 1))
SHARE_TENT_SAMPLES = float(_TENT.sum() ** 4 / (_TENT ** 2).sum() ** 2)
# A share's denominator at or below this (absolute, per channel) is "no light": fallback.
SHARE_FLOOR = 1e-8
# A pixel whose colour pass comes from the noisy outlines' exchanges alone and is below this
# share of the colour around it (5x5, its pixels that had it before) is left without: a
# pass there would be its light over a sliver of colour (cycles/smoke: a `DiffDir` pixel
# 35 760 times the reference's; bench/light_layers.py: 0.1 and 0.25 both remove those,
# 0.25 also takes dof's `DiffDir` 0.352x -> 0.314x its input's relMSE, `Env` +3 %; 0.5 and
# 1 raise `DiffCol` and `Env` by 6-11 % and 35-115 %).
SLIVER_FRACTION = 0.25
# How far a pass's averaged stored light from last frame may lie from this frame's: this
# many standard errors of this frame's average (filters.pass_shares; bench/light_layers.py
# on cycles/production, smoke and dof: 0.5 leaves more flicker, 2 lets a reflection's old
# place linger on dof's rolling metal ball, GlossDir relMSE +8 % against +2 % at 1).
SHARE_HISTORY_REACH = 1.0
# A sliver of colour (lend_slivers) is at most this share of the colour of the neighbours it
# is filled from: a pixel whose centre sample missed a surface is at most about half on it.
SLIVER_CAP = 0.5


def box_filter(planes: np.ndarray, radius: int = SHARE_RADIUS,
               out: np.ndarray | None = None) -> np.ndarray:
    """The (C, H, W) planes' mean over a (2 radius + 1)^2 window, clipped at the borders
    (``filters.shares.box_mean``), into ``out`` when given (float32, C-contiguous)."""
    out = np.empty(planes.shape, dtype=F32) if out is None else out
    box_mean(np.ascontiguousarray(planes, dtype=F32), int(radius), out)
    return out


def tent_filter(planes: np.ndarray, radius: int = SHARE_TENT_RADIUS,
                out: np.ndarray | None = None) -> np.ndarray:
    """The (C, H, W) planes' :func:`box_filter` of ``radius`` twice: their tent mean, into
    ``out`` when given (float32, C-contiguous; the second box runs in place)."""
    out = box_filter(planes, radius, out)
    box_mean(out, int(radius), out)
    return out


def each_filtered(planes: list[np.ndarray],
                  filter_: Callable[..., np.ndarray] = tent_filter) -> np.ndarray:
    """The K (3, H, W) planes each through ``filter_`` (:func:`box_filter` or
    :func:`tent_filter`, its own radius), written straight into one (K, 3, H, W) array: no
    stack of K filtered copies (:func:`split_by_shares` takes one array as it is)."""
    out = np.empty((len(planes), *planes[0].shape), dtype=F32)
    for plane, filtered in zip(planes, out, strict=True):
        filter_(plane, out=filtered)
    return out


Planes = np.ndarray | list[np.ndarray]  # K (3, H, W) planes: a list, or one (K, 3, H, W) array
Fallback = Planes | Callable[[], Planes] | None
Last = np.ndarray | Callable[[], np.ndarray] | None  # (K, 3) weights for the whole image


def _joined(planes: list[np.ndarray]) -> np.ndarray:
    """Equal planes as one array along a new first axis: a view of them where they lie one
    after the other in memory, else their stack (a copy)."""
    first = planes[0]
    if all(p.flags.c_contiguous and p.dtype == first.dtype and p.shape == first.shape
           and p.ctypes.data == first.ctypes.data + k * first.nbytes
           for k, p in enumerate(planes)):
        return np.lib.stride_tricks.as_strided(first, (len(planes), *first.shape),
                                               (first.nbytes, *first.strides))
    return np.stack(planes)


def _stacked(planes: Planes) -> np.ndarray:
    """``planes`` as one (K, 3, H, W) float32 C-contiguous array: itself when it is one, a
    view when the planes lie one after the other in memory (the light passes as read:
    ``io.lightlayers.pass_layers``), else their stack (a copy)."""
    return np.ascontiguousarray(planes if isinstance(planes, np.ndarray) else _joined(planes),
                                dtype=F32)


def split_by_shares(total: np.ndarray, weights: Planes, fallback: Fallback = None,
                    out: np.ndarray | None = None, last: Last = None,
                    excluded: dict[int, np.ndarray] | None = None) -> np.ndarray:
    """``total`` split per pixel and channel in proportion to the K ``weights`` (negative
    weights count as 0): the (K, 3, H, W) parts, adding up to ``total`` (to float32
    rounding). Where the weights sum to at most SHARE_FLOOR, ``fallback``'s proportions
    (the planes, or a function making them; part k's counted as 0 on the (H, W) pixels
    ``excluded[k]``), and where those too, ``last``'s: one weight per part and channel for
    the whole image ((K, 3), or a function making it: e.g. each part's light over the frame,
    :func:`frame_totals`; None: equal parts); where those are 0 too, no parts (the caller
    gives that total to someone else; ``filters.shares.split_shares``). The fallback and
    ``last`` are made and stacked only when some value needs them (most frames: none).
    ``out`` (None: a new array) may be the stacked weights themselves: each value's weights
    are read before its parts are written."""
    weights = _stacked(weights)
    parts = np.empty_like(weights) if out is None else out
    if len(weights) == 1:
        np.copyto(parts[0], total)
        return parts
    total = np.ascontiguousarray(total, dtype=F32)
    pending = np.empty(total.shape[0] * total.shape[1], np.uint8)
    needed = split_plain_rows(total, weights, SHARE_FLOOR, parts, pending)
    jobs = np.flatnonzero(pending)
    if not len(jobs):
        return parts
    backup, rest, bits = weights, None, np.empty((0, 0), np.uint64)
    if needed:
        if fallback is not None:
            backup = _stacked(fallback() if callable(fallback) else fallback)
            if excluded:
                bits = _exclusion_bits(excluded, total.shape[1:])
        if last is not None:
            rest = np.asarray(last() if callable(last) else last, dtype=np.float64)
    if rest is None:
        rest = np.ones(weights.shape[:2])
    split_shares(total, weights, backup, backup is not weights, bits, rest, SHARE_FLOOR, parts,
                 jobs)
    return parts


def _exclusion_bits(excluded: dict[int, np.ndarray], shape: tuple[int, ...]) -> np.ndarray:
    """The (H, W) uint64 bit masks of ``filters.shares.split_shares``: bit k where part k
    is excluded (at most 64 parts)."""
    bits = np.zeros(shape, np.uint64)
    for k, pixels in excluded.items():
        if not 0 <= k < 64:
            raise ValueError(f"part {k} cannot be excluded: at most 64 parts")
        bits[pixels] |= np.uint64(1) << np.uint64(k)
    return bits


def frame_totals(planes: list[np.ndarray]) -> np.ndarray:
    """Each (3, H, W) plane's light summed over the image, (K, 3) float64, negative sums as
    0: the last resort of :func:`split_by_shares`, so a layer black in the whole frame is
    given none; a channel black in every plane gets equal weights (the total is not lost)."""
    totals = np.maximum([p.sum(axis=(1, 2)) for p in planes], 0.0).astype(np.float64)
    totals[:, totals.sum(axis=0) <= 0.0] = 1.0
    return totals


def compose_groups(colour: np.ndarray, filtered: np.ndarray, groups: list[LightLayer],
                   lone: Pixels | None = None) -> np.ndarray:
    """The denoised light groups, (K, 3, H, W), into ``filtered`` (the K filtered groups,
    stacked): ``colour`` split by their shares (the input groups' box-filtered shares where
    the filtered ones are 0); near the ``lone`` lights of the G-buffer albedo no filtered
    group counts for more than the colour, and on them what the colour kept is the lit
    group's (``filters.lone_lights``: ``bound_by_total``, ``give_to_their_groups``)."""
    radiance = [g.radiance for g in groups]
    if lone is not None:
        bound_by_total(filtered, colour, lone)
        give_to_their_groups(filtered, colour, radiance, lone)
    return split_by_shares(colour, filtered, lambda: each_filtered(radiance, box_filter),
                           out=filtered, last=lambda: frame_totals(radiance))


def spill_groups(filtered: np.ndarray, weight: float) -> None:
    """In place: the renderer's pixel filter (``filters.pixel_filter``, neighbour ``weight``;
    0: none) on each filtered group (K, 3, H, W), as the colour's filter applies it to the
    colour it splits. Without it the light the kernel spills from an object onto the pixels
    beside it (the sky behind a silhouette) would go to the groups that light those pixels
    (the world's) rather than to those that light the object."""
    if weight <= 0.0 or not len(filtered):
        return
    zero = np.zeros(filtered.shape[1:], dtype=F32)
    for group in filtered:  # contiguous (3, H, W) each: the kernel reads before it writes
        pixel_filter(group, zero, F32(weight), group)


# A pass's averaged stored light (in place) and how far its history may lie from it.
Blend = Callable[[int, np.ndarray, np.ndarray], None]


def compose_passes(light: np.ndarray, signal_outputs: dict[str, np.ndarray],
                   passes: list[LightLayer], barred: dict[int, np.ndarray] | None = None,
                   emitters: bool = False, blend: Blend | None = None,
                   written: list[np.ndarray | None] | None = None) -> np.ndarray:
    """The denoised light passes, (P, 3, H, W), in the colour's units (light x colour
    pass), adding up to ``light`` (the colour less the emission). ``barred`` maps a pass's
    index to the (H, W) pixels where it carries no light (its part there goes to the other
    passes, in proportion to theirs). Where no pass has light, filtered or read: none when
    the file has ``emitters`` (emission passes: they take that light), else by the passes'
    light over the frame; a signal's light where none of its passes' weights has any, by
    their light as read over the share tent, and where that is none too by their light over
    the frame. A pass black in the whole frame as read (Cycles' VolumeInd or TransDir, often)
    gets none: its weight is 0 and not box-filtered, and a signal with one pass lit is
    that pass's alone. ``blend(index, average)``: each pass's averaged stored light, before
    it is multiplied by its colour, blended with its history (``filters.pass_shares``).
    ``written``: each pass's colour pass as written, by which a pass of no filtered signal
    (``--signals combined``) is weighed instead of its colour as read."""
    estimates = np.empty((len(passes), *light.shape), dtype=F32)
    covered: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # by id of a colour pass
    members: dict[str, list[int]] = {}
    for index, layer in enumerate(passes):
        owner = layer.signal if layer.signal in signal_outputs else ""
        members.setdefault(owner, []).append(index)
    for owner, indexes in members.items():
        filtered = signal_outputs[owner] if owner else light
        # A pass black in the whole frame as read gets none of its signal.
        lit = [i for i in indexes if _lit(passes[i].radiance)]
        estimates[[i for i in indexes if i not in lit]] = 0.0
        if len(lit) <= 1:  # the signal is this pass's light alone
            if lit:
                estimates[lit[0]] = filtered
            continue
        own = [passes[i] for i in indexes]
        weights = np.empty((len(own), *light.shape), dtype=F32)
        spread = np.empty(light.shape, dtype=F32) if blend is not None else None
        for index, smooth, layer in zip(indexes, weights, own, strict=True):
            if index not in lit:
                smooth[...] = 0.0
                continue
            if layer.colour is None:
                tent_filter(layer.stored, out=smooth)
                continue
            # The stored light's mean over the window's pixels that have its colour (a pass
            # divided by its colour is 0 off it: a plain mean dims it along the colour's
            # edges, e.g. TransInd around the rim of a glass), times the pixel's colour.
            if id(layer.colour) not in covered:
                covered[id(layer.colour)] = _coverage(layer.colour)
            surface, coverage = covered[id(layer.colour)]
            stored = np.ascontiguousarray(layer.stored, dtype=F32)
            covered_average(stored, surface, coverage, SHARE_TENT_RADIUS, smooth)
            if blend is not None and spread is not None:
                covered_spread(stored, surface, coverage, smooth, SHARE_TENT_RADIUS,
                               SHARE_HISTORY_REACH, SHARE_TENT_SAMPLES, spread)
                blend(index, smooth, spread)
            # A pass of no filtered signal takes a share of the whole light, which took
            # the noisy outlines' exchanges: its colour as written, as it is divided by.
            colour = written[index] if not owner and written is not None else None
            smooth *= layer.colour if colour is None else colour
        # Passes listed side by side (a signal's always are): split straight into theirs.
        side_by_side = indexes == list(range(indexes[0], indexes[-1] + 1))
        # Where no pass's weight has light (its colour as read is 0 around a sample whose
        # colour came from the noisy outlines' mix), the passes' light as read nearby: one
        # pixel's 1-spp light, or the frame's totals, gave a defocused horizon's rare
        # GlossInd sample the whole signal (a speckled band on cycles/dof).
        parts = split_by_shares(
            filtered, weights, lambda own=own: each_filtered([p.radiance for p in own]),
            out=estimates[indexes[0]:indexes[-1] + 1] if side_by_side else weights,
            last=lambda own=own: frame_totals([p.radiance for p in own]))
        if not side_by_side:
            estimates[indexes] = parts
    barred = {k: pixels for k, pixels in (barred or {}).items() if pixels.any()}
    for index, pixels in barred.items():
        np.copyto(estimates[index], 0.0, where=pixels)
    last = (np.zeros((len(passes), 3)) if emitters
            else lambda: frame_totals([p.radiance for p in passes]))
    # The passes as read where no estimate has light, a barred pass's counted as 0 there (a
    # view of them as read: io.lightlayers.pass_layers reads them side by side).
    return split_by_shares(light, estimates, lambda: [p.radiance for p in passes],
                           out=estimates, last=last, excluded=barred)


def _coverage(colour: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where a colour pass (3, H, W) is not 0 in some channel, (H, W) float32 1/0, and that
    mask's tent mean (the passes' share window), (H, W)."""
    surface = _surface(colour).astype(F32)
    return surface, tent_filter(surface[None])[0]


def _surface(colour: np.ndarray) -> np.ndarray:
    """(H, W) bool: where a colour pass (3, H, W) is above 0 in some channel."""
    out = np.empty(colour.shape[1:], dtype=bool)
    coloured(np.ascontiguousarray(colour, dtype=F32), out)
    return out


def _lit(planes: np.ndarray) -> bool:
    """Whether a (3, H, W) layer has light somewhere (``any``, on both cores)."""
    return any_nonzero(np.ascontiguousarray(planes, dtype=F32))


def covered_pixel_filter(colour: np.ndarray, weight: float) -> None:
    """In place: the renderer's pixel filter (``filters.pixel_filter``, neighbour
    ``weight``; 0: none) on a colour pass (3, H, W) written anew, over its pixels above 0
    only (each divided by the kernel's weight on those): a converged render's colour pass
    is filtered as its colour is, so texture edges blend as the light does, while a pixel
    with no colour stays 0 (spread there, the passes would divide their light by a sliver
    of colour)."""
    if weight > 0.0:
        covered_pixel_filter_kernel(colour, float(weight))


def remodulated_colours(passes: list[LightLayer], albedos: dict[str, np.ndarray]
                        ) -> dict[tuple[str, str, str], np.ndarray]:
    """The colour passes as the filter remodulated by, per colour pass (its channels): the
    owning signal's colour (the temporal albedo's running mean when that stage runs), split
    among the signal's colour passes in proportion to their own values (``specular``:
    ``GlossCol`` and ``TransCol``). Passes of no signal keep their colour as read."""
    by_signal: dict[str, dict[tuple[str, str, str], np.ndarray]] = {}
    for layer in passes:
        if layer.colour is None or layer.colour_channels is None:
            continue
        if layer.signal in albedos:
            by_signal.setdefault(layer.signal, {})[layer.colour_channels] = layer.colour
    colours: dict[tuple[str, str, str], np.ndarray] = {}
    for signal, own in by_signal.items():
        total = np.sum(list(own.values()), axis=0, dtype=F32) if len(own) > 1 else None
        for key, colour in own.items():
            if key in colours:
                continue
            if total is None:  # a copy: medium_colours writes into it, the filter keeps its own
                colours[key] = albedos[signal].astype(F32, copy=True)
                continue
            share = np.divide(colour, total, out=np.zeros_like(colour), where=total > 0)
            colours[key] = (albedos[signal] * share).astype(F32, copy=False)
    return colours


def medium_colours(colours: dict[tuple[str, str, str], np.ndarray],
                   passes: list[LightLayer], medium: np.ndarray) -> None:
    """In place: on the medium pixels, each colour pass as read, box-filtered. The filter
    demodulated them by the colour of the surface behind the medium, but a renderer's
    converged colour pass there is that colour on the samples that reach the surface and 0
    on the others (Cycles), which the mean over the neighbours estimates."""
    read = {layer.colour_channels: layer.colour for layer in passes
            if layer.colour_channels is not None and layer.colour is not None}
    crop = (slice(None), *_medium_box(medium))
    inside = medium[crop[1:]]
    for key, colour in colours.items():
        if key in read:
            colour[crop][:, inside] = box_filter(read[key][crop])[:, inside]


def _medium_box(pixels: np.ndarray) -> tuple[slice, slice]:
    """The bounding box of the (H, W) ``pixels`` (some set) grown by the share window's
    radius: a box mean over it is the whole frame's on those pixels (their windows lie in
    it, or are clipped by the image's edge alike)."""
    rows, columns = np.nonzero(pixels)
    height, width = pixels.shape
    return (slice(max(rows.min() - SHARE_RADIUS, 0), min(rows.max() + SHARE_RADIUS + 1, height)),
            slice(max(columns.min() - SHARE_RADIUS, 0),
                  min(columns.max() + SHARE_RADIUS + 1, width)))


def stored_values(layer: LightLayer, radiance: np.ndarray,
                  colour: np.ndarray | None, cover: Cover | None = None) -> np.ndarray:
    """A denoised pass in its stored units, in place of ``radiance``: divided by its
    (written) colour pass where that is not 0 (elsewhere the pass adds nothing to the
    colour: its stored light as read). With its colour pass's ``cover``: on the pixels
    where that colour is 0 in every channel, next to a pixel where the pass carries light,
    those neighbours' light over their colour (:func:`filters.shares.fill_from_neighbours`),
    as a converged render's pixel filter spreads a pass divided by its colour one pixel past
    the 1-spp colour's edge; it still adds nothing there."""
    if colour is not None:
        divide_where_coloured(radiance, colour, layer.stored)
        if cover is not None:
            fill_from_neighbours(radiance, colour, cover.source, cover.vacant)
    return radiance


@dataclasses.dataclass
class Cover:
    """Where a colour pass (as written) lets its light passes carry light, (H, W) bool each:
    ``surface``, its colour not 0 in some channel; ``barred``, the medium pixels where they
    carry none (its colour 0 there, or no pixel among the 4 neighbours that is no medium pixel
    and has the colour: a sample that reached the surface); ``source``, surface and not
    barred; ``vacant``, not surface."""

    surface: np.ndarray
    barred: np.ndarray | None
    source: np.ndarray
    vacant: np.ndarray = dataclasses.field(init=False)

    def __post_init__(self) -> None:
        self.vacant = ~self.surface


def spilled_colours(colours: dict[tuple[str, str, str], np.ndarray],
                    covers: dict[int, Cover], spill: OutlineSpill) -> None:
    """In place: the noisy outlines' exchanges (``spill``, as made on the colour) on each
    colour pass written anew, whose :class:`Cover` (by id, computed before) then counts as
    vacant only the pixels still 0. Where the 1-spp G-buffer is noise (a defocused
    region: each sample one surface or another) a converged render's colour pass is the
    mix of the surfaces in the pixel's footprint, as its colour is; the exchanges give the
    colour that mix, so a light pass there is divided by the mix rather than by whichever
    surface the sample saw (dof: `DiffCol` relMSE 0.55x -> 0.14x the input's). The cover's
    other pixels stay the centre-sampled colour's: a pass is filled one pixel past that
    colour's edge (:func:`stored_values`), not past the mix's, which reaches surfaces with
    no such colour (a metal's interior)."""
    for colour in colours.values():
        cover = covers[id(colour)]  # its surface: the colour before the exchanges
        spill.apply(colour, colour)
        slivers = np.empty_like(cover.surface)
        find_slivers(colour, cover.surface, SLIVER_FRACTION, SHARE_TENT_RADIUS, slivers)
        colour[:, slivers] = 0.0
        cover.vacant = ~_surface(colour)


def lend_slivers(residual: np.ndarray, parts: np.ndarray, written: list[np.ndarray | None],
                 covers: dict[int, Cover], medium: np.ndarray | None) -> dict[int, np.ndarray]:
    """The light the colour took from a neighbour across its edge (a thin wire's glint that
    the pixel and edge filters spread onto the sky beside it), given back to the light
    passes: by id of each colour pass as written, that colour with a sliver of itself on
    its vacant pixels next to its light (not a medium's) where light is left that no pass
    carries (``residual``, (3, H, W), above 0 in every channel; in place, less what the
    slivers carry); only the colours that got one. ``parts``: each pass's stored values
    (P, 3, H, W), ``written`` its colour pass.

    A converged render's colour pass there is the surface's colour times its share of the
    pixel, and its light passes the surface's light over its colour, as
    :func:`stored_values` fills them from the 4 neighbours. So the light left is shared
    among the colours in proportion to their passes' light on those neighbours, and each
    sliver is the neighbours' colour times that share, one factor in every channel (its
    hue kept: :func:`filters.shares.claim_share`), at most ``SLIVER_CAP`` of their mean:
    the passes there carry light at the neighbours' ratio, never light over a sliver.
    Without it that light went to the emission passes (production at 640x360: `Env` 1.16x
    its input's relMSE)."""
    members: dict[int, list[int]] = {}
    colours: dict[int, np.ndarray] = {}
    for index, colour in enumerate(written):
        if colour is not None:
            members.setdefault(id(colour), []).append(index)
            colours[id(colour)] = np.ascontiguousarray(colour, dtype=F32)
    if not members:
        return {}
    no_medium = np.zeros((0, 0), dtype=bool) if medium is None else medium
    lit = (residual > 0.0).all(axis=0)
    claims = np.zeros_like(residual)
    indexes = {key: np.array(passes, np.int64) for key, passes in members.items()}
    taking = [key for key in members
              if sliver_claims(colours[key], parts, indexes[key], covers[key].source,
                               covers[key].vacant, no_medium, lit, claims)]
    if not taking:
        return {}
    share = np.empty(lit.shape, dtype=F32)
    claim_share(residual, claims, share)
    lent = {}
    for key in taking:
        cover = covers[key]
        out = np.empty_like(colours[key])
        lend_sliver(colours[key], parts, indexes[key], cover.source,
                    cover.vacant, no_medium, lit, share, SLIVER_CAP, residual, out)
        lent[key] = out
    return lent


def colour_cover(colour: np.ndarray, medium: np.ndarray | None) -> Cover:
    """The :class:`Cover` of a colour pass (3, H, W) as written, with the frame's medium
    pixels (None: none). A medium pixel's colour is the file's averaged over 7x7 pixels
    (:func:`medium_colours`): some reach the surface, but next to the sky or deep in the
    medium none may, and a pass divided by a colour averaged from samples a few pixels away
    is a light divided by a colour near 0 (a converged render's is 0 there: no surface in
    the pixel). Next to a pixel whose sample reached it, the converged colour is not 0."""
    surface = _surface(colour)
    if medium is None:
        return Cover(surface, None, surface)
    reached = np.empty_like(surface)
    touching(surface & ~medium, reached)
    barred = medium & ~(surface & reached)
    return Cover(surface, barred, surface & ~barred)


def medium_emission(filtered: np.ndarray, pixels: np.ndarray, passes: list[LightLayer],
                    emitters: list[LightLayer]) -> np.ndarray:
    """The emission passes' part of the filtered medium signal ``filtered`` (the medium's
    light plus, on the medium ``pixels``, the emission seen through it: filters.stages.
    fill_medium), per emission pass, (E, 3, N) over the N medium pixels: the signal split
    between its own passes and the emission passes in proportion to their box-filtered input
    light, and among the emission passes likewise (equal parts where they are all 0). Two box
    means of sums (and one per emission pass where several hold light there), each over the
    medium pixels' box (:func:`_medium_box`): the same means on those pixels."""
    crop = (slice(None), *_medium_box(pixels))
    inside = pixels[crop[1:]]

    def smooth(planes: list[np.ndarray]) -> np.ndarray:
        return box_filter(np.sum([p[crop] for p in planes], axis=0, dtype=F32))[:, inside]

    through = smooth([layer.radiance for layer in emitters])
    total = through + smooth([layer.radiance for layer in passes]) if passes else through
    share = np.divide(through, total, out=np.zeros_like(through), where=total > SHARE_FLOOR)
    taken = filtered[crop][:, inside] * share
    lit = [k for k, layer in enumerate(emitters) if layer.radiance[crop][:, inside].any()]
    if len(lit) == 1:
        out = np.zeros((len(emitters), *taken.shape), dtype=F32)
        out[lit[0]] = taken
        return out
    weights = np.stack([smooth([layer.radiance]) for layer in emitters])
    weight_sum = weights.sum(axis=0)
    return np.where(weight_sum > SHARE_FLOOR,
                    taken * weights / np.maximum(weight_sum, SHARE_FLOOR),
                    taken / len(emitters)).astype(F32)


def emission_kept(light: LightLayers, emission: np.ndarray | None,
                  averaged: np.ndarray | None = None) -> np.ndarray:
    """The emission passes' light as added back, (E, 3, H, W): Emit and Env are noise-free,
    so their own values are the shares; where the filter took the emission into a signal it
    is 0 in ``emission`` (the medium's split fills it: :func:`medium_emission`). On the
    ``averaged`` pixels (a still light's outline: its mean over frames,
    ``filters.stages.emission_mean``) each pass takes its share of the mean: its own share
    there, else its share of the 7x7 around (:func:`emission_shares`)."""
    kept = np.zeros((len(light.emission), *light.emission[0].radiance.shape)
                    if light.emission else (0,), dtype=F32)
    for own, layer in zip(kept, light.emission, strict=True):
        np.copyto(own, layer.radiance, where=True if emission is None else emission != 0.0)
    if emission is not None and averaged is not None and len(kept):
        shares = emission_shares([layer.radiance for layer in light.emission])
        kept[:, :, averaged] = shares[:, :, averaged] * emission[:, averaged]
    return kept


def emission_shares(passes: list[np.ndarray]) -> np.ndarray:
    """Each emission pass's share of their sum, (E, 3, H, W): its own where they hold light,
    else over the 7x7 around (``box_filter``), else equal parts."""
    raw = np.stack(passes).astype(F32)
    total = raw.sum(axis=0)
    around = box_filter(raw.reshape(-1, *raw.shape[2:])).reshape(raw.shape)
    around_total = around.sum(axis=0)
    equal = np.full_like(raw, 1.0 / len(passes))
    own = np.divide(raw, total, out=equal.copy(), where=total > SHARE_FLOOR)
    near = np.divide(around, around_total, out=equal, where=around_total > SHARE_FLOOR)
    return np.where(total > SHARE_FLOOR, own, near).astype(F32)


def colours_written_anew(passes: list[LightLayer], albedos: dict[str, np.ndarray],
                         medium: np.ndarray | None, pixel_weight: float,
                         spill: OutlineSpill | None
                         ) -> tuple[dict[tuple[str, str, str], np.ndarray], dict[int, Cover]]:
    """The colour passes the filter remodulated by (:func:`remodulated_colours`), as written:
    with the colour's pixel filter (:func:`covered_pixel_filter`), the file's 7x7 means on
    the ``medium`` pixels (:func:`medium_colours`), then the colour's noisy outline
    exchanges (:func:`spilled_colours`); and their :class:`Cover` by id. With ``spill``,
    the other colour passes (a glossy signal's, which its filter remodulates by this frame's
    colour as read) are written anew too: as read, with the exchanges, and as read again on
    the ``medium`` pixels (:func:`spilled_read_colours`)."""
    colours = remodulated_colours(passes, albedos)
    for colour in colours.values():
        covered_pixel_filter(colour, pixel_weight)
    if medium is not None:
        medium_colours(colours, passes, medium)
    read = _colours_as_read(passes, colours) if spill is not None else {}
    colours.update({key: np.array(colour, dtype=F32, copy=True) for key, colour in read.items()})
    covers = {id(colour): colour_cover(colour, medium) for colour in colours.values()}
    if spill is not None:
        spilled_colours(colours, covers, spill)
        spilled_read_colours(colours, covers, read, medium)
    return colours, covers


def _colours_as_read(passes: list[LightLayer], written: dict[tuple[str, str, str], np.ndarray]
                     ) -> dict[tuple[str, str, str], np.ndarray]:
    """The colour passes of the light passes that are not among ``written``, as read, by
    their channels."""
    return {layer.colour_channels: layer.colour for layer in passes
            if layer.colour is not None and layer.colour_channels is not None
            and layer.colour_channels not in written}


def spilled_read_colours(colours: dict[tuple[str, str, str], np.ndarray],
                         covers: dict[int, Cover],
                         read: dict[tuple[str, str, str], np.ndarray],
                         medium: np.ndarray | None) -> None:
    """In place, after :func:`spilled_colours`: the colour passes written from ``read`` (a
    glossy signal's ``GlossCol``, ``TransCol``) back as read on the ``medium`` pixels, whose
    cover then counts as vacant the pixels still 0. Where the G-buffer is defocus speckle
    the mix is what a converged render writes, and a glossy pass is the light over it
    (cycles/dof at 640x360: `GlossDir` 0.67x -> 0.20x its input's relMSE, `GlossCol`
    0.19x); a medium's pixels (fog, smoke) hold no surface of their own, and mixed there
    the colour spread a glass's `TransCol` onto the fog beside it (production `TransInd`
    0.27x -> 0.35x)."""
    if medium is None:
        return
    for key, colour in read.items():
        written = colours[key]
        np.copyto(written, colour, where=medium[None])
        covers[id(written)].vacant = ~_surface(written)


def write_passes(denoised: DenoisedFrame, emission: np.ndarray | None,
                 outputs: dict[str, np.ndarray], albedos: dict[str, np.ndarray],
                 light: LightLayers, medium_signal: str | None = None,
                 kept: np.ndarray | None = None, blend: Blend | None = None,
                 pixel_weight: float = 0.0, spill: OutlineSpill | None = None) -> None:
    """The denoised light passes and their colour passes into ``denoised.light``; the light
    they cannot carry (where their colour passes are 0: the pixel filter's spill onto the
    background, emitters' edges) goes to the emission passes, split by their shares. On
    medium pixels the emission seen through the medium was filtered with the medium's
    signal ``medium_signal``: its part goes back to the emission passes
    (:func:`medium_emission`). ``kept``: the emission passes' light as added back, when not
    :func:`emission_kept` (the noisy outlines' exchanges made on it). ``blend``: as
    :func:`compose_passes`'. ``pixel_weight``: the colour's pixel filter (its neighbour
    weight; 0: none), applied to the colour passes written anew
    (:func:`covered_pixel_filter`); ``spill``: the noisy outlines' exchanges made on the
    colour (``filters.edge_filter.OutlineSpill``), made on those colour passes last
    (:func:`spilled_colours`)."""
    if kept is None:
        kept = emission_kept(light, emission, denoised.emission_averaged)
    if (light.emission and denoised.medium is not None and emission is not None
            and medium_signal in outputs and denoised.medium.any()):
        assert medium_signal is not None
        pixels = denoised.medium
        through = medium_emission(outputs[medium_signal], pixels,
                                  [p for p in light.passes if p.signal == medium_signal],
                                  light.emission)
        # The medium pixels by their flat indexes (row-major: the boolean mask's order), so
        # each update touches those pixels only, not a frame-sized mask.
        flat = np.flatnonzero(pixels)
        kept.reshape(*kept.shape[:2], -1)[:, :, flat] += through
        taken = through.sum(axis=0)
        medium_light, emission = outputs[medium_signal].copy(), emission.copy()
        medium_light.reshape(3, -1)[:, flat] -= taken
        emission.reshape(3, -1)[:, flat] += taken
        outputs = {**outputs, medium_signal: medium_light}
    residual = denoised.color.copy() if emission is None else denoised.color - emission
    medium = denoised.medium if denoised.medium is not None and denoised.medium.any() else None
    colours, covers = colours_written_anew(light.passes, albedos, medium, pixel_weight, spill)
    written: list[np.ndarray | None] = []  # each pass's colour pass as written
    for layer in light.passes:
        colour = layer.colour
        if layer.colour_channels is not None and layer.colour_channels in colours:
            colour = colours[layer.colour_channels]
        written.append(colour)
        if colour is not None and id(colour) not in covers:
            covers[id(colour)] = colour_cover(colour, medium)
    barred = {k: cover.barred for k, colour in enumerate(written) if colour is not None
              and (cover := covers[id(colour)]).barred is not None}
    # Light no pass has, filtered or read (the pixel filter's spill onto the background) goes
    # to the emission passes when there are some, not in equal parts to every pass.
    # Where the denoised colour is below the emission (a defocused sky's edge: the filtered
    # colour is smooth, the emission passes are not), the light passes get no light rather
    # than negative light; the emission passes take the difference.
    light_only = np.maximum(residual, 0.0) if light.emission else residual
    parts = compose_passes(light_only, outputs, light.passes, barred, bool(light.emission),
                           blend, written)
    for layer, part, colour in zip(light.passes, parts, written, strict=True):
        stored = stored_values(layer, part, colour,
                               None if colour is None else covers[id(colour)])
        _write(layer.channels, stored, denoised.light)
        if colour is None:
            residual -= stored
        else:
            subtract_product(residual, stored, colour)
    # stored_values divided each part in place: parts holds the stored values.
    lent = lend_slivers(residual, parts, written, covers, medium)
    for layer, colour in zip(light.passes, written, strict=True):
        if colour is not None and id(colour) in lent and layer.colour_channels is not None:
            colours[layer.colour_channels] = lent[id(colour)]
    for channels, colour in colours.items():
        _write(channels, colour, denoised.light)
    if not light.emission:
        return
    extra = split_by_shares(residual, kept, None,
                            last=lambda: frame_totals([e.radiance for e in light.emission]))
    for layer, own, part in zip(light.emission, kept, extra, strict=True):
        _write(layer.channels, np.add(own, part, out=part), denoised.light)


def _write(channels: tuple[str, str, str], planes: np.ndarray,
           into: dict[str, np.ndarray]) -> None:
    for name, plane in zip(channels, planes, strict=True):
        into[name] = np.ascontiguousarray(plane, dtype=F32)


def _rgb(layers: dict[str, np.ndarray], name: str) -> np.ndarray:
    """The layers ``<name>.R/G/B`` as one (3, H, W) array: a view of them where they lie one
    after the other in memory (a signal's output and colour as the filter hands them:
    ``filters.stages.remodulate.signal_output``), else their stack (a copy)."""
    return _joined([layers[f"{name}.{c}"] for c in "RGB"])


def _planes(layers: dict[str, np.ndarray], names: tuple[str, ...], suffix: str = ""
            ) -> dict[str, np.ndarray]:
    """``<name><suffix>.R/G/B`` of each signal ``name`` as (3, H, W) planes (`_rgb`)."""
    return {name: _rgb(layers, f"{name}{suffix}") for name in names
            if f"{name}{suffix}.R" in layers}


# The light groups' filter only gives shares of the colour, whose detail is the colour's own
# filter's: cheaper settings (bench/light_layers.py and bench/light_layers_cost.py; docs/
# cycles.md#light-groups-and-light-passes-come-out-denoised).
GROUP_SETTINGS: dict[str, object] = {
    # The filter's pixel filter stage acts on its summed output, which the shares do not use:
    # spill_groups applies the colour's to each filtered group instead.
    "atrous_iterations": 3, "temporal_albedo": False, "pixel_filter": 0.0, "despike": 0.0,
    # Shares want smooth groups: the colour's tighter stop (docs/stability.md#a-tighter-
    # luminance-stop) left Combined_env at 0.30x its input's relMSE, 2.5 gives 0.27x.
    "mixed_sigma_luminance": 2.5,
    # Cost (issue 32): the turning objects' history and the outline filter do not change the
    # shares, and a 3x3 spatial variance where the history is short moves each group's relMSE
    # by at most 2 % (bench/light_layers.py on cycles/production, smoke and dof: better on
    # smoke, worse on dof), for 20-35 % less time in the groups' filter at 1080p
    # (docs/performance.md#production-frames-1080p-80-channels).
    "object_history": False, "edge_filter": 0.0, "noisy_outline_weight": 0.0,
    "spatial_variance_radius": 1,
    # TAA acts on the summed output too, which the shares do not use (the colour's TAA is
    # in the colour the groups are composed to).
    "taa": False, "taa_jittered": False,
}


def group_params(params: SVGFParams) -> SVGFParams:
    """The light groups' filter settings: the colour's with :data:`GROUP_SETTINGS`."""
    return dataclasses.replace(params, **GROUP_SETTINGS)  # type: ignore[arg-type]


def frame_light(frame: Frame) -> LightLayers:
    """The frame's light layers, made by its ``light_loader`` (once) where it has one."""
    if frame.light is None and frame.light_loader is not None:
        frame.light = frame.light_loader()
    frame.light_loader = None
    return frame.light or LightLayers()


def group_lone_lights(frame: Frame, medium: np.ndarray | None) -> Pixels:
    """The lone lights of the G-buffer albedo (``filters.lone_lights``) the groups' filter
    demodulates: not on the ``medium`` pixels that are a medium surface of their own, where
    that albedo is the medium's per-sample noise (smoke: above 1 on a pixel in 20) and
    :func:`group_frame` filters the groups as radiance."""
    ys, xs = lone_lights(frame.albedo, frame.depth)
    if medium is None or not ys.size:
        return ys, xs
    kept = ~(medium[ys, xs] & (frame.depth[ys, xs] == MEDIUM_DEPTH))
    return ys[kept], xs[kept]


def group_frame(frame: Frame, groups: list[LightLayer], medium: np.ndarray | None = None,
                lone: Pixels | None = None) -> Frame:
    """The frame whose signals are the light groups (each filtered like a combined colour:
    demodulated by the G-buffer albedo, direct and indirect light together), same guides.
    On the ``medium`` pixels (the colour filter's, its G-buffer filled: ``frame``) that are
    a medium surface of their own (no surface near: ``filters.medium``) the groups are
    filtered as radiance, as the colour's medium signal is: the G-buffer albedo there is
    the medium's on this pixel's sample (Cycles' ``Denoising Albedo`` inside smoke: 0.2 to
    1.8 from one pixel to the next), and remodulating by it puts that noise back into the
    groups' shares. The ``lone`` lights of that albedo (``filters.lone_lights``) take their
    neighbours' albedo: their light is a firefly to the groups' filter, as to the colour's."""
    albedo = (frame.albedo if lone is None
              else neighbours_albedo(frame.albedo, frame.depth, lone))
    if medium is not None:
        own = medium & (frame.depth == MEDIUM_DEPTH)
        if own.any():
            albedo = albedo.copy() if albedo is frame.albedo else albedo
            albedo[:, own] = 1.0
    signals = [Signal(f"group{k}", np.ascontiguousarray(g.radiance, dtype=F32), albedo,
                      guide_albedo=True, mixed=True) for k, g in enumerate(groups)]
    return dataclasses.replace(frame, signals=signals, emission=None, light=None,
                               final_colour=None)


def group_input(gbuffer: Frame, groups: list[LightLayer], medium: np.ndarray | None
                ) -> tuple[Frame | None, Pixels | None]:
    """The groups' filter's frame (:func:`group_frame`) and the lone lights it found
    (:func:`group_lone_lights`); None, None without groups."""
    if not groups:
        return None, None
    lone = group_lone_lights(gbuffer, medium)
    return group_frame(gbuffer, groups, medium, lone), lone


@dataclasses.dataclass
class LayerClock:
    """The wall seconds of the light layers' own work on the last frame, by part: the
    light passes' shares (``passes``), the light groups' (``groups``: their pixel filter,
    the outlines' exchanges and the split; their filter has its own stages; on 2x2 blocks,
    ``group_blocks``: making the blocks and upsampling their output). `svgf denoise
    -v` prints them after the inner filters' stages."""

    stage_seconds: dict[str, float] = dataclasses.field(default_factory=dict)


# The light groups' filter runs on 2x2 blocks (filters.halfres) from 720p up: at 1080p its
# cost falls from ~0.64 to ~0.14 s a frame (the blocks' making and upsampling 0.1-0.2 more)
# and the run's peak by ~250 MB. At 640x360 the groups' relMSE moved by -8 to -19 % on the
# dof shot and by -2 to +17 % on the smoke shot, all under 0.015x their input's; at 128x72
# by -32 to +24 % (docs/performance.md, session 42): not below 720p. Its sparkles' dark blobs
# went with the lone lights' handling (filters.lone_lights). At 1280x720 (smoke, 256-spp
# references) the key group's relMSE is 15 % above full resolution's, env 4 % below
# (session 43): the lever, should that show, is this threshold.
GROUP_BLOCKS_MIN_PIXELS = 1280 * 720


class LayeredDenoiser:
    """The causal Denoiser plus the light layers of its frames (`Frame.light`): the colour as
    the Denoiser alone gives it, and every light pass and light group denoised, adding up to
    it (`DenoisedFrame.light`). The light groups' filter keeps its own history; ``state()``
    is the colour's (a history file resumes the colour; the groups then start cold)."""

    def __init__(self, params: SVGFParams, debug_layers: bool = False,
                 colour: PipelineFilter | None = None) -> None:
        from svgf_cli.filters.denoiser import Denoiser

        self.params = params
        self.debug_layers = debug_layers
        # The colour's filter (the causal Denoiser unless given): its process(frame, ...)
        # hands back a DenoisedFrame with its G-buffer, or None (no output for that frame).
        self.colour: Any = Denoiser(params, debug_layers=debug_layers) if colour is None \
            else colour
        self.colour.setup = dataclasses.replace(self.colour.setup, signal_outputs=True)
        self.colour.gbuffer_output = True
        self.groups = Denoiser(group_params(params))
        self.groups.setup = dataclasses.replace(self.groups.setup, signal_outputs=True)
        self.layers = LayerClock()
        self.shares = PassShares()  # the light passes' shares over time

    @property
    def stages(self) -> tuple[str, ...]:
        return self.colour.stages

    @property
    def frames_processed(self) -> int:
        return self.colour.frames_processed

    def held_bytes(self) -> int:
        return self.colour.held_bytes() + self.groups.held_bytes()

    def reset(self) -> None:
        self.colour.reset()
        self.groups.reset()
        self.shares.reset()

    def state(self) -> dict[str, np.ndarray]:
        return self.colour.state()

    def load_state(self, state: dict[str, np.ndarray]) -> None:
        self.colour.load_state(state)
        self.shares.reset()

    def process(self, frame: Frame, *args: Any) -> DenoisedFrame | None:
        """Denoise the next frame (``args``: the colour filter's) and its light layers; None
        where the colour's filter gives no output (a reverse pass's warm-up). The groups'
        filter takes the G-buffer as the colour's filter used it (medium pixels filled)."""
        denoised = self.colour.process(frame, *args)
        # The two filters run one after the other, each letting go of its per-frame planes
        # when done: one workspace held at a time (1080p production: peak 4.14 -> 3.72 GB).
        self.colour.resident.release_workspace()
        if denoised is None:
            return None
        light = frame_light(frame)
        gbuffer, denoised.gbuffer = denoised.gbuffer, None  # for the groups' filter only
        assert gbuffer is not None
        groups, lone = group_input(gbuffer, light.groups, denoised.medium)
        emission = denoised.emission  # the frame's, less what the filter took into a signal
        names = self.colour.signal_names or ()
        outputs = _planes(denoised.layers, names)
        spill = denoised.outline_spill
        if spill is not None:
            # The noisy outlines' exchanges were made on the colour, emission included: made
            # on every share and every emission pass too, the layers still add up to it.
            # An emission pass's light where the filter took it into a signal (the medium's
            # pixels) is that signal's: left out before the exchange, as write_passes does.
            # In place where this frame's planes are not kept for the writer: the signals'
            # outputs (fresh per frame, written only as debug layers), the emission kept.
            outputs = {name: spill.apply(plane, None if self.debug_layers else plane)
                       for name, plane in outputs.items()}
            kept = (emission_kept(light, emission, denoised.emission_averaged)
                    if light.emission else None)
            for own in kept if kept is not None else ():
                spill.apply(own, own)
            emission = None if emission is None else spill.apply(emission)
        else:
            kept = None
        # The colours the diffuse-like signals were remodulated by (their temporal means);
        # glossy signals keep this frame's colour, except where a reflected light's colour
        # stands in (filters.stages.reflected_lights): their colour passes stay as read.
        albedos = _planes(denoised.layers, tuple(s.name for s in frame.signals
                                                 if not s.glossy), ".albedo")
        medium_signal = next((s.name for s in frame.signals
                              if frame.medium is not None and s.radiance is frame.medium), None)
        for filtered in (frame, gbuffer):  # read by the colour's filter alone (peak -115 MB)
            filtered.release_filtered_planes()
        lengths = {name: denoised.layers.get(f"{name}.history_length") for name in names}
        denoised.layers = ({k: v for k, v in denoised.layers.items()
                            if ".albedo." not in k and not k.endswith(".history_length")}
                           if self.debug_layers else {})
        clock = self.layers.stage_seconds
        clock.clear()
        if light.passes:
            started = time.perf_counter()
            alpha = params_for_samples(self.params, frame.samples_per_pixel).alpha

            def blend(index: int, mean: np.ndarray, spread: np.ndarray) -> None:
                layer = light.passes[index]
                self.shares.blend(layer.channels, mean, spread, gbuffer.motion,
                                  gbuffer.mesh_id, lengths.get(layer.signal), alpha)

            write_passes(denoised, emission, outputs, albedos, light, medium_signal, kept, blend,
                         pixel_filter_weight(self.params.pixel_filter, frame.centre_sampled),
                         spill)
            self.shares.advance(gbuffer.mesh_id)
            clock["passes"] = time.perf_counter() - started
        if groups is not None:
            filtered = self.filter_groups(groups)
            assert filtered is not None
            started = time.perf_counter()
            spill_groups(filtered, pixel_filter_weight(self.params.pixel_filter,
                                                       frame.centre_sampled))
            if spill is not None:
                for group in filtered:
                    spill.apply(group, group)
            for layer, part in zip(light.groups, compose_groups(denoised.color, filtered,
                                                                light.groups, lone),
                                   strict=True):
                _write(layer.channels, part, denoised.light)
            clock["groups"] = time.perf_counter() - started
        return denoised

    def filter_groups(self, groups: Frame, outputs: bool = True) -> np.ndarray | None:
        """The light groups' filter on ``groups`` (:func:`group_frame`), its outputs as one
        (K, 3, H, W) array; on 2x2 blocks (``filters.halfres``) from
        ``GROUP_BLOCKS_MIN_PIXELS`` up. Without ``outputs`` (a warm-up frame: the filter's
        history alone is wanted) None, and the blocks are not brought back."""
        started = time.perf_counter()
        small = (halve_frame(groups) if groups.depth.size >= GROUP_BLOCKS_MIN_PIXELS
                 else None)
        blocks = time.perf_counter() - started
        layers = self.groups.process(groups if small is None else small).layers
        self.groups.resident.release_workspace()
        if not outputs:
            return None
        # A view of the filter's outputs (side by side: filters.stages.remodulate).
        filtered = _joined([_rgb(layers, s.name) for s in groups.signals])
        if small is None:
            return filtered
        started = time.perf_counter()
        filtered = upsample(filtered, small, groups)
        # -v prints it with the light layers' own work (LayerClock).
        self.layers.stage_seconds["group_blocks"] = blocks + time.perf_counter() - started
        return filtered


class LayeredReversePass(LayeredDenoiser):
    """The reverse pass of a bidirectional run (``filters.two_pass.ReversePass``) plus the
    light layers of its output frames, as :class:`LayeredDenoiser` makes them: split from the
    combined colour by the same shares. The light groups' filter and the passes' shares go
    the reverse pass's way (their history from the later frames, reprojected with its motion
    to the next frame): the groups' filter from the pass's first frame (its warm-up frames
    too, as a causal run's), the shares from its first output frame."""

    def __init__(self, params: SVGFParams, debug_layers: bool = False) -> None:
        from svgf_cli.filters.two_pass import ReversePass

        super().__init__(params, debug_layers,
                         colour=ReversePass(params, debug_layers=debug_layers))

    def forward_buffers(self, num_signals: int, height: int, width: int) -> Any:
        """The reverse pass's (``ReversePass.forward_buffers``)."""
        return self.colour.forward_buffers(num_signals, height, width)

    def process(self, frame: Frame, *args: Any) -> DenoisedFrame | None:
        """As :meth:`LayeredDenoiser.process`; on a warm-up frame (no output) the light
        groups' filter still takes the frame, as a causal run's warm-up frames give it a
        history before the first output (the frame's light passes are read with its groups
        and not used: warm-up frames only)."""
        denoised = super().process(frame, *args)
        warmup, self.colour.warmup_gbuffer = self.colour.warmup_gbuffer, None
        if denoised is None and warmup is not None:
            light = frame_light(frame)
            if light.groups:
                gbuffer, medium = warmup
                warm, _ = group_input(gbuffer, light.groups, medium)
                assert warm is not None
                self.filter_groups(warm, outputs=False)
        return denoised

