"""filters.lone_lights against plain float64 loops: the lone lit pixels of a G-buffer albedo,
their neighbours' albedo, the tent weights around them, the bound of the groups' shares and
the rest of the colour given to the lit group."""

from __future__ import annotations

import numpy as np

from svgf_cli.filters.context import MAX_REFLECTANCE
from svgf_cli.filters.lone_lights import (
    LONE_LIGHT_GAIN,
    LONE_LIGHT_RADIUS,
    bound_by_total,
    give_to_their_groups,
    lone_light_weights,
    lone_lights,
    neighbours_albedo,
)
from svgf_cli.filters.modulate import LIT_NEIGHBOURS_ROUGH

OFFSETS = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if dy or dx]


def _lit(albedo: np.ndarray, y: int, x: int) -> bool:
    values = albedo[:, y, x].astype(np.float64)
    return bool(np.any(np.isfinite(values) & (values > MAX_REFLECTANCE)))


def _inside(shape: tuple[int, ...], y: int, x: int) -> bool:
    return 0 <= y < shape[0] and 0 <= x < shape[1]


def lone_reference(albedo: np.ndarray, depth: np.ndarray) -> set[tuple[int, int]]:
    found = set()
    for y in range(depth.shape[0]):
        for x in range(depth.shape[1]):
            if depth[y, x] <= 0 or not _lit(albedo, y, x):
                continue
            around = sum(_lit(albedo, y + dy, x + dx) for dy, dx in OFFSETS
                         if _inside(depth.shape, y + dy, x + dx))
            if around < LIT_NEIGHBOURS_ROUGH:
                found.add((y, x))
    return found


def neighbours_reference(albedo: np.ndarray, depth: np.ndarray, pixels) -> np.ndarray:  # noqa: ANN001
    out = albedo.astype(np.float64)
    for y, x in zip(*pixels, strict=True):
        usable = []
        for dy, dx in OFFSETS:
            yy, xx = y + dy, x + dx
            if not _inside(depth.shape, yy, xx) or depth[yy, xx] <= 0:
                continue
            colour = albedo[:, yy, xx].astype(np.float64)
            if np.all(np.isfinite(colour)) and colour.max() <= MAX_REFLECTANCE:
                usable.append(colour)
        if usable:
            out[:, y, x] = np.mean(usable, axis=0)
    return out


def speckled_albedo(seed: int, h: int = 24, w: int = 30):  # noqa: ANN201
    """A reflectance albedo with lit pixels alone, in pairs and in a light's image, at the
    borders, on background, next to non-finite and background neighbours."""
    rng = np.random.default_rng(seed)
    albedo = rng.uniform(0.05, 0.9, (3, h, w)).astype(np.float32)
    depth = rng.uniform(1.0, 9.0, (h, w)).astype(np.float32)
    lit = rng.random((h, w)) < 0.06
    lit[10:13, 10:13] = True  # a light's image
    lit[0, 0] = lit[h - 1, w - 1] = True  # corners
    albedo[:, lit] = rng.uniform(2.0, 300.0, (3, lit.sum())).astype(np.float32)
    albedo[1, 5, 5] = np.nan
    albedo[0, 6, 7] = np.inf  # not lit: non-finite
    depth[rng.random((h, w)) < 0.05] = 0.0  # background
    return albedo, depth


def test_lone_lights_are_lit_pixels_with_too_few_lit_neighbours() -> None:
    for seed in range(4):
        albedo, depth = speckled_albedo(seed)
        ys, xs = lone_lights(albedo, depth)
        got = set(zip(ys.tolist(), xs.tolist(), strict=True))
        assert got == lone_reference(albedo, depth)
        assert got  # the fixture has some, and not the light's image
        assert not got & {(11, 11)}
    plain = np.full((3, 5, 6), 0.5, np.float32)
    ys, xs = lone_lights(plain, np.ones((5, 6), np.float32))
    assert ys.size == 0 and xs.size == 0


def test_neighbours_albedo_is_the_mean_of_the_reflectances_around() -> None:
    for seed in range(4):
        albedo, depth = speckled_albedo(seed)
        before = albedo.copy()
        pixels = lone_lights(albedo, depth)
        got = neighbours_albedo(albedo, depth, pixels)
        np.testing.assert_allclose(got, neighbours_reference(albedo, depth, pixels),
                                   rtol=1e-6, atol=0.0)
        assert got is not albedo
        np.testing.assert_array_equal(albedo, before)  # the frame's plane is not written
        changed = np.any(got != albedo, axis=0)
        changed[np.isnan(albedo).any(axis=0)] = False
        assert changed.sum() > 0 and np.all(got[:, changed] <= MAX_REFLECTANCE)
    albedo, depth = speckled_albedo(0)
    none = (np.zeros(0, np.intp), np.zeros(0, np.intp))
    assert neighbours_albedo(albedo, depth, none) is albedo


def weights_reference(shape: tuple[int, int], pixels) -> np.ndarray:  # noqa: ANN001
    side = 2 * LONE_LIGHT_RADIUS + 1
    out = np.zeros(shape)
    for y, x in zip(*pixels, strict=True):
        for yy in range(shape[0]):
            for xx in range(shape[1]):
                ty = max(0, side - abs(yy - y)) / side
                tx = max(0, side - abs(xx - x)) / side
                out[yy, xx] += ty * tx
    return np.minimum(LONE_LIGHT_GAIN * out, 1.0)


def test_lone_light_weights_are_a_capped_tent_around_each_light() -> None:
    shape = (40, 52)
    for pixels in ((np.array([20]), np.array([26])),
                   (np.array([0, 3, 39, 25]), np.array([0, 40, 51, 10]))):
        (rows, columns), weights = lone_light_weights(shape, pixels)
        full = np.zeros(shape)
        full[rows, columns] = weights
        np.testing.assert_allclose(full, weights_reference(shape, pixels), atol=1e-12)
    (rows, columns), weights = lone_light_weights(shape, (np.array([20]), np.array([26])))
    side = 2 * LONE_LIGHT_RADIUS + 1
    assert weights.max() == 1.0  # a tent's corner: the least above 0
    assert weights[0, 0] == weights.min() == LONE_LIGHT_GAIN / side ** 2
    assert rows == slice(20 - 2 * LONE_LIGHT_RADIUS, 20 + 2 * LONE_LIGHT_RADIUS + 1)
    assert lone_light_weights(shape, (np.zeros(0, np.intp), np.zeros(0, np.intp))) is None


def test_bound_by_total_holds_each_share_to_the_total_near_lone_lights() -> None:
    rng = np.random.default_rng(3)
    k, h, w = 3, 36, 44
    parts = rng.uniform(0.0, 4.0, (k, 3, h, w)).astype(np.float32)
    total = rng.uniform(-0.2, 2.0, (3, h, w)).astype(np.float32)
    pixels = (np.array([5, 30]), np.array([6, 20]))
    weights = weights_reference((h, w), pixels)
    cap = np.maximum(total.astype(np.float64), 0.0)
    want = parts - weights * np.maximum(parts - cap[None], 0.0)
    got = parts.copy()
    bound_by_total(got, total, pixels)
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-6)
    far = weights == 0.0
    assert far.any() and np.array_equal(got[:, :, far], parts[:, :, far])
    full = weights >= 1.0
    assert np.all(got[:, :, full] <= cap[:, full][None] + 1e-6)
    same = parts.copy()
    bound_by_total(same, total, (np.zeros(0, np.intp), np.zeros(0, np.intp)))
    assert np.array_equal(same, parts)


def test_give_to_their_groups_gives_the_colours_rest_to_the_lit_group() -> None:
    rng = np.random.default_rng(5)
    k, h, w = 3, 10, 12
    parts = rng.uniform(0.0, 1.0, (k, 3, h, w)).astype(np.float32)
    total = rng.uniform(-0.1, 4.0, (3, h, w)).astype(np.float32)
    inputs = [rng.uniform(0.0, 1.0, (3, h, w)).astype(np.float32) for _ in range(k)]
    pixels = (np.array([0, 4, 4, 9]), np.array([0, 5, 6, 11]))
    inputs[2][:, 4, 5] = 90.0  # a sample of group 2's light
    inputs[0][:, 4, 6] = inputs[1][:, 4, 6] = 50.0  # equals: the first
    want = parts.astype(np.float64)
    for y, x in zip(*pixels, strict=True):
        owner = int(np.argmax([inputs[j][:, y, x].astype(np.float64).sum() for j in range(k)]))
        for c in range(3):
            others = sum(want[j, c, y, x] for j in range(k) if j != owner)
            want[owner, c, y, x] = max(want[owner, c, y, x], max(total[c, y, x], 0.0) - others)
    got = parts.copy()
    give_to_their_groups(got, total, inputs, pixels)
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-6)
    assert got[2, 0, 4, 5] >= total[0, 4, 5] - got[0, 0, 4, 5] - got[1, 0, 4, 5] - 1e-6
    assert np.array_equal(got[1, :, 4, 6], parts[1, :, 4, 6])  # not the first of equals
    untouched = np.ones((h, w), bool)
    untouched[pixels] = False
    assert np.array_equal(got[:, :, untouched], parts[:, :, untouched])
    assert np.all(got >= parts)  # only raised
