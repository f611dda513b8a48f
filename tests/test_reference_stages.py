"""Each kernel of the temporal half alone against the float64 reference (``reference_svgf``).

Inputs are built to take every branch: background, image borders, black and one-channel-
black albedo, emission, depth edges inside one mesh, mesh-id changes at equal depth,
normal creases and grazing normals, disocclusions, taps outside the image, the bilinear
path, the 3x3 fallback (also the one reached because the passing bilinear weight is below
0.01), non-finite motion. Each test asserts that its inputs really reach those branches.

Tolerances: the kernels run in float32 (relative rounding 6e-8 per operation, a few dozen
operations per output) and the spatial-variance weights use ``fast_exp`` (relative error
< 4e-6). Pure arithmetic stages are held to 1e-6 relative, the weighted ones to 2e-5,
which is 10 to 100 times tighter than any of the planted bugs the suite must catch
(``tests/mutants/plant.py``), whose effects are percent-level or more.
"""

from __future__ import annotations

import numpy as np
import pytest
import reference_svgf as ref
from moving_scene import scene_frame

from svgf_cli.filters.clamp import firefly_clamp, history_clamp
from svgf_cli.filters.edges import normal_squarings
from svgf_cli.filters.gradients import depth_gradients, normal_gradient, unit_normals
from svgf_cli.filters.modulate import (
    demodulate,
    filter_normals,
    remodulate,
    remodulate_add,
    restore_background,
)
from svgf_cli.filters.reproject import accumulate, reproject
from svgf_cli.filters.taa import taa_resolve
from svgf_cli.filters.variance import (
    boost_short_history,
    estimate_variance,
    spatial_variance,
    temporal_variance,
)
from svgf_cli.frame import Frame

F32 = np.float32
EPS = 1e-3  # albedo floor (the default)


def _close(got: np.ndarray, want: np.ndarray, rtol: float, what: str = "",
           scale: float | None = None) -> None:
    """``|got - want| <= rtol * (|want| + scale)``: relative, with an absolute floor at the
    quantity's scale (default ``max|want|``: values that cancel to near 0 are held to the
    same absolute precision as the largest ones). A variance ``m2 - m1^2`` is a difference
    of moments: its scale is the moments' (float32 rounds ``m2``, not the difference)."""
    want = np.asarray(want, dtype=np.float64)
    if scale is None:
        scale = float(np.max(np.abs(want))) if want.size else 0.0
    np.testing.assert_allclose(got, want, rtol=rtol, atol=rtol * scale, err_msg=what)


# --------------------------------------------------------------------------- kernels
# Thin adapters: the only place that knows the kernels' calling conventions.
def kernel_geometry(frame: Frame) -> dict[str, np.ndarray]:
    height, width = frame.depth.shape
    planes = {name: np.zeros((height, width), F32)
              for name in ("ddx", "ddy", "depth_slope", "normal_width")}
    unit = np.zeros((3, height, width), F32)
    unit_normals(frame.normal, frame.depth, unit)
    depth_gradients(frame.depth, planes["ddx"], planes["ddy"], planes["depth_slope"])
    normal_gradient(unit, frame.depth, planes["normal_width"])
    negated = np.zeros_like(unit)
    filter_normals(unit, frame.albedo, F32(EPS), negated)
    return {**planes, "unit_normal": unit, "filter_normal": negated, "depth": frame.depth}


def as_reference(g: dict[str, np.ndarray]) -> ref.Geometry:
    """The kernels' float32 geometry as the reference's, so a stage is compared alone."""
    return ref.Geometry(*(g[k].astype(np.float64) for k in (
        "depth", "unit_normal", "ddx", "ddy", "depth_slope", "normal_width", "filter_normal")))


def kernel_demodulated(frame: Frame) -> np.ndarray:
    signals = frame.signals()
    out = np.zeros((len(signals), *frame.albedo.shape), F32)
    emission = frame.emission if frame.emission is not None else frame.albedo
    for index, (_, signal) in enumerate(signals):
        demodulate(signal, emission, frame.emission is not None and index == 0, frame.albedo,
                   F32(EPS), out[index])
    return out


# --------------------------------------------------------------------------- 0 geometry
def _rough_geometry() -> tuple[np.ndarray, np.ndarray]:
    """Integer depths (ties between one-sided differences, ridges with opposite-sign sides),
    background holes and edges, random and degenerate normals."""
    rng = np.random.default_rng(4)
    height, width = 9, 11
    depth = rng.integers(1, 6, (height, width)).astype(F32)
    depth[0, :3] = 0.0
    depth[4, 5] = 0.0  # isolated hole: neighbours lose one side on each axis
    depth[:, -1] = 0.0
    depth[6, 2] = 0.0
    depth[7, 2] = 0.0
    normal = rng.normal(size=(3, height, width)).astype(F32)
    # Degenerate normals on surface pixels, next to the background column so that their
    # one-sided normal differences (unit length on both sides) are not a tie.
    normal[:, 2, -2] = 0.0
    normal[:, 3, -2] = 1e-7
    return depth, normal


@pytest.mark.parametrize("source", ["rough", "scene"])
def test_geometry_matches_reference(source: str) -> None:
    if source == "rough":
        depth, normal = _rough_geometry()
        albedo = np.full((3, *depth.shape), 0.5, F32)
    else:
        frame = scene_frame(3)
        depth, normal, albedo = frame.depth, frame.normal, frame.albedo
    frame = Frame(albedo=albedo, normal=normal, depth=depth,
                  motion=np.zeros((2, *depth.shape), F32),
                  mesh_id=np.ones(depth.shape, np.int32), color=albedo)
    got = kernel_geometry(frame)
    unit = ref.unit_normals(normal, depth)
    _close(got["unit_normal"], unit, 1e-6, "unit normals")
    ddx, ddy, slope = ref.depth_gradients(depth)
    _close(got["ddx"], ddx, 1e-6, "ddx")
    _close(got["ddy"], ddy, 1e-6, "ddy")
    _close(got["depth_slope"], slope, 1e-6, "slope")
    # The normal gradient is compared on the kernel's own unit normals (stage alone).
    _close(got["normal_width"], ref.normal_gradient(got["unit_normal"], depth), 1e-6, "fwidth")
    _close(got["filter_normal"], ref.filter_normals(got["unit_normal"], albedo, EPS), 0.0)
    if source == "rough":
        # The branches: ties between equal-magnitude sides with opposite signs, pixels with
        # one usable side, pixels with none (zero derivative), degenerate normals.
        left = np.abs(depth[1:-1, 1:-2] - depth[1:-1, :-3])
        right = np.abs(depth[1:-1, 2:-1] - depth[1:-1, 1:-2])
        assert np.any((left == right) & (left > 0))
        assert np.any((got["ddx"] == 0) & (depth > 0) & (np.roll(depth, 1, 1) == 0))
        assert np.all(got["unit_normal"][:, 2:4, -2] == 0) and np.all(depth[2:4, -2] > 0)


# --------------------------------------------------------------------------- 1 demodulation
@pytest.mark.parametrize("split", [True, False])
def test_demodulation_round_trip_matches_reference(split: bool) -> None:
    frame = scene_frame(2, split=split)
    black = ref.not_demodulated(frame.albedo, EPS)
    assert black.any() and np.any((frame.albedo < EPS).any(axis=0) & ~black)
    assert np.any(frame.emission > 0) and np.any(frame.depth <= 0)
    got = kernel_demodulated(frame)
    for index, (_, signal) in enumerate(frame.signals()):
        emission = frame.emission if index == 0 else None
        want = ref.demodulate(signal, emission, frame.albedo, EPS)
        _close(got[index], want, 1e-6, "demodulate")
        back = np.empty_like(signal)
        remodulate(got[index], frame.emission, index == 0, frame.albedo, F32(EPS), back)
        _close(back, ref.remodulate(got[index], emission, frame.albedo, EPS), 1e-6)
        np.testing.assert_allclose(back, signal, rtol=1e-5, atol=1e-6)  # exact inverse
        restored = back + F32(7.0)
        restore_background(restored, signal, frame.depth)
        _close(restored, ref.radiance_with_background(back + 7.0, signal, frame.depth), 1e-6)
    # Remodulation, background restore and the sum of the signals in one pass.
    total = np.zeros_like(frame.albedo)
    for index, (_, signal) in enumerate(frame.signals()):
        remodulate_add(got[index], signal, frame.emission, index == 0, frame.albedo, F32(EPS),
                       frame.depth, total)
    want = sum(ref.radiance_with_background(
        ref.remodulate(got[i], frame.emission if i == 0 else None, frame.albedo, EPS), signal,
        frame.depth) for i, (_, signal) in enumerate(frame.signals()))
    _close(total, want, 1e-6, "remodulate_add")


# --------------------------------------------------------------------------- clamps
def _spiky_illumination(seed: int, height: int = 9, width: int = 10) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    illumination = rng.gamma(2.0, 0.5, (2, 3, height, width)).astype(F32)
    illumination[0, :, 4, 4] *= 40.0  # fireflies, one at the border
    illumination[1, :, 0, 7] *= 25.0
    depth = np.full((height, width), 5.0, F32)
    depth[2, :4] = 0.0  # background: skipped and left out of the neighbour statistics
    depth[7, 0] = 0.0
    depth[8, 1] = 0.0
    return illumination, depth


def test_firefly_clamp_matches_reference() -> None:
    illumination, depth = _spiky_illumination(1)
    out = np.empty_like(illumination)
    firefly_clamp(illumination, depth, F32(1.5), out)
    want = ref.firefly_clamp(illumination, depth, 1.5)
    _close(out, want, 2e-5, "firefly clamp")
    changed = np.any(want != illumination, axis=1)
    assert changed[0, 4, 4] and changed[1, 0, 7] and changed.sum() > 10
    assert np.all(want[:, :, depth <= 0] == illumination[:, :, depth <= 0])


def test_history_clamp_matches_reference() -> None:
    current, depth = _spiky_illumination(2)
    rng = np.random.default_rng(3)
    history = (current * rng.uniform(0.2, 3.0, current.shape)).astype(F32)
    length = rng.choice([0.0, 1.0, 2.5, 8.0], size=depth.shape).astype(F32)
    got = history.copy()
    history_clamp(got, length, current, depth, F32(1.0))
    want = ref.history_clamp(history, length, current, depth, 1.0)
    _close(got, want, 2e-5, "history clamp")
    assert np.sum(want != history) > 50  # it clamps, ...
    untouched = (length <= 0) | (depth <= 0)
    assert untouched.any() and np.all(want[:, :, untouched] == history[:, :, untouched])


# --------------------------------------------------------------------------- 2 reprojection
def _history_for(prev: Frame, seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    shape = prev.depth.shape
    return {
        "illumination": rng.gamma(2.0, 0.5, (2, 3, *shape)).astype(F32),
        "moments": rng.gamma(2.0, 0.5, (2, 2, *shape)).astype(F32),
        "length": rng.choice([1.0, 2.0, 3.5, 6.0, 32.0], size=shape).astype(F32),
    }


def _run_reproject(prev: Frame, cur: Frame, history: dict[str, np.ndarray],
                   tolerances: tuple[float, float, float] = (10.0, 0.002, 16.0)):
    """The kernel and the reference on the same float32 geometry; returns both."""
    g_prev, g_cur = kernel_geometry(prev), kernel_geometry(cur)
    height, width = cur.depth.shape
    out = (np.full((2, 3, height, width), np.nan, F32),
           np.full((2, 2, height, width), np.nan, F32),
           np.full((height, width), np.nan, F32))
    reproject(cur.motion, cur.depth, g_cur["unit_normal"], cur.mesh_id, g_cur["depth_slope"],
              g_cur["normal_width"], prev.depth, g_prev["unit_normal"], prev.mesh_id,
              history["illumination"], history["moments"], history["length"],
              *(F32(t) for t in tolerances), *out)
    previous = ref.History(history["illumination"].astype(np.float64),
                           history["moments"].astype(np.float64),
                           history["length"].astype(np.float64),
                           prev.depth.astype(np.float64),
                           g_prev["unit_normal"].astype(np.float64), prev.mesh_id)
    want = ref.reproject(cur.motion, as_reference(g_cur), cur.mesh_id, previous, *tolerances)
    return out, want


def _assert_reprojection_matches(out, want: ref.Reprojected) -> None:
    illumination, moments, length = out
    _close(length, want.history_length, 1e-6, "history length")
    _close(illumination, want.illumination, 1e-6, "illumination")
    _close(moments, want.moments, 1e-6, "moments")


def test_reprojection_of_the_moving_scene_matches_reference() -> None:
    """Disocclusions behind the object, the mesh-id-only edge of the sticker, the depth step
    and the normal crease inside the object, the left column's taps outside the image."""
    for t in (1, 2, 4):
        prev, cur = scene_frame(t - 1), scene_frame(t)
        out, want = _run_reproject(prev, cur, _history_for(prev, seed=t))
        _assert_reprojection_matches(out, want)
        surface = cur.depth > 0
        assert np.sum(want.path == ref.BILINEAR) > 250
        assert np.sum(want.path == ref.FALLBACK) >= 5
        if t % 2 == 0:
            assert np.sum((want.path == ref.REJECTED) & surface) >= 2


def test_reprojection_with_perturbed_history_takes_every_test() -> None:
    """The scene with its previous frame perturbed (ids, depths, normals, background pixels)
    and sub-pixel motion jitter: every test rejects somewhere, on its own."""
    rng = np.random.default_rng(8)
    prev, cur = scene_frame(2), scene_frame(3)
    shape = prev.depth.shape
    surface = prev.depth > 0
    changed_id = rng.random(shape) < 0.08
    prev.mesh_id[changed_id & surface] += 5
    nearer = rng.random(shape) < 0.08
    prev.depth[nearer & surface] *= F32(0.9)
    tilted = rng.random(shape) < 0.08
    prev.normal[:, tilted & surface] = np.array([0.0, 0.7, 0.7], F32)[:, None]
    holes = rng.random(shape) < 0.04
    prev.depth[holes] = 0.0
    cur.motion += rng.uniform(-0.45, 0.45, cur.motion.shape).astype(F32)
    cur.motion[:, 5, 0] = np.nan
    cur.motion[0, 6, 1] = np.inf
    cur.motion[1, 7, 1] = -1e30
    out, want = _run_reproject(prev, cur, _history_for(prev, seed=9))
    _assert_reprojection_matches(out, want)
    # Each test alone must reject some tap: loosen one tolerance at a time.
    for tolerances in ((1e9, 1e9, 16.0), (10.0, 0.002, 1e9)):
        loose_out, loose_want = _run_reproject(prev, cur, _history_for(prev, seed=9), tolerances)
        _assert_reprojection_matches(loose_out, loose_want)
        assert np.sum(loose_want.history_length != want.history_length) > 5
    assert np.sum(want.path == ref.FALLBACK) > 10
    assert np.all(want.history_length[5:8, :2][np.isnan(cur.motion[0, 5:8, :2])] == 0)


def _flat(width: int, height: int, **planes: np.ndarray) -> Frame:
    depth = np.full((height, width), 5.0, F32)
    normal = np.zeros((3, height, width), F32)
    normal[2] = 1.0
    frame = Frame(albedo=np.full((3, height, width), 0.5, F32), normal=normal, depth=depth,
                  motion=np.zeros((2, height, width), F32),
                  mesh_id=np.ones((height, width), np.int32),
                  color=np.ones((3, height, width), F32))
    for name, plane in planes.items():
        setattr(frame, name, plane)
    return frame


def test_reprojection_fallback_and_rejection_cases() -> None:
    """Hand-placed cases on a flat plane, each with its expected branch."""
    height, width = 10, 12
    prev = _flat(width, height)
    # Case A lands at (1.995, 1.995): three of its 2x2 taps, (2, 1), (1, 2) and (2, 2), carry
    # another id.
    prev.mesh_id[1, 2] = 7
    prev.mesh_id[2, 1] = 7
    prev.mesh_id[2, 2] = 7
    prev.depth[6:10, 8:12] = 0.0  # a background corner: case C finds nothing at all
    motion = np.zeros((2, height, width), F32)
    motion[:, 1, 1] = 0.995  # A: only tap (1, 1) passes, weight 2.5e-5 < 0.01 -> 3x3 fallback
    motion[:, 4, 4] = 0.25  # B: all four taps pass -> bilinear
    motion[:, 8, 9] = 0.5  # C: every tap in the background -> rejected
    motion[0, 5, 0] = -0.5  # D: the left taps are outside the image -> bilinear on two
    cur = _flat(width, height, motion=motion)
    history = _history_for(prev, seed=1)
    out, want = _run_reproject(prev, cur, history)
    _assert_reprojection_matches(out, want)
    assert want.path[1, 1] == ref.FALLBACK
    box = [(ty, tx) for ty in range(1, 4) for tx in range(1, 4) if prev.mesh_id[ty, tx] == 1]
    np.testing.assert_allclose(out[2][1, 1], np.mean([history["length"][q] for q in box]),
                               rtol=1e-6)
    assert want.path[4, 4] == ref.BILINEAR
    assert want.path[8, 9] == ref.REJECTED and out[2][8, 9] == 0.0
    assert want.path[5, 0] == ref.BILINEAR
    np.testing.assert_allclose(out[2][5, 0], history["length"][5, 0], rtol=1e-6)


def test_resampled_history_length_keeps_whole_counts() -> None:
    """A footprint of equal history lengths resamples to exactly that length at any
    sub-pixel position. (Float32 renormalised weights used to give 2.9999998 for 3 at about
    9 % of positions, so a pixel with four frames of history fell below the variance
    threshold of 4 and got the spatial estimate.) Mixed lengths stay fractional."""
    height, width = 24, 32
    rng = np.random.default_rng(12)
    prev = _flat(width, height)
    motion = rng.uniform(-0.99, 0.99, (2, height, width)).astype(F32)
    cur = _flat(width, height, motion=motion)
    history = _history_for(prev, seed=2)
    history["length"][:] = 3.0
    history["length"][:, width // 2:] = 2.0
    out, want = _run_reproject(prev, cur, history)
    _assert_reprojection_matches(out, want)
    length = out[2]
    inside = (slice(2, -2), slice(2, width // 2 - 2))
    assert np.all(length[inside] == 3.0)
    assert np.all(length[inside] + 1.0 >= 4.0)  # the next frame's h reaches the threshold
    mixed = length[2:-2, width // 2 - 1:width // 2 + 1]
    assert np.any((mixed > 2.0) & (mixed < 3.0))


# --------------------------------------------------------------------------- 2 accumulation
@pytest.mark.parametrize(("alpha", "moments_alpha", "cap"), [(0.2, 0.2, 32.0), (0.05, 0.2, 8.0)])
def test_accumulation_matches_reference(alpha: float, moments_alpha: float, cap: float) -> None:
    rng = np.random.default_rng(5)
    height, width = 6, 8
    current = rng.gamma(2.0, 0.5, (2, 3, height, width)).astype(F32)
    history = rng.gamma(2.0, 0.5, (2, 3, height, width)).astype(F32)
    moments = rng.gamma(2.0, 0.5, (2, 2, height, width)).astype(F32)
    lengths = [0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 7.5, 19.0, 31.0, 31.5, 40.0]
    previous = rng.choice(lengths, size=(height, width)).astype(F32)
    previous[0, :len(lengths)] = lengths[:width]
    previous[1, :len(lengths) - width] = lengths[width:]
    depth = np.full((height, width), 3.0, F32)
    depth[5, 2:5] = 0.0  # background: h = 0, current values
    out = (np.empty_like(current), np.empty_like(moments), np.empty_like(previous))
    accumulate(current, history, moments, previous, depth, F32(alpha), F32(moments_alpha),
               F32(cap), *out)
    want = ref.accumulate(current, history, moments, previous, depth, alpha, moments_alpha, cap)
    _close(out[0], want[0], 1e-6, "illumination")
    _close(out[1], want[1], 1e-6, "moments")
    _close(out[2], want[2], 0.0, "history length")
    # The 1/h ramp, colour and moments alike: h_prev = 1 gives h = 2 and a blend of 1/2.
    lum = float(ref.LUMA @ current[0, :, 0, 2])
    assert previous[0, 2] == 1.0
    np.testing.assert_allclose(out[1][0, 0, 0, 2], 0.5 * moments[0, 0, 0, 2] + 0.5 * lum,
                               rtol=1e-6)
    np.testing.assert_allclose(out[0][0, :, 0, 2], 0.5 * (history + current)[0, :, 0, 2],
                               rtol=1e-6)


# --------------------------------------------------------------------------- 3 variance
def _variance_inputs(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, Frame]:
    """Accumulated-looking inputs on the scene's geometry with mixed history lengths."""
    rng = np.random.default_rng(seed)
    frame = scene_frame(3)
    illumination = ref.demodulate(frame.direct, frame.emission, frame.albedo, EPS)
    illumination = np.stack([illumination,
                             ref.demodulate(frame.indirect, None, frame.albedo, EPS)])
    illumination = illumination.astype(F32)
    lum = ref.luminance(illumination)
    spread = rng.uniform(0.0, 0.5, lum.shape)
    moments = np.stack([lum, lum * lum + spread], axis=1).astype(F32)
    length = rng.choice([1.0, 2.0, 3.0, 3.5, 4.0, 6.0], size=frame.depth.shape).astype(F32)
    length[:, :6] = 1.0  # a cold band over the black patch and the left border
    length[frame.depth <= 0] = 0.0
    return illumination, moments, length, frame


@pytest.mark.parametrize(("radius", "sigma_normal"), [(3, 128.0), (1, 128.0), (2, 64.0),
                                                      (3, 100.0)])
def test_spatial_variance_matches_reference(radius: int, sigma_normal: float) -> None:
    illumination, moments, length, frame = _variance_inputs(seed=radius)
    g = kernel_geometry(frame)
    variance = np.full((2, *length.shape), -1.0, F32)
    blurred = np.full_like(illumination, -1.0)
    spatial_variance(illumination, moments, length, frame.depth, g["ddx"], g["ddy"],
                     g["filter_normal"], F32(4.0), radius, F32(1.0), F32(10.0),
                     normal_squarings(sigma_normal), F32(sigma_normal), True, variance, blurred)
    want_variance, want_colour, short = ref.spatial_variance(
        illumination, moments, length, as_reference(g), 4.0, radius, 1.0, 10.0, sigma_normal)
    assert short.sum() > 100 and (~short & (frame.depth > 0)).sum() > 50
    _close(variance[:, short], want_variance[:, short], 2e-5, "spatial variance",
           float(moments[:, 1].max()))
    _close(blurred[:, :, short], want_colour[:, :, short], 2e-5, "blurred colour")
    assert np.all(variance[:, ~short] == -1.0)  # other pixels untouched
    # The estimate is not trivially the temporal one, and black pixels are in it.
    assert np.mean(np.abs(want_variance - ref.temporal_variance(moments))[:, short]) > 0.05
    assert np.any(short & ref.not_demodulated(frame.albedo, EPS))


@pytest.mark.parametrize("blur", [False, True])
def test_variance_estimate_with_boost_matches_reference(blur: bool) -> None:
    from svgf_cli.filters.params import resolve_params

    illumination, moments, length, frame = _variance_inputs(seed=11)
    g = kernel_geometry(frame)
    params = resolve_params("paper", spatial_variance_blur_color=blur)
    variance = np.empty((2, *length.shape), F32)
    colour = np.empty_like(illumination) if blur else None
    estimate_variance(illumination, moments, length, frame.depth, g["ddx"], g["ddy"],
                      g["filter_normal"], history_threshold=4.0, radius=3, sigma_depth=1.0,
                      sigma_luminance=10.0, squarings=7, sigma_normal=128.0,
                      out_variance=variance, out_illumination=colour)
    want_variance, want_colour = ref.estimate_variance(illumination, moments, length,
                                                       as_reference(g), params)
    m2_scale = float(moments[:, 1].max())
    _close(variance, want_variance, 2e-5, "variance", m2_scale)
    if blur:
        _close(colour, want_colour, 2e-5, "colour")
    temporal = np.empty_like(variance)
    temporal_variance(moments, temporal)
    _close(temporal, ref.temporal_variance(moments), 1e-6, "temporal variance", m2_scale)
    long_history = length >= 4.0
    np.testing.assert_array_equal(variance[:, long_history], temporal[:, long_history])
    boosted = variance.copy()
    boost_short_history(boosted, length, F32(4.0))
    _close(boosted, ref.boost_short_history(variance, length, 4.0), 1e-6, "boost")
    # The boost is 4 / h: h = 1, 2, 3, 3.5 pixels all present.
    assert {1.0, 2.0, 3.0, 3.5} <= set(np.unique(length[(length > 0) & (length < 4)]).tolist())


# --------------------------------------------------------------------------- TAA
def test_taa_matches_reference() -> None:
    rng = np.random.default_rng(6)
    height, width = 9, 12
    current = rng.gamma(2.0, 0.5, (3, height, width)).astype(F32)
    previous = rng.gamma(2.0, 0.5, (3, height, width)).astype(F32)
    motion = rng.uniform(-2.5, 2.5, (2, height, width)).astype(F32)
    motion[0, :, 0] = -0.75  # outside on the left (x - 0.75 < -0.5): current value
    motion[0, :, 1] = -1.25  # just inside the image: clamped taps
    motion[1, 0, :] = -0.25
    out = np.empty_like(current)
    taa_resolve(current, previous, motion, F32(0.1), out)
    want = ref.taa_resolve(current, previous, motion, 0.1)
    _close(out, want, 1e-6, "taa")
    np.testing.assert_array_equal(out[:, :, 0], current[:, :, 0])


def test_taa_follows_the_motion_of_a_translating_image() -> None:
    """An image that moved by exactly (+2, +1) px: with its history reprojected through the
    backward motion, a slow blend (alpha 0.1) returns the current image unchanged."""
    y, x = np.mgrid[0:12, 0:14].astype(np.float64)

    def image(shift_x: float, shift_y: float) -> np.ndarray:
        u, v = x - shift_x, y - shift_y
        return np.stack([1 + np.sin(0.9 * u), 1 + np.cos(0.7 * v), 1 + np.sin(0.5 * (u + v))]
                        ).astype(F32)

    previous, current = image(0, 0), image(2, 1)
    motion = np.stack([np.full(x.shape, -2.0), np.full(x.shape, -1.0)]).astype(F32)
    out = np.empty_like(current)
    taa_resolve(current, previous, motion, F32(0.1), out)
    inside = (slice(None), slice(1, None), slice(2, None))
    np.testing.assert_allclose(out[inside], current[inside], rtol=1e-6, atol=1e-6)
    _close(out, ref.taa_resolve(current, previous, motion, 0.1), 1e-6)
