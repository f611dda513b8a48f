"""Where an object turns, its light follows its translation, not its material points.

Motion vectors follow a surface's material point, which suits a texture. A demodulated
light is not a property of the material point but of where the point is and which way it
faces: on a ball that rolls, a point turns away from the light every frame, so the history
the motion vectors fetch differs from this frame's light, and anti-lag (correctly) drops it
frame after frame. The history that fits is the one at the same place relative to the
object: last frame's pixel shifted by the object's own translation.

These kernels find those pixels and that shift; ``filters.stages.object_history`` resamples
the history there and keeps it where anti-lag trusts it more than the material point's.

* :func:`turn_evidence`: where the material point's normal last frame differs from the
  pixel's now (a kernel over the frame: most frames have no turning object, and finding
  that must cost next to nothing);
* :func:`refine_translation`: an object's translation, from the mean motion of its pixels
  (the motion of its centroid in screen space; a turn about the centroid averages out)
  refined by matching its normals;
* :func:`turning_pixels`: the pixels whose normal last frame at the translated position is
  much closer to their normal now than at the material point's position: an object turning
  about its own axis whose shape looks the same after the turn (a ball, a wheel, a
  cylinder). A face of a turning box fails the test (the translated position faced another
  way), as does everything that only translates or stands still (the two positions agree).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from svgf_cli.filters.fastmath import FASTMATH

F32 = np.float32
# Objects with fewer pixels than this have no meaningful mean motion.
MIN_OBJECT_PIXELS = 16
# The material point must have moved at least this far (pixels) from the object's
# translation: otherwise both histories are the same one.
MIN_TURN_SHIFT = 0.5
# The translated position's normal difference must be below this share of the material
# point's (squared lengths: 1/4 is half the difference).
NORMAL_GAIN = 0.25
# ... and the material point's normal must have turned by more than this (squared length
# of the normals' difference: 0.01 is about 6 degrees).
MIN_NORMAL_TURN = 0.01
# An object turns when at least this share of its pixels with a history of their own turn.
MIN_TURNING_SHARE = 0.25
# How far (pixels) the translation is searched around the mean motion, and on how many of
# the object's pixels at most (a regular subsample of them).
SEARCH_RADIUS = 3
SEARCH_PIXELS = 4096
# Then in steps of FINE_STEP pixels, FINE_RADIUS steps either way.
FINE_STEP = 0.25
FINE_RADIUS = 3


def _nearest_normal_distance(
    xs: np.ndarray, ys: np.ndarray, px: np.ndarray, py: np.ndarray, normal: np.ndarray,
    prev_normal: np.ndarray, prev_mesh_id: np.ndarray, mesh: np.ndarray,
) -> np.ndarray:
    """Squared distance between the normal at pixels ``(xs, ys)`` and last frame's at the
    nearest pixel to ``(px, py)``; infinite off the image or on another object."""
    height, width = prev_mesh_id.shape
    tx = np.floor(px + 0.5).astype(np.int64)
    ty = np.floor(py + 0.5).astype(np.int64)
    inside = (tx >= 0) & (ty >= 0) & (tx < width) & (ty < height)
    tx = np.clip(tx, 0, width - 1)
    ty = np.clip(ty, 0, height - 1)
    diff = normal[:, ys, xs] - prev_normal[:, ty, tx]
    distance = np.einsum("ck,ck->k", diff, diff)
    same = inside & (prev_mesh_id[ty, tx] == mesh)
    return np.where(same, distance, np.inf)


def refine_translation(
    xs: np.ndarray, ys: np.ndarray, translation: tuple[float, float], normal: np.ndarray,
    prev_normal: np.ndarray, prev_mesh_id: np.ndarray, mesh: int,
) -> tuple[float, float]:
    """The shift near ``translation`` whose taps' normals best match the pixels
    ``(xs, ys)``: the mean of ``min(|n(p) - n'(p + t)|^2, 1)`` over (at most
    ``SEARCH_PIXELS`` of) them is least. First over whole shifts within ``SEARCH_RADIUS``
    of it with the nearest taps; then, around the mean (where it lies nearest to the best
    whole shift) or that shift, in quarter pixels within ``FINE_RADIUS`` with bilinear
    taps, to a finer position by a parabola through the best and its neighbours on each
    axis.

    The mean motion of the visible pixels is the centroid's motion only where the object is
    seen whole and symmetric about its axis; occluded or seen obliquely it is off by a pixel
    or two, which is a turn of a few degrees at the object's rim."""
    stride = max(1, xs.size // SEARCH_PIXELS)
    xs, ys = xs[::stride], ys[::stride]
    # Whole shifts: the nearest taps of a shift between them are those of one of them.
    x0, y0 = round(translation[0]), round(translation[1])
    whole = [(x0 + i, y0 + j) for j in range(-SEARCH_RADIUS, SEARCH_RADIUS + 1)
             for i in range(-SEARCH_RADIUS, SEARCH_RADIUS + 1)]
    costs = [np.minimum(_nearest_normal_distance(xs, ys, xs + i, ys + j, normal, prev_normal,
                                                 prev_mesh_id, mesh), 1.0).mean()
             for i, j in whole]
    best = whole[int(np.argmin(costs))]
    centre = translation if best == (x0, y0) else best
    steps = np.arange(-FINE_RADIUS, FINE_RADIUS + 1) * FINE_STEP
    cost = np.empty((steps.size, steps.size))
    for j, dy in enumerate(steps):
        for i, dx in enumerate(steps):
            distance = _bilinear_normal_distance(xs, ys, xs + (centre[0] + dx),
                                                 ys + (centre[1] + dy), normal, prev_normal,
                                                 prev_mesh_id, mesh)
            cost[j, i] = np.minimum(distance, 1.0).mean()
    j, i = np.unravel_index(int(np.argmin(cost)), cost.shape)
    return (centre[0] + steps[i] + FINE_STEP * _vertex(cost[j, i - 1:i + 2]),
            centre[1] + steps[j] + FINE_STEP * _vertex(cost[j - 1:j + 2, i]))


def _bilinear_normal_distance(
    xs: np.ndarray, ys: np.ndarray, px: np.ndarray, py: np.ndarray, normal: np.ndarray,
    prev_normal: np.ndarray, prev_mesh_id: np.ndarray, mesh: int,
) -> np.ndarray:
    """Squared distance between the normal at pixels ``(xs, ys)`` and last frame's normal
    interpolated bilinearly at ``(px, py)``; infinite where a tap is off the image or on
    another object."""
    height, width = prev_mesh_id.shape
    fx, fy = np.floor(px), np.floor(py)
    tx, ty = fx.astype(np.int64), fy.astype(np.int64)
    wx, wy = px - fx, py - fy
    inside = (tx >= 0) & (ty >= 0) & (tx + 1 < width) & (ty + 1 < height)
    tx, ty = np.clip(tx, 0, width - 2), np.clip(ty, 0, height - 2)
    same = inside.copy()
    blended = np.zeros((3, xs.size))
    for oy, ox, w in ((0, 0, (1 - wx) * (1 - wy)), (0, 1, wx * (1 - wy)),
                      (1, 0, (1 - wx) * wy), (1, 1, wx * wy)):
        same &= prev_mesh_id[ty + oy, tx + ox] == mesh
        blended += w * prev_normal[:, ty + oy, tx + ox]
    diff = normal[:, ys, xs] - blended
    return np.where(same, np.einsum("ck,ck->k", diff, diff), np.inf)


def _vertex(three: np.ndarray) -> float:
    """The offset (-0.5 to 0.5) of the minimum of the parabola through three costs around the
    least one; 0 at the search's border or where the costs are flat."""
    if three.size != 3:
        return 0.0
    curvature = three[0] - 2.0 * three[1] + three[2]
    if curvature <= 0.0:
        return 0.0
    return float(np.clip(0.5 * (three[0] - three[2]) / curvature, -0.5, 0.5))


@njit(parallel=True, fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False,
      error_model="numpy")
def turn_evidence(
    motion: np.ndarray, normal: np.ndarray, mesh_id: np.ndarray, prev_normal: np.ndarray,
    prev_mesh_id: np.ndarray, where: np.ndarray, min_turn: np.float32, out: np.ndarray,
) -> None:
    """Per pixel of ``where`` (uint8 (H, W)) with an object id: ``out`` (uint8 (H, W)) 1
    where last frame's pixel nearest to the material point's position ``p + m(p)`` holds
    the same object, 2 where its normal also differs from this one's by
    ``|n(p) - n'(p + m(p))|^2 > min_turn``; 0 elsewhere."""
    height, width = mesh_id.shape
    fwidth, fheight = np.float32(width), np.float32(height)
    for y in prange(height):
        ids, inside, result = mesh_id[y], where[y], out[y]
        mx, my = motion[0, y], motion[1, y]
        fy = np.float32(y) + np.float32(0.5)
        for x in range(width):
            result[x] = 0
            mesh = ids[x]
            if inside[x] == 0 or mesh < 0:
                continue
            px = np.floor(np.float32(x) + mx[x] + np.float32(0.5))
            py = np.floor(fy + my[x])
            # Also false for NaN positions.
            if not (px >= 0.0 and py >= 0.0 and px < fwidth and py < fheight):
                continue
            # Unsigned: no negative-index wrap-around on the loads.
            tx, ty = np.uint64(px), np.uint64(py)
            if prev_mesh_id[ty, tx] != mesh:
                continue
            distance = np.float32(0.0)
            for c in range(3):
                d = normal[c, y, x] - prev_normal[c, ty, tx]
                distance += d * d
            result[x] = 2 if distance > min_turn else 1


def turning_pixels(
    motion: np.ndarray,
    normal: np.ndarray,
    mesh_id: np.ndarray,
    prev_normal: np.ndarray,
    prev_mesh_id: np.ndarray,
    where: np.ndarray,
) -> np.ndarray:
    """(2, H, W) float32: at the pixels of ``where`` (bool (H, W)) on a turning object (see
    the module), the object's translation as a backward motion; NaN elsewhere.

    An object ``k`` turns when at least ``MIN_TURNING_SHARE`` of its pixels whose material
    point was on it last frame (:func:`turn_evidence`) faced a way more than
    ``MIN_NORMAL_TURN`` from now. Its translation is the mean motion ``t_k`` of its pixels,
    refined by :func:`refine_translation` over its pixels with
    ``|m(p) - t_k| > MIN_TURN_SHIFT`` (none: it does not move as a turn would). Such a pixel
    takes it when ``|n(p) - n'(p + t_k)|^2 < NORMAL_GAIN |n(p) - n'(p + m(p))|^2`` (last
    frame's normal nearest to the translated position much closer to this one than at the
    material point's, both on object ``k``, the latter more than ``MIN_NORMAL_TURN`` off)
    and the object still turns by the same share with that test; then its pixels turned
    into view since (their material point was not on it last frame) take it too where
    ``|n(p) - n'(p + t_k)|^2 < MIN_NORMAL_TURN``.
    """
    out = np.full(motion.shape, np.nan, dtype=F32)
    evidence = np.empty(mesh_id.shape, np.uint8)
    turn_evidence(motion, normal, mesh_id, prev_normal, prev_mesh_id,
                  where.view(np.uint8), F32(MIN_NORMAL_TURN), evidence)
    for k in np.unique(mesh_id[evidence == 2]).tolist():
        pixels = (mesh_id == k) & where
        own = evidence[pixels]
        if np.count_nonzero(own == 2) < MIN_TURNING_SHARE * np.count_nonzero(own):
            continue  # not a turning object: a surface seen with parallax, a deforming one
        ky, kx = np.nonzero(pixels)
        if ky.size < MIN_OBJECT_PIXELS:
            continue
        mx, my = motion[0, ky, kx], motion[1, ky, kx]
        mean = (float(mx.mean(dtype=np.float64)), float(my.mean(dtype=np.float64)))
        shifted = (mx - mean[0]) ** 2 + (my - mean[1]) ** 2 > MIN_TURN_SHIFT**2
        if not shifted.any():
            continue
        tx, ty = refine_translation(kx[shifted], ky[shifted], mean, normal, prev_normal,
                                    prev_mesh_id, k)
        shifted = (mx - tx) ** 2 + (my - ty) ** 2 > MIN_TURN_SHIFT**2
        ky, kx, mx, my = ky[shifted], kx[shifted], mx[shifted], my[shifted]
        material = _nearest_normal_distance(kx, ky, kx + mx, ky + my, normal, prev_normal,
                                            prev_mesh_id, k)
        translated = _nearest_normal_distance(kx, ky, kx + tx, ky + ty, normal, prev_normal,
                                              prev_mesh_id, k)
        seen = np.isfinite(material)
        turned = seen & (material > MIN_NORMAL_TURN) & (translated < NORMAL_GAIN * material)
        if np.count_nonzero(turned) < MIN_TURNING_SHARE * np.count_nonzero(seen):
            continue  # a box that turns: its faces face another way at the translation too
        turned |= ~seen & (translated < MIN_NORMAL_TURN)
        out[0, ky[turned], kx[turned]] = tx
        out[1, ky[turned], kx[turned]] = ty
    return out
