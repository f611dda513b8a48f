"""The renderer's pixel filter across outlines, for frames whose sample went through the
pixel centre.

A centre-sampled frame (``filters.pixel_filter``) sees, at a pixel on an object's outline,
one of the two surfaces: the one at the centre, in every frame, so no history mixes them.
The renderer's converged frame weighs both by the pixel filter: a silhouette against the
sky, a light's edge, an object in front of another are anti-aliased there, and a staircase
of point samples crawls as the outline moves. The a-trous never blurs across an outline
(its edge-stops), and the emission (the sky seen directly, lights) is added back
unfiltered, so the pixel filter's small interior kernel (0.05, tuned where the a-trous has
already blurred) leaves outlines as sharp as the samples.

:func:`edge_filter` adds the filter's spill across outlines: for each pair of neighbouring
pixels on two surfaces (another object id, background, or depths more than ``DEPTH_JUMP``
apart), each takes ``w`` of the other's whole colour, emission included, and gives up as
much of its own (``c'(p) = c(p) + w sum_{q ~ p} (c(q) - c(p))`` over its outline
neighbours, rows then columns): what the pair holds is kept. Where the 1-spp G-buffer
itself is noisy (a defocused region whose depth jumps from sample to sample, the surfaces
seen through fog) every pair is an outline, and the spill is a small blur of what the
G-buffer could not guide.

:func:`noisy_outline_weights` makes that blur stronger where it is all there is: where more
than ``DENSE_FROM`` of the pixel pairs around a pixel (its ``(2 DENSE_RADIUS + 1)^2``
window, rows and columns) change object or meet the background, the G-buffer is noise (a
defocused region, where each sample sees one surface or another at random: half of the
pairs for an even mix), not geometry: a clean outline crosses a 5x5 window in one row or
column of pairs (at most 22 % of them), a one-pixel wire in two (22 %), two outlines
crossing about as much. The extra weight grows linearly to the full
``noisy_outline_weight`` at ``DENSE_FULL`` and is exchanged over ``NOISY_PASSES`` passes;
each pair uses the mean of its two pixels' weights, so what the pair holds is still kept.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numba import njit, prange

from svgf_cli.filters.fastmath import FASTMATH
from svgf_cli.filters.params import AUTO_PIXEL_FILTER
from svgf_cli.filters.shares import box_mean, row_sums

F32 = np.float32
_ZERO = F32(0.0)
_HALF = F32(0.5)
# Depths further apart than this ratio are two surfaces (as filters.taa's outlines).
DEPTH_JUMP = F32(1.05)
# Each outline neighbour's weight for a centre-sampled frame (on top of the pixel filter's).
CENTRE_SAMPLE_EDGE_WEIGHT = 0.05
# Noisy outlines: the window (radius), the share of its pairs on outlines where the extra
# weight starts and where it is full, and how many passes exchange it (measured on
# cycles/dof and smoke, docs/algorithm.md#noisy-outlines-defocus).
DENSE_RADIUS = 2
DENSE_FROM = 0.3
DENSE_FULL = 0.55
NOISY_PASSES = 4
# A pixel whose sample saw a surface none of its 4 neighbours saw is noise too where its
# window's share of outlines is this or more (sparse defocus speckle); below it (a clean
# region: one such pixel's own 4 pairs are 10 % of a 5x5 window's 40) it may be a small
# object in focus and stays as sharp.
ISOLATED_FROM = 0.15


def edge_filter_weight(setting: float, centre_sampled: bool) -> float:
    """The outline neighbours' weight for a frame: ``setting`` unless it is
    ``AUTO_PIXEL_FILTER``, then ``CENTRE_SAMPLE_EDGE_WEIGHT`` for a centre-sampled frame and
    0 for any other."""
    if setting != AUTO_PIXEL_FILTER:
        return setting
    return CENTRE_SAMPLE_EDGE_WEIGHT if centre_sampled else 0.0


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, error_model="numpy")
def _outline(mesh_a: np.int32, mesh_b: np.int32, z_a: np.float32, z_b: np.float32) -> bool:
    """Whether two neighbouring pixels show two surfaces."""
    if mesh_a != mesh_b:
        return True
    if z_a <= _ZERO or z_b <= _ZERO:
        return z_a > _ZERO or z_b > _ZERO
    return z_a > DEPTH_JUMP * z_b or z_b > DEPTH_JUMP * z_a


@njit(fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy")
def _pair_weights(ids_a: np.ndarray, z_a: np.ndarray, w_a: np.ndarray, ids_b: np.ndarray,
                  z_b: np.ndarray, w_b: np.ndarray, out: np.ndarray) -> None:
    """``out[i]`` = the mean of the two pixels' weights where pixels ``a[i]`` and ``b[i]``
    show two surfaces, else 0."""
    for i in range(out.size):
        pair = _HALF * (w_a[i] + w_b[i])
        out[i] = pair if _outline(ids_a[i], ids_b[i], z_a[i], z_b[i]) else _ZERO


@njit(parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
      error_model="numpy")
def pair_weights(mesh_id: np.ndarray, depth: np.ndarray, weight: np.ndarray,
                 right: np.ndarray, down: np.ndarray) -> None:
    """The exchanges' weights (H, W): ``right[y, x]`` of the pair of pixel ``(y, x)`` and
    its right neighbour, ``down[y, x]`` of it and the one below: the mean of the two
    pixels' ``weight`` where they show two surfaces, else 0 (0 past the image's edge)."""
    height, width = depth.shape
    for y in prange(height):
        ids, z, w = mesh_id[y], depth[y], weight[y]
        across, under = right[y], down[y]
        _pair_weights(ids[:-1], z[:-1], w[:-1], ids[1:], z[1:], w[1:], across[:-1])
        across[width - 1] = _ZERO
        if y < height - 1:
            _pair_weights(ids, z, w, mesh_id[y + 1], depth[y + 1], weight[y + 1], under)
        else:
            under[:] = _ZERO


@njit(parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
      error_model="numpy")
def exchange(planes: np.ndarray, right: np.ndarray, down: np.ndarray, rows: np.ndarray,
             out: np.ndarray) -> None:
    """``out`` (C, H, W): ``planes`` (C, H, W) after the exchanges of the pair weights
    ``right`` and ``down`` (:func:`pair_weights`), ``c'(p) = c(p) + sum_q w_pq (c(q) -
    c(p))``, along rows (into ``rows``, (C, H, W) scratch) then columns; float32, row
    slices."""
    channels, height, width = planes.shape
    for y in prange(height):
        across = right[y]
        for c in range(channels):
            source, row = planes[c, y], rows[c, y]
            row[0] = source[0] + across[0] * (source[1] - source[0]) if width > 1 else source[0]
            for x in range(1, width - 1):
                here = source[x]
                row[x] = (here + across[x - 1] * (source[x - 1] - here)
                          + across[x] * (source[x + 1] - here))
            if width > 1:
                row[width - 1] = source[width - 1] + across[width - 2] * (
                    source[width - 2] - source[width - 1])
    for y in prange(height):
        above = max(y - 1, 0)
        below = min(y + 1, height - 1)
        up = down[above]
        under = down[y]
        for c in range(channels):
            here, target = rows[c, y], out[c, y]
            over, lower = rows[c, above], rows[c, below]
            if y > 0:
                for x in range(width):
                    h = here[x]
                    target[x] = h + up[x] * (over[x] - h) + under[x] * (lower[x] - h)
            else:  # the first row has no pair above: a zero weight, the same arithmetic
                for x in range(width):
                    h = here[x]
                    target[x] = h + _ZERO * (over[x] - h) + under[x] * (lower[x] - h)


def edge_filter(colour: np.ndarray, mesh_id: np.ndarray, depth: np.ndarray,
                weight: np.ndarray, out: np.ndarray) -> None:
    """``out`` (3, H, W): ``colour`` (3, H, W) with each outline neighbour's colour
    exchanged at the mean of the two pixels' ``weight`` (H, W), along rows then columns
    (module docstring); float32."""
    right = np.empty(depth.shape, dtype=F32)
    down = np.empty(depth.shape, dtype=F32)
    pair_weights(mesh_id, depth, weight, right, down)
    exchange(colour, right, down, np.empty(out.shape, dtype=F32), out)


def outline_share(mesh_id: np.ndarray, depth: np.ndarray, radius: int = DENSE_RADIUS
                  ) -> np.ndarray:
    """(H, W) float32: the share of the pixel pairs in each pixel's ``(2 radius + 1)^2``
    window (its pixels with their right and lower neighbours in the image) whose two pixels
    show another object or one of them the background. Depth steps do not count: a floor
    seen at a grazing angle steps at every row."""
    height, width = depth.shape
    counts = np.empty((height, width), dtype=np.int32)
    _outline_counts(mesh_id, depth, counts)
    share = np.empty((height, width), dtype=F32)
    _window_share(counts, np.int64(radius), share)
    return share


@njit(parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False)
def _outline_counts(mesh_id: np.ndarray, depth: np.ndarray, counts: np.ndarray) -> None:
    """``counts[y, x]``: how many of the pairs with the pixel's right and lower neighbour
    change object or meet the background (0, 1 or 2)."""
    height, width = depth.shape
    for y in prange(height):
        ids, z, row = mesh_id[y], depth[y], counts[y]
        below = min(y + 1, height - 1)
        for x in range(width):
            here_bg = z[x] <= _ZERO
            count = 0
            if x + 1 < width and (ids[x] != ids[x + 1] or here_bg != (z[x + 1] <= _ZERO)):
                count += 1
            if y + 1 < height and (ids[x] != mesh_id[below, x]
                                   or here_bg != (depth[below, x] <= _ZERO)):
                count += 1
            row[x] = count


@njit(parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False)
def _window_share(counts: np.ndarray, radius: np.int64, share: np.ndarray) -> None:
    """``share``: the window sums of ``counts`` over the number of pairs inside the image
    in each window (rows, then columns, as running sums)."""
    height, width = counts.shape
    rows = np.empty((height, width))  # whole counts: exact in float64
    for y in prange(height):
        row_sums(counts[y], radius, rows[y])
    for x in prange(width):
        total = 0.0
        for y in range(min(radius, height)):
            total += rows[y, x]
        x0, x1 = max(x - radius, 0), min(x + radius, width - 1)
        columns = x1 - x0 + 1
        columns_with_right = min(x1, width - 2) - x0 + 1
        for y in range(height):
            if y + radius < height:
                total += rows[y + radius, x]
            if y - radius - 1 >= 0:
                total -= rows[y - radius - 1, x]
            y0, y1 = max(y - radius, 0), min(y + radius, height - 1)
            pairs = (y1 - y0 + 1) * columns_with_right + columns * (min(y1, height - 2) - y0 + 1)
            share[y, x] = F32(total) / F32(pairs) if pairs > 0 else _ZERO


def noisy_outline_weights(share: np.ndarray, weight: float,
                          isolated: np.ndarray | None = None) -> np.ndarray:
    """(H, W) float32: ``weight`` times how dense the outlines are, 0 below ``DENSE_FROM``
    of the pairs and 1 from ``DENSE_FULL``, linear between (module docstring); the full
    ``weight`` on the ``isolated`` pixels (H, W) bool whose share is ``ISOLATED_FROM`` or
    more (:func:`isolated_samples`)."""
    dense = np.clip((share - F32(DENSE_FROM)) / F32(DENSE_FULL - DENSE_FROM), 0.0, 1.0)
    if isolated is not None:
        dense[isolated & (share >= F32(ISOLATED_FROM))] = 1.0
    return (dense * F32(weight)).astype(F32)


@njit(parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False)
def isolated_samples(mesh_id: np.ndarray, depth: np.ndarray, out: np.ndarray) -> None:
    """``out`` (H, W) bool: the pixels whose every neighbour in the image (up, down, left,
    right; at least two) shows another object or, of the two, one the background: a sample
    that saw a surface none of its neighbours saw."""
    height, width = depth.shape
    for y in prange(height):
        ids, z = mesh_id[y], depth[y]
        for x in range(width):
            here_bg = z[x] <= _ZERO
            alone = True
            seen = 0
            for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                yy, xx = y + dy, x + dx
                if 0 <= yy < height and 0 <= xx < width:
                    seen += 1
                    if ids[x] == mesh_id[yy, xx] and here_bg == (depth[yy, xx] <= _ZERO):
                        alone = False
            out[y, x] = alone and seen >= 2


def near(pixels: np.ndarray, radius: int = DENSE_RADIUS) -> np.ndarray:
    """(H, W) bool: the pixels with one of ``pixels`` (H, W) bool within their
    ``(2 radius + 1)^2`` window (its box mean above 0: ``filters.shares.box_mean``)."""
    mean = np.empty((1, *pixels.shape), dtype=F32)
    box_mean(np.ascontiguousarray(pixels[None], dtype=F32), int(radius), mean)
    return mean[0] > 0.0


def lone_samples(mesh_id: np.ndarray, depth: np.ndarray,
                 medium: np.ndarray | None = None) -> np.ndarray:
    """(H, W) bool: :func:`isolated_samples` not within ``DENSE_RADIUS`` of a ``medium``
    pixel (through a medium a lone sample is the surface seen between scatterings, its
    light already the medium's filtered signal: ``filters.stages.fill_medium``)."""
    lone = np.empty(depth.shape, dtype=np.bool_)
    isolated_samples(mesh_id, depth, lone)
    if medium is not None and medium.any():
        lone &= ~near(medium)
    return lone


@dataclass(frozen=True)
class OutlineSpill:
    """The noisy outlines' exchanges made on a frame: ``weight`` (H, W), ``passes`` times,
    over the outlines of ``mesh_id`` and ``depth``. Linear and conservative, so made on each
    light layer as on the colour they keep the layers adding up to it. Only the pixels
    within one of a weighted pixel change (a pair's weight is the mean of its two pixels'):
    the exchanges are made on that box alone. The pairs' weights are found once, for every
    pass and every plane the exchanges are made on (a frame's colour and its ten or more
    light layers)."""

    mesh_id: np.ndarray
    depth: np.ndarray
    weight: np.ndarray
    passes: int
    # Where in the frame the three planes above lie (the whole frame by default).
    box: tuple[slice, slice] = (slice(None), slice(None))
    # pair_weights of the three planes: (right, down).
    pairs: tuple[np.ndarray, np.ndarray] = field(init=False, repr=False, compare=False)
    # The crops and rows the exchanges go through (`_scratch`).
    scratch: list[np.ndarray] = field(default_factory=list, init=False, repr=False,
                                      compare=False)

    def __post_init__(self) -> None:
        right = np.empty(self.depth.shape, dtype=F32)
        down = np.empty(self.depth.shape, dtype=F32)
        pair_weights(self.mesh_id, self.depth, self.weight, right, down)
        object.__setattr__(self, "pairs", (right, down))

    @classmethod
    def of(cls, mesh_id: np.ndarray, depth: np.ndarray, weight: np.ndarray,
           passes: int) -> OutlineSpill:
        """The exchanges of ``weight`` (not all 0), cropped to the box of its non-zero
        pixels grown by one: outside it no pair has weight."""
        rows = np.flatnonzero(weight.any(axis=1))
        columns = np.flatnonzero(weight.any(axis=0))
        height, width = depth.shape
        box = (slice(max(int(rows[0]) - 1, 0), min(int(rows[-1]) + 2, height)),
               slice(max(int(columns[0]) - 1, 0), min(int(columns[-1]) + 2, width)))
        return cls(np.ascontiguousarray(mesh_id[box]), np.ascontiguousarray(depth[box]),
                   np.ascontiguousarray(weight[box]), passes, box)

    def apply(self, planes: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """``planes`` (3, H, W) with the exchanges made: into ``out`` (float32; may be
        ``planes`` itself), else a new float32 array."""
        if out is None:
            out = np.array(planes, dtype=F32, order="C")
        elif out is not planes:
            np.copyto(out, planes)
        region = out[(slice(None), *self.box)]
        # The passes go back and forth between two crops, in place where the box is the
        # whole of ``out``; the crops and the rows' scratch are this spill's, for every
        # plane it is made on (each fresh plane costs its pages' faults: docs/
        # performance.md).
        whole = region.flags.c_contiguous
        rows, first, *rest = self._scratch(region.shape, 2 if whole else 3)
        if whole:
            crop, other = region, first
        else:
            np.copyto(first, region)
            crop, other = first, rest[0]
        right, down = self.pairs
        for _ in range(self.passes):
            exchange(crop, right, down, rows, other)
            crop, other = other, crop
        if crop is not region:
            region[...] = crop
        return out

    def _scratch(self, shape: tuple[int, ...], count: int) -> list[np.ndarray]:
        """``count`` float32 arrays of ``shape``, kept for the next call."""
        if self.scratch and self.scratch[0].shape != shape:
            self.scratch.clear()
        while len(self.scratch) < count:
            self.scratch.append(np.empty(shape, dtype=F32))
        return self.scratch[:count]
