"""Reflected albedo (``filters.reflected_albedo``): glossy light on diffuse-free objects
whose G-buffer albedo shows a sharp reflection is demodulated by that albedo."""

from __future__ import annotations

import numpy as np
import pytest

from svgf_cli.filters import reflected_albedo as ra
from svgf_cli.filters.denoiser import Denoiser
from svgf_cli.filters.params import PRESETS
from svgf_cli.frame import Frame, Signal

F32 = np.float32
HEIGHT, WIDTH = 24, 40


def _agreement_reference(gloss: np.ndarray, albedo: np.ndarray, candidates: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray]:
    """``albedo_agreement`` in float64 with explicit loops and clamped indices, and where a
    neighbour pair lies within 1e-5 of the factor (float32 may round either way there)."""
    clean = np.where(np.isfinite(albedo), albedo, 0.0).astype(np.float64)
    level = np.maximum(np.maximum(clean, gloss.astype(np.float64) * ra.FLOOR).mean(axis=0),
                       1e-4)
    height, width = level.shape
    agree = np.zeros((height, width))
    close = np.zeros((height, width), bool)
    for y in range(height):
        for x in range(width):
            if not candidates[y, x]:
                continue
            for dy in (-1, 0, 1):
                for dx in (-1, 0, 1):
                    if dy or dx:
                        other = level[min(max(y + dy, 0), height - 1),
                                      min(max(x + dx, 0), width - 1)]
                        ratio = max(other, level[y, x]) / min(other, level[y, x])
                        agree[y, x] += ratio < ra.AGREE
                        close[y, x] |= abs(ratio - ra.AGREE) < 1e-5
    return agree / 8.0, close


def _grey(plane: np.ndarray) -> np.ndarray:
    """A (3, H, W) colour with the (H, W) plane in every channel."""
    return np.ascontiguousarray(np.broadcast_to(plane, (3, *plane.shape)), dtype=F32)


def _checker(height: int, width: int, size: int, dark: float, light: float) -> np.ndarray:
    yy, xx = np.mgrid[0:height, 0:width]
    return np.where((yy // size + xx // size) % 2 == 0, light, dark).astype(F32)


def test_agreement_matches_the_float64_reference():
    rng = np.random.default_rng(5)
    gloss = np.full((3, 17, 23), 0.9, F32)
    albedo = np.empty((3, 17, 23), F32)
    albedo[:] = _checker(17, 23, 4, 0.1, 0.7)[None]  # patches: agreement near 1
    albedo[:, 9:, :] = rng.uniform(0.05, 0.9, (3, 8, 23))  # noise: agreement low
    albedo[:, 2, 3] = 0.0  # floored at 0.25 of the gloss colour
    albedo[0, 4, 4] = np.nan  # counted as 0, then floored
    candidates = rng.uniform(size=(17, 23)) < 0.7
    want, close = _agreement_reference(gloss, albedo, candidates)
    got = ra.albedo_agreement(gloss, albedo, candidates)
    assert got.dtype == F32
    np.testing.assert_array_equal(got[~close], want[~close])  # shares of 8: exact
    assert np.all(got[~candidates] == 0.0)
    assert got[:6][candidates[:6]].mean() > 0.7 > 0.5 > got[12:][candidates[12:]].mean()


def test_candidates_are_diffuse_free_pixels_whose_albedo_is_a_reflected_reflectance():
    gloss = np.full((3, 1, 9), 0.9, F32)
    albedo = np.full((3, 1, 9), 0.5, F32)
    diffuse = np.zeros((1, 9), F32)
    depth = np.ones((1, 9), F32)
    diffuse[0, 1] = 0.2  # a diffuse colour: the albedo AOV is not the reflection's
    albedo[1, 0, 2] = 0.9 * 1.05 + 2e-4  # above the gloss colour: no reflectance through it
    albedo[:, 0, 3] = 0.0  # no albedo (a renderer that writes none there)
    albedo[0, 0, 4] = np.nan  # non-finite
    depth[0, 5] = 0.0  # background
    gloss[:, 0, 6] = 0.0  # no gloss colour
    albedo[:, 0, 7] = 0.9 * 1.05  # at the limit: still a candidate
    # A reflected light: its emission in the albedo AOV and, put there by the reflected-light
    # stage, in the gloss colour too; no reflectance.
    albedo[:, 0, 8] = gloss[:, 0, 8] = 40.0
    got = ra.reflected_candidates(gloss, albedo, [_grey(diffuse)], depth)
    np.testing.assert_array_equal(got[0], [True, False, False, False, False, False, False,
                                           True, False])


def test_candidates_match_the_reference_on_random_pixels():
    rng = np.random.default_rng(11)
    shape = (37, 53)
    gloss = rng.uniform(0.0, 1.0, (3, *shape)).astype(F32)
    gloss[:, rng.uniform(size=shape) < 0.1] = 0.0
    albedo = (gloss * rng.uniform(0.0, 1.2, (3, *shape))).astype(F32)
    albedo[:, rng.uniform(size=shape) < 0.05] = 2.0
    albedo[1, rng.uniform(size=shape) < 0.05] = np.inf
    diffuse = np.where(rng.uniform(size=shape) < 0.3, 0.5, 0.0).astype(F32)
    depth = np.where(rng.uniform(size=shape) < 0.1, 0.0, 3.0).astype(F32)
    a = albedo.astype(np.float64)
    with np.errstate(invalid="ignore"):
        free = ((depth > 0) & (gloss.max(axis=0) > 0)
                & np.all(np.isfinite(a), axis=0) & (a.max(axis=0) > 0)
                & (a.max(axis=0) <= np.float64(F32(1.05)))
                & np.all(a <= gloss * F32(1.05) + F32(1e-4), axis=0))
    want = free & (diffuse < 1e-3)
    # Two diffuse colours: each must be dark; one channel above is enough to exclude.
    first = np.zeros((3, *shape), F32)
    second = np.zeros((3, *shape), F32)
    second[2] = diffuse
    got = ra.reflected_candidates(gloss, albedo, [first, second], depth)
    np.testing.assert_array_equal(got, want)
    assert 0 < got.sum() < got.size
    none = ra.reflected_candidates(gloss, albedo, [], depth)  # no diffuse signal at all
    np.testing.assert_array_equal(none, free)
    assert none.sum() > got.sum()


def test_object_weights_ramp_the_mean_agreement_of_each_object():
    agreement = np.zeros((4, 6), F32)
    agreement[0] = 1.0  # object 1: sharp
    agreement[1] = 0.5  # object 2: noise
    agreement[2] = (1.0, 1.0, 1.0, 0.75, 0.75, 0.75)  # object 3: mean 0.875
    agreement[3] = 0.0  # object 1 again, but no candidates there
    mesh = np.array([[1] * 6, [2] * 6, [3] * 6, [1] * 6], np.int32)
    candidates = np.ones((4, 6), bool)
    candidates[3] = False
    got = ra.object_weights(agreement, candidates, mesh)
    low, high = ra.RAMP
    np.testing.assert_array_equal(got[0], 1.0)
    np.testing.assert_array_equal(got[1], 0.0)
    assert low < 0.875 < high
    np.testing.assert_allclose(got[2], (0.875 - low) / (high - low), rtol=1e-6)
    assert 0.0 < got[2, 0] < 1.0
    np.testing.assert_array_equal(got[3], 0.0)
    assert ra.object_weights(agreement, np.zeros((4, 6), bool), mesh).max() == 0.0


def test_reflected_colour_mixes_geometrically_and_keeps_the_ends_exact():
    rng = np.random.default_rng(9)
    gloss = rng.uniform(0.2, 1.0, (3, 2, 5)).astype(F32)
    floored = rng.uniform(0.05, 1.0, (3, 2, 5)).astype(F32)
    weights = np.array([[0.0, 1.0, 0.5, 0.25, 0.0], [1.0, 0.75, 0.0, 1.0, 0.5]], F32)
    got = ra.reflected_colour(gloss, floored, weights)
    want = np.exp(weights.astype(np.float64) * np.log(floored.astype(np.float64))
                  + (1 - weights.astype(np.float64)) * np.log(gloss.astype(np.float64)))
    np.testing.assert_allclose(got, want, rtol=2e-6)
    np.testing.assert_array_equal(got[:, weights == 1.0], floored[:, weights == 1.0])
    np.testing.assert_array_equal(got[:, weights == 0.0], gloss[:, weights == 0.0])


def _mirror_scene(height: int = HEIGHT, width: int = WIDTH, seed: int = 0, shift: int = 0):
    """A sharp mirror (object 1, left half: it reflects a checker of 12 px squares, moved
    right by ``shift`` px) and a rough one (object 2, right half: one random reflected albedo
    per pixel), both diffuse-free."""
    rng = np.random.default_rng(seed)
    gloss = np.full((3, height, width), 0.9, F32)
    reflected = np.roll(_checker(height, width + 24, 12, 0.1, 0.8), shift, axis=1)[:, :width]
    half = width // 2
    reflected[:, half:] = rng.choice(np.array([0.1, 0.8], F32), (height, width - half))
    albedo = np.ascontiguousarray(gloss * reflected[None])
    mesh = np.ones((height, width), np.int32)
    mesh[:, half:] = 2
    return gloss, albedo, reflected, mesh


def test_sharp_mirrors_take_the_albedo_rough_ones_keep_their_gloss_colour():
    gloss, albedo, _, mesh = _mirror_scene()
    diffuse = np.zeros((HEIGHT, WIDTH), F32)
    depth = np.ones((HEIGHT, WIDTH), F32)
    found = ra.reflected_albedo(gloss, albedo, [_grey(diffuse)], depth, mesh)
    assert found is not None
    colour, changed, sharp = found
    half = WIDTH // 2
    assert changed == HEIGHT * half
    np.testing.assert_array_equal(sharp.holds(np.array([0, 1, 2, 3])), [False, True, False, False])
    np.testing.assert_array_equal(colour[:, :, :half],
                                  np.maximum(albedo, F32(ra.FLOOR) * gloss)[:, :, :half])
    np.testing.assert_array_equal(colour[:, :, half:], gloss[:, :, half:])
    # The caller's planes are left alone; with a diffuse colour there is nothing to do.
    assert colour is not gloss and np.all(gloss == 0.9)
    assert ra.reflected_albedo(gloss, albedo, [_grey(diffuse + 0.5)], depth, mesh) is None
    # A renderer whose albedo AOV is the gloss colour itself: every object coherent, and the
    # colour the same.
    same = ra.reflected_albedo(gloss, gloss.copy(), [], depth, mesh)
    assert same is not None
    np.testing.assert_array_equal(same[0], gloss)


def test_only_the_objects_pixels_change_and_a_frame_without_mirrors_is_left_alone():
    gloss, albedo, _, mesh = _mirror_scene(40, 60, seed=2)
    diffuse = np.full((40, 60), 0.5, F32)
    diffuse[8:32, 7:50] = 0.0  # the mirrors' visible part only
    depth = np.ones((40, 60), F32)
    found = ra.reflected_albedo(gloss, albedo, [_grey(diffuse)], depth, mesh)
    assert found is not None
    candidates = ra.reflected_candidates(gloss, albedo, [_grey(diffuse)], depth)
    weights = ra.object_weights(ra.albedo_agreement(gloss, albedo, candidates), candidates,
                                mesh)
    changed = weights > 0
    assert found[1] == changed.sum() > 0 and not np.any(changed & ~candidates)
    np.testing.assert_array_equal(found[0][:, ~changed], gloss[:, ~changed])
    want = ra.reflected_colour(gloss, ra.floored_albedo(gloss, albedo), weights)
    np.testing.assert_allclose(found[0][:, changed], want[:, changed], rtol=1e-6)
    assert 0.0 < weights.max() < 1.0  # the mixed colour, not an end
    # Rough mirrors only: nothing to change, no copy made.
    rough = mesh == 2
    assert ra.reflected_albedo(gloss, albedo, [_grey(np.where(rough, 0.0, 0.5))], depth,
                               mesh) is None
    # Object ids as hashes (beyond the dense table) take the sorting path: the same colour.
    hashed = ra.reflected_albedo(gloss, albedo, [_grey(diffuse)], depth,
                                 mesh * np.int32(1_000_003) - 7)
    assert hashed is not None and hashed[1] == found[1]
    np.testing.assert_allclose(hashed[0], found[0], rtol=1e-6)
    assert found[2].holds(np.array([1]))[0] and not found[2].holds(np.array([2]))[0]
    assert hashed[2].holds(np.array([1_000_003 - 7, 2 * 1_000_003 - 7])).tolist() == [True, False]


def test_sharp_objects_by_id():
    table = ra._sharp_table(np.array([5, 7], np.int64))
    ids = np.array([[4, 5, 6], [7, 8, -3]])
    np.testing.assert_array_equal(table.holds(ids), [[False, True, False], [True, False, False]])
    # Ids as hashes too far apart for a table: no object counts as sharp (the rough rule).
    spread = ra._sharp_table(np.array([3, 3 + (1 << 20)], np.int64))
    assert spread.table.size == 0 and not spread.holds(np.array([3, 3 + (1 << 20)])).any()


def _mirror_frame(t: int) -> Frame:
    """Frame ``t`` of a still diffuse-free mirror reflecting a textured, evenly lit floor that
    slides 2 px a frame (the camera or the floor moves; the mirror does not): glossy light =
    gloss colour x reflected albedo x irradiance (1.5) x 1-spp noise."""
    gloss, albedo, reflected, mesh = _mirror_scene(shift=2 * t)
    rng = np.random.default_rng(200 + t)
    noise = rng.exponential(1.0, (HEIGHT, WIDTH)).astype(F32)
    glossy = np.ascontiguousarray(albedo * F32(1.5) * noise[None])
    black = np.zeros((3, HEIGHT, WIDTH), F32)
    normal = np.zeros((3, HEIGHT, WIDTH), F32)
    normal[2] = 1.0
    return Frame(
        signals=[Signal("diffuse", black.copy(), black.copy()),
                 Signal("glossy", glossy, gloss.copy(), glossy=True)],
        normal=normal, depth=np.full((HEIGHT, WIDTH), 4.0, F32),
        motion=np.zeros((2, HEIGHT, WIDTH), F32), mesh_id=mesh, albedo=albedo,
    )


def _mirror_error(params) -> tuple[float, dict[str, int]]:
    """relMSE of the sharp mirror's output (frame 6) against its truth, and the counts."""
    denoiser = Denoiser(params)
    for t in range(6):
        out = denoiser.process(_mirror_frame(t))
    truth = _mirror_scene(shift=10)[1] * F32(1.5)
    half = WIDTH // 2
    err = (out.color - truth) ** 2 / (truth ** 2 + 1e-2)
    return float(err[:, 2:-2, 2:half - 3].mean()), out.counts


@pytest.mark.parametrize("preset", ["default"])
def test_a_sharp_mirror_is_filtered_by_the_texture_it_reflects(preset: str):
    """Demodulated by the flat gloss colour the reflected checker is in the light, and the
    history of a sliding reflection is a different checker, which the glossy clamp cuts
    short: 1-spp noise. Demodulated by the reflected albedo the light is the floor's even
    irradiance, whose history stays valid as the reflection slides."""
    on, counts = _mirror_error(PRESETS[preset])
    off, counts_off = _mirror_error(PRESETS[preset].replace(reflected_albedo=False))
    assert counts["reflected_albedo.glossy"] == HEIGHT * (WIDTH // 2)
    assert "reflected_albedo.glossy" not in counts_off
    assert on < 0.5 * off
    assert PRESETS["paper"].reflected_albedo is False
