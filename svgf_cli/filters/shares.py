"""Kernels of the composable light layers (``filters.composable``): a clipped box mean, the
tent mean of a pass over its colour's pixels, and the split of a total by per-pixel shares.
Float64 references: ``tests/test_light_layers.py``.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from svgf_cli.filters.fastmath import FASTMATH

_JIT = dict(fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, parallel=True,
            error_model="numpy")


@njit(**_JIT)
def box_mean(planes: np.ndarray, radius: int, out: np.ndarray) -> None:
    """``out`` = the (C, H, W) planes' mean over a (2 radius + 1)^2 window clipped at the
    borders (each window divided by the pixels it covers), summed in float64: running sums
    along each row, then down each column, each in the same order. One job per channel
    keeps only the 2 radius + 2 row sums the column sums still need (a ring of rows): a
    frame-sized float64 temporary made this memory-bound. ``out`` may be ``planes``."""
    for c in prange(planes.shape[0]):
        _box_channel(planes[c], planes[c], False, False, radius, out[c])


def covered_average(stored: np.ndarray, surface: np.ndarray, coverage: np.ndarray,
                    radius: int, out: np.ndarray) -> None:
    """``out`` = the tent mean ``T`` (:func:`box_mean` of ``radius`` twice: weights
    ``t(dy) t(dx)``, ``t(d) = 2 radius + 1 - |d|``) of ``stored x surface`` (3, H, W) x
    (H, W) 1/0, divided by ``coverage`` (the surface's own tent mean, (H, W)) where that is
    above 0: ``T(stored surface) / T(surface)``, a pass stored divided by its colour averaged
    over the window's pixels that have that colour, nearer pixels weighing more (a lone
    bright sample leaves a peak, not a flat square). Each box rounds to float32."""
    _covered_moments(stored, surface, coverage, radius, False, out)


def covered_spread(stored: np.ndarray, surface: np.ndarray, coverage: np.ndarray,
                   average: np.ndarray, radius: int, reach: float, samples: float,
                   out: np.ndarray) -> None:
    """``out`` = ``reach`` standard errors of :func:`covered_average` ``average``: the
    values' spread about it, ``sqrt(max(T(stored^2 surface) / T(surface) - average^2, 0))``,
    over the square root of how many samples the weights are worth (``coverage`` x
    ``samples``, the tent's ``1 / sum w^2``, at least 1)."""
    _covered_moments(stored, surface, coverage, radius, True, out)
    _spread_of_moments(out, average, coverage, float(reach), float(samples))


# The two kernels the covered tent means share: a flag from Python is a plain bool to numba,
# where a constant in a kernel's call would compile one more copy of _tent_channel.
@njit(**_JIT)
def _covered_moments(stored: np.ndarray, surface: np.ndarray, coverage: np.ndarray,
                     radius: int, squared: bool, out: np.ndarray) -> None:
    """``out`` = ``T(stored surface) / T(surface)`` per channel (``squared``: of
    ``stored^2``), as :func:`covered_average` describes."""
    for c in prange(stored.shape[0]):
        _tent_channel(stored[c], surface, squared, coverage, radius, out[c])


@njit(**_JIT)
def _spread_of_moments(moments: np.ndarray, average: np.ndarray, coverage: np.ndarray,
                       reach: float, samples: float) -> None:
    """``moments`` (the covered tent means of the squares) become :func:`covered_spread`,
    in place."""
    for c in prange(moments.shape[0]):
        for y in range(moments.shape[1]):
            row, mean, share = moments[c, y], average[c, y], coverage[y]
            for x in range(row.shape[0]):
                count = max(share[x] * samples, 1.0)
                row[x] = reach * np.sqrt(max(row[x] - mean[x] * mean[x], 0.0) / count)


@njit(fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy")
def _tent_channel(plane: np.ndarray, surface: np.ndarray, squared: bool, coverage: np.ndarray,
                  radius: int, out: np.ndarray) -> None:
    """One channel (H, W) of :func:`covered_average` (``squared``: of the squares): the box
    mean of ``plane x surface``, the box mean of that in place, over ``coverage``."""
    _box_channel(plane, surface, True, squared, radius, out)
    _box_channel(out, out, False, False, radius, out)  # each row is summed before it is written
    for y in range(out.shape[0]):
        row, share = out[y], coverage[y]
        for x in range(row.shape[0]):
            row[x] = row[x] / share[x] if share[x] > 0.0 else row[x]


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
      error_model="numpy")
def _box_channel(plane: np.ndarray, surface: np.ndarray, covered: bool, squared: bool,
                 radius: int, out: np.ndarray) -> None:
    """One channel (H, W) of :func:`box_mean` (``covered`` False: ``surface`` is not
    read), or of the box mean of ``plane`` (``squared``: of its squares) times ``surface``.
    ``out`` may be ``plane``: row ``y`` is summed into the ring before ``out[y]`` is
    written."""
    height, width = plane.shape
    ring = 2 * radius + 2  # rows y - radius - 1 .. y + radius
    rows = np.empty((ring, width), dtype=np.float64)
    masked = np.empty(width if covered else 0, dtype=np.float32)
    columns = np.zeros(width)
    for y in range(min(radius, height)):
        _row_sums_of(plane, surface, covered, squared, masked, y, radius, rows[y % ring])
        columns += rows[y % ring]
    for y in range(height):
        if y + radius < height:
            added = rows[(y + radius) % ring]
            _row_sums_of(plane, surface, covered, squared, masked, y + radius, radius, added)
            if y - radius - 1 >= 0:
                removed = rows[(y - radius - 1) % ring]
                for x in range(width):
                    columns[x] = columns[x] + added[x] - removed[x]
            else:
                for x in range(width):
                    columns[x] += added[x]
        elif y - radius - 1 >= 0:
            removed = rows[(y - radius - 1) % ring]
            for x in range(width):
                columns[x] -= removed[x]
        rows_covered = min(y + radius + 1, height) - max(y - radius, 0)
        row = out[y]
        for x in range(width):
            cover = rows_covered * (min(x + radius + 1, width) - max(x - radius, 0))
            row[x] = columns[x] / cover


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
      error_model="numpy")
def _row_sums_of(plane: np.ndarray, surface: np.ndarray, covered: bool, squared: bool,
                 masked: np.ndarray, y: int, radius: int, out: np.ndarray) -> None:
    """:func:`row_sums` of row ``y`` of ``plane`` (``squared``: of its squares), times
    ``surface``'s when ``covered``."""
    if covered:
        values, mask = plane[y], surface[y]
        for x in range(masked.shape[0]):
            value = values[x] * values[x] if squared else values[x]
            masked[x] = value * mask[x]
        row_sums(masked, radius, out)
    else:
        row_sums(plane[y], radius, out)


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
      error_model="numpy")
def row_sums(row: np.ndarray, radius: int, out: np.ndarray) -> None:
    """``out[x]`` = the running sum of ``row`` over x - radius .. x + radius (float64)."""
    width = row.shape[0]
    running = 0.0
    for x in range(min(radius, width)):
        running += row[x]
    for x in range(width):
        if x + radius < width:
            running += row[x + radius]
        if x - radius - 1 >= 0:
            running -= row[x - radius - 1]
        out[x] = running


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
      error_model="numpy")
def _positive_sum(weights: np.ndarray, c: int, y: int, x: int) -> float:
    """The weights of one pixel and channel summed, negative ones as 0."""
    s = 0.0
    for k in range(weights.shape[0]):
        s += max(weights[k, c, y, x], 0.0)
    return s


@njit(**_JIT)
def split_plain_rows(total: np.ndarray, weights: np.ndarray, floor: float, out: np.ndarray,
                     pending: np.ndarray) -> int:
    """``out[k]`` = ``total`` x ``weights[k] / sum_j weights[j]`` per pixel and channel
    (negative weights count as 0) on every (channel, row) whose values all have a sum above
    ``floor``; the others are left for :func:`split_shares` and marked in ``pending``
    (C x H, 1: left). Returns how many values of those rows need its fallback (``total``
    not 0, the sum at most ``floor``): 0, and it needs none. ``out`` may be ``weights``
    (a left row is not written)."""
    count, channels, height, width = weights.shape
    found = np.zeros(channels * height, np.int64)
    for job in prange(channels * height):
        c, y = job // height, job % height
        sums = np.empty(width)
        _row_positive_sums(weights, c, y, sums)
        if _all_above(sums, floor):
            pending[job] = 0
            for k in range(count):
                _split_row(total[c, y], weights[k, c, y], sums, out[k, c, y])
            continue
        pending[job] = 1
        row = total[c, y]
        for x in range(width):
            found[job] += (sums[x] <= floor) & (row[x] != 0.0)
    return int(found.sum())


@njit(**_JIT)
def split_shares(total: np.ndarray, weights: np.ndarray, fallback: np.ndarray,
                 use_fallback: bool, excluded: np.ndarray, last: np.ndarray, floor: float,
                 out: np.ndarray, jobs: np.ndarray) -> None:
    """The (channel, row) ``jobs`` (``c x H + y``) that :func:`split_plain_rows` left:
    ``out[k]`` = ``total`` x ``weights[k] / sum_j weights[j]`` per value (negative weights
    count as 0); where that sum is at most ``floor``, the same with ``fallback`` (when
    ``use_fallback``; ``excluded``, (H, W) uint64 or empty: bit k set where ``fallback[k]``
    counts as 0), and where that is too, with the (K, C) ``last`` (one weight per part and
    channel for the whole image: ones for equal parts), and where those are all 0, no parts
    (0: the caller gives that total to someone else). ``out`` may be ``weights``: a value's
    weights are all read before its parts are written. Whole-row loops that choose per
    value (they vectorize: 30-97 % of a real frame's values may take the fallback)."""
    count, channels, height, width = weights.shape
    for i in prange(jobs.shape[0]):
        job = jobs[i]
        c, y = job // height, job % height
        sums = np.empty(width)
        _row_positive_sums(weights, c, y, sums)
        backup = np.zeros(width)  # the fallback's sums (0: not used)
        bits = np.zeros(width, np.uint64)
        if use_fallback and excluded.shape[0] > 0:
            bits[:] = excluded[y]
        if use_fallback:
            for k in range(count):
                row = fallback[k, c, y]
                for x in range(width):
                    backup[x] += _kept(row[x], bits[x], k)
        rest = 0.0
        for k in range(count):
            rest += max(last[k, c], 0.0)
        for k in range(count):
            row, spare, part = weights[k, c, y], fallback[k, c, y], out[k, c, y]
            even = max(last[k, c], 0.0) / rest if rest > 0.0 else 0.0
            spread = rest > 0.0  # else the part is +0, not t x 0
            for x in range(width):
                t, s, f = total[c, y, x], sums[x], backup[x]
                mine = t * (max(row[x], 0.0) / (s if s > floor else 1.0))
                other = t * (_kept(spare[x], bits[x], k) / (f if f > floor else 1.0)) \
                    if use_fallback else 0.0
                part[x] = mine if s > floor else (
                    other if f > floor else (t * even if spread else 0.0))


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
      error_model="numpy")
def _kept(weight: float, excluded: np.uint64, k: int) -> float:
    """A fallback weight as counted: negative as 0, and 0 where bit ``k`` of ``excluded``."""
    if (excluded >> np.uint64(k)) & np.uint64(1):
        return 0.0
    return max(weight, 0.0)


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
      error_model="numpy")
def _row_positive_sums(weights: np.ndarray, c: int, y: int, sums: np.ndarray) -> None:
    """``sums[x]`` = :func:`_positive_sum` of every pixel of row ``y``, in the same order."""
    sums[:] = 0.0
    for k in range(weights.shape[0]):
        row = weights[k, c, y]
        for x in range(sums.shape[0]):
            sums[x] += max(row[x], 0.0)


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
      error_model="numpy")
def _all_above(sums: np.ndarray, floor: float) -> bool:
    low = 0
    for x in range(sums.shape[0]):
        low += sums[x] <= floor
    return low == 0


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
      error_model="numpy")
def _split_row(total: np.ndarray, weights: np.ndarray, sums: np.ndarray,
               out: np.ndarray) -> None:
    """One part of a row: ``total x max(weight, 0) / sum``; ``out`` may be ``weights``."""
    for x in range(sums.shape[0]):
        out[x] = total[x] * (max(weights[x], 0.0) / sums[x])


@njit(**_JIT)
def divide_where_coloured(light: np.ndarray, colour: np.ndarray, stored: np.ndarray) -> None:
    """In place, per value of (3, H, W): ``light / colour`` where ``colour > 0``, else
    ``stored`` (a light pass stored divided by its colour: where that is 0, as read)."""
    channels, height, width = light.shape
    for job in prange(channels * height):
        c, y = job // height, job % height
        row, col, old = light[c, y], colour[c, y], stored[c, y]
        for x in range(width):
            row[x] = row[x] / col[x] if col[x] > 0.0 else old[x]


@njit(**_JIT)
def touching(mask: np.ndarray, out: np.ndarray) -> None:
    """``out`` (H, W) bool: whether one of the pixel's 4 neighbours (up, down, left, right;
    inside the image) is in ``mask`` (H, W) bool."""
    height, width = mask.shape
    for y in prange(height):
        for x in range(width):
            out[y, x] = ((y > 0 and mask[y - 1, x]) or (y + 1 < height and mask[y + 1, x])
                         or (x > 0 and mask[y, x - 1]) or (x + 1 < width and mask[y, x + 1]))


@njit(**_JIT)
def fill_from_neighbours(stored: np.ndarray, colour: np.ndarray, source: np.ndarray,
                         target: np.ndarray) -> int:
    """In place, on each ``target`` pixel (H, W) bool with a ``source`` pixel among its 4
    neighbours: ``stored`` (3, H, W) = those neighbours' ``stored x colour`` summed over their
    ``colour`` summed, per channel (0 where that colour sum is 0): a light pass stored
    divided by its colour, one pixel past where its colour ends. Targets must not be
    sources (a target's value is read by none). Returns how many pixels were filled."""
    _, height, width = stored.shape
    filled = np.zeros(height, np.int64)
    for y in prange(height):
        for x in range(width):
            if not target[y, x]:
                continue
            found = False
            for c in range(3):
                light = 0.0
                weight = 0.0
                for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                    yy, xx = y + dy, x + dx
                    if 0 <= yy < height and 0 <= xx < width and source[yy, xx]:
                        found = True
                        light += stored[c, yy, xx] * colour[c, yy, xx]
                        weight += colour[c, yy, xx]
                if found:
                    stored[c, y, x] = light / weight if weight > 0.0 else 0.0
            if found:
                filled[y] += 1
    return int(filled.sum())


@njit(**_JIT)
def subtract_product(residual: np.ndarray, stored: np.ndarray, colour: np.ndarray) -> None:
    """In place, per value of (3, H, W): ``residual -= stored x colour`` (a light pass's
    light as written: its stored value times its colour pass)."""
    channels, height, width = residual.shape
    for job in prange(channels * height):
        c, y = job // height, job % height
        row, values, tint = residual[c, y], stored[c, y], colour[c, y]
        for x in range(width):
            row[x] -= values[x] * tint[x]


@njit(**_JIT)
def coloured(colour: np.ndarray, out: np.ndarray) -> None:
    """``out`` (H, W) bool: where a colour pass (3, H, W) is above 0 in some channel."""
    _, height, width = colour.shape
    for y in prange(height):
        r, g, b, row = colour[0, y], colour[1, y], colour[2, y], out[y]
        for x in range(width):
            row[x] = (r[x] > 0.0) | (g[x] > 0.0) | (b[x] > 0.0)


@njit(**_JIT)
def find_slivers(colour: np.ndarray, before: np.ndarray, fraction: float, radius: int,
                 out: np.ndarray) -> None:
    """``out`` (H, W) bool: the pixels that had no colour ``before`` (H, W) bool and whose
    colour pass now (3, H, W) is above 0 but below ``fraction`` times the mean over the
    (2 radius + 1)^2 window's pixels that had colour before and still have, in its largest
    channel: ``max_c a_c(p) < fraction x max_c mean_q a_c(q)`` (the surfaces around it,
    not the other pixels the mix reached), or with no such pixel in the window. Found
    first, cleared by the caller: in place, a row would read neighbours another row had
    cleared."""
    _, height, width = colour.shape
    for y in prange(height):
        for x in range(width):
            out[y, x] = False
            own = max(colour[0, y, x], colour[1, y, x], colour[2, y, x])
            if before[y, x] or own <= 0.0:
                continue
            sums = np.zeros(3)
            count = 0
            for yy in range(max(y - radius, 0), min(y + radius + 1, height)):
                for xx in range(max(x - radius, 0), min(x + radius + 1, width)):
                    r, g, b = colour[0, yy, xx], colour[1, yy, xx], colour[2, yy, xx]
                    if before[yy, xx] & ((r > 0.0) | (g > 0.0) | (b > 0.0)):
                        sums[0] += r
                        sums[1] += g
                        sums[2] += b
                        count += 1
            if count == 0:
                out[y, x] = True
                continue
            around = max(sums[0], sums[1], sums[2]) / count
            out[y, x] = own < fraction * around


@njit(**_JIT)
def any_nonzero(planes: np.ndarray) -> bool:
    """Whether some value of the (C, H, W) planes is not 0 (``ndarray.any``)."""
    channels, height, width = planes.shape
    found = np.zeros(channels * height, np.bool_)
    for job in prange(channels * height):
        c, y = job // height, job % height
        row = planes[c, y]
        hit = False
        for x in range(width):
            hit |= row[x] != 0.0
        found[job] = hit
    return bool(found.any())


@njit(**_JIT)
def blend_previous(mean: np.ndarray, spread: np.ndarray, previous: np.ndarray,
                   motion: np.ndarray, mesh_id: np.ndarray, previous_mesh: np.ndarray,
                   length: np.ndarray, alpha: float) -> None:
    """In place, per pixel and channel of ``mean`` (3, H, W): ``lerp(p, mean, max(alpha,
    1 / length))`` (paper equation 6's blend, with the history length the colour's filter
    gave the pixel), ``p`` being ``previous`` at the nearest pixel to ``(x + motion.x, y +
    motion.y)`` clamped to ``mean +- spread`` (what this frame's mean allows: a reflection
    does not move with the surface it is seen on), where that pixel lies in the image and
    had the same mesh id last frame; elsewhere, and where ``length`` is at most 1 (no
    history), ``mean`` as it is."""
    _, height, width = mean.shape
    for y in prange(height):
        for x in range(width):
            h = length[y, x]
            if h <= 1.0:
                continue
            px = int(np.floor(x + motion[0, y, x] + 0.5))
            py = int(np.floor(y + motion[1, y, x] + 0.5))
            if px < 0 or py < 0 or px >= width or py >= height:
                continue
            if previous_mesh[py, px] != mesh_id[y, x]:
                continue
            a = max(alpha, 1.0 / h)
            for c in range(3):
                now, reach = mean[c, y, x], spread[c, y, x]
                kept = min(max(previous[c, py, px], now - reach), now + reach)
                mean[c, y, x] = kept + a * (now - kept)


@njit(**_JIT)
def covered_pixel_filter_kernel(colour: np.ndarray, weight: float) -> None:
    """In place on ``colour`` (3, H, W): on its pixels above 0 in some channel, the
    separable kernel ``[w, 1 - 2 w, w]`` (rows, then columns, edges replicated) over those
    pixels only, divided by the kernel's weight on them; other pixels as they are."""
    _, height, width = colour.shape
    centre = 1.0 - 2.0 * weight
    mask = np.empty((height, width), dtype=np.float32)
    for y in prange(height):
        for x in range(width):
            mask[y, x] = 1.0 if (colour[0, y, x] > 0.0) | (colour[1, y, x] > 0.0) | (
                colour[2, y, x] > 0.0) else 0.0
    rows = np.empty((4, height, width), dtype=np.float32)  # 3 channels, then the weight
    for y in prange(height):
        m = mask[y]
        last = width - 1
        for x in range(width):
            left, right = max(x - 1, 0), min(x + 1, last)
            rows[3, y, x] = centre * m[x] + weight * (m[left] + m[right])
            for c in range(3):
                v = colour[c, y]
                rows[c, y, x] = (centre * v[x] * m[x]
                                 + weight * (v[left] * m[left] + v[right] * m[right]))
    for y in prange(height):
        up, down = max(y - 1, 0), min(y + 1, height - 1)
        for x in range(width):
            if mask[y, x] == 0.0:
                continue
            total = centre * rows[3, y, x] + weight * (rows[3, up, x] + rows[3, down, x])
            for c in range(3):
                colour[c, y, x] = (centre * rows[c, y, x]
                                   + weight * (rows[c, up, x] + rows[c, down, x])) / total


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
      error_model="numpy")
def _is_sliver(source: np.ndarray, vacant: np.ndarray, medium: np.ndarray,
               lit: np.ndarray, y: int, x: int) -> bool:
    """Whether pixel (y, x) may take a sliver: ``vacant``, a ``source`` pixel among its 4
    neighbours, not ``medium`` (empty: none), ``lit`` (light no pass carries, in every
    channel)."""
    height, width = vacant.shape
    if not vacant[y, x] or not lit[y, x] or (medium.shape[0] > 0 and medium[y, x]):
        return False
    return ((y > 0 and source[y - 1, x]) or (y + 1 < height and source[y + 1, x])
            or (x > 0 and source[y, x - 1]) or (x + 1 < width and source[y, x + 1]))


@njit(**_JIT)
def sliver_claims(colour: np.ndarray, stored: np.ndarray, members: np.ndarray,
                  source: np.ndarray, vacant: np.ndarray, medium: np.ndarray,
                  lit: np.ndarray, claims: np.ndarray) -> int:
    """In place, on each pixel that may take a sliver of ``colour`` (3, H, W): ``claims``
    (3, H, W) += the light of its light passes (``stored[k]`` (K, 3, H, W) for k in
    ``members``, times ``colour``) on its 4 neighbours that are ``source`` (vacant: its
    colour is 0; medium: (H, W) bool or empty; lit: where light is left, (H, W) bool).
    Returns how many such pixels."""
    height, width = vacant.shape
    found = np.zeros(height, np.int64)
    for y in prange(height):
        for x in range(width):
            if not _is_sliver(source, vacant, medium, lit, y, x):
                continue
            found[y] += 1
            for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                yy, xx = y + dy, x + dx
                if 0 <= yy < height and 0 <= xx < width and source[yy, xx]:
                    for c in range(3):
                        light = 0.0
                        for k in members:
                            light += stored[k, c, yy, xx]
                        claims[c, y, x] += light * colour[c, yy, xx]
    return int(found.sum())


@njit(**_JIT)
def claim_share(residual: np.ndarray, claims: np.ndarray, out: np.ndarray) -> None:
    """``out`` (H, W): the share of ``claims`` (3, H, W) the light ``residual`` there can
    give, the same in every channel: ``max(min_c residual / claims, 0)`` where every
    channel claims some, else 0."""
    _, height, width = residual.shape
    for y in prange(height):
        for x in range(width):
            share = 0.0
            if claims[0, y, x] > 0.0 and claims[1, y, x] > 0.0 and claims[2, y, x] > 0.0:
                share = residual[0, y, x] / claims[0, y, x]
                for c in range(1, 3):
                    share = min(share, residual[c, y, x] / claims[c, y, x])
                share = max(share, 0.0)
            out[y, x] = share


@njit(**_JIT)
def lend_sliver(colour: np.ndarray, stored: np.ndarray, members: np.ndarray,
                source: np.ndarray, vacant: np.ndarray, medium: np.ndarray, lit: np.ndarray,
                share: np.ndarray, cap: float, residual: np.ndarray, out: np.ndarray) -> None:
    """On each pixel that may take a sliver of ``colour`` (as :func:`sliver_claims`):
    ``out`` (3, H, W; elsewhere ``colour``) = its 4 ``source`` neighbours' colour summed,
    times ``min(share, cap / their count)`` (at most ``cap`` times their mean), and in
    place ``residual -= `` the light its passes carry under it (their stored values there,
    filled from those neighbours, times ``out``)."""
    height, width = vacant.shape
    for y in prange(height):
        for x in range(width):
            lent = _is_sliver(source, vacant, medium, lit, y, x)
            if lent:
                count = 0
                for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                    yy, xx = y + dy, x + dx
                    count += 0 <= yy < height and 0 <= xx < width and source[yy, xx]
                part = min(share[y, x], cap / count)
                for c in range(3):
                    total = 0.0
                    for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                        yy, xx = y + dy, x + dx
                        if 0 <= yy < height and 0 <= xx < width and source[yy, xx]:
                            total += colour[c, yy, xx]
                    sliver = total * part
                    out[c, y, x] = sliver
                    light = 0.0
                    for k in members:
                        light += stored[k, c, y, x]
                    residual[c, y, x] -= light * sliver
            else:
                for c in range(3):
                    out[c, y, x] = colour[c, y, x]
