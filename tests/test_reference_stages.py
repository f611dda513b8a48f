"""Each kernel of the temporal half alone against the float64 reference (``reference_svgf``).

Inputs are built to take every branch: background, image borders, black, one-channel-black
and brighter-than-a-reflectance demodulation colours, several signals with colours of their
own, emission, non-finite and beyond-limit values, depth edges inside one mesh, mesh-id
changes at equal depth, normal creases and grazing normals, disocclusions, taps outside the
image, the bilinear path, the 3x3 fallback (also the one reached because the passing
bilinear weight is below 0.01), taps of another demodulation mode and reset (no-history)
taps, non-finite motion. Each test asserts that its inputs really reach those branches.

Tolerances: the kernels run in float32 (relative rounding 6e-8 per operation, a few dozen
operations per output) and the spatial-variance weights use ``fast_exp`` (relative error
< 4e-6). Pure arithmetic stages are held to 1e-6 relative, the weighted ones to 2e-5,
which is 10 to 100 times tighter than any of the planted bugs the suite must catch
(``tests/mutants/plant.py``), whose effects are percent-level or more. Modes, masks, counts
and the value policy's replacements are compared exactly.
"""

from __future__ import annotations

import numba
import numpy as np
import pytest
import reference_svgf as ref
from moving_scene import ACESCG_LUMINANCE, plant_extremes, scene_frame

from svgf_cli.filters import values
from svgf_cli.filters.clamp import BAND_ROWS, firefly_clamp, heavy_tailed, history_clamp
from svgf_cli.filters.denoiser import MAX_REFLECTANCE, RELATIVE_ALBEDO_FLOOR
from svgf_cli.filters.despike import despike, despike_lone
from svgf_cli.filters.edges import normal_squarings
from svgf_cli.filters.fastmath import REC709, float32_weights
from svgf_cli.filters.fireflies import GLOSSY_RADIUS, RADIUS, spread_fireflies
from svgf_cli.filters.gradients import depth_gradients, normal_gradient, unit_normals
from svgf_cli.filters.modulate import (
    DEMODULATE_COUNTERS,
    NO_HISTORY,
    add_remodulated,
    demodulate,
    remodulate,
    remodulate_add,
)
from svgf_cli.filters.pixel_filter import pixel_filter
from svgf_cli.filters.reproject import accumulate, reproject
from svgf_cli.filters.taa import on_outline, taa_resolve
from svgf_cli.filters.variance import (
    boost_short_history,
    estimate_variance,
    spatial_variance,
    temporal_variance,
)
from svgf_cli.frame import Frame

F32 = np.float32
EPS = 1e-3  # albedo floor (the default)
RULE = (F32(EPS), F32(MAX_REFLECTANCE), F32(RELATIVE_ALBEDO_FLOOR))
ACESCG = float32_weights(ACESCG_LUMINANCE)


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


def mode_mask(radiance_mode: np.ndarray) -> np.ndarray:
    """The (S, H, W) booleans as the kernels' (H, W) uint16 mode mask."""
    return np.asarray(sum(radiance_mode[s].astype(np.uint16) << s
                          for s in range(len(radiance_mode))), dtype=np.uint16)


def mode_bits(mask: np.ndarray, num_signals: int) -> np.ndarray:
    """The kernels' uint16 mode mask as (S, H, W) booleans."""
    return np.stack([(mask >> s) & 1 == 1 for s in range(num_signals)])


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
    return {**planes, "unit_normal": unit, "depth": frame.depth}


def as_reference(g: dict[str, np.ndarray]) -> ref.Geometry:
    """The kernels' float32 geometry as the reference's, so a stage is compared alone."""
    return ref.Geometry(*(g[k].astype(np.float64) for k in (
        "depth", "unit_normal", "ddx", "ddy", "depth_slope", "normal_width")))


def kernel_demodulated(frame: Frame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(illumination (S, 3, H, W), uint16 mode mask, per-signal counter totals); the depth
    (which only decides what counts as a surface) cleaned first, as the Denoiser does."""
    depth = values.cleaned_depth(frame.depth)
    out = np.zeros((len(frame.signals), *frame.albedo.shape), F32)
    mode = np.full(frame.depth.shape, 0xFFFF, np.uint16)  # signal 0 overwrites it
    totals = []
    for index, signal in enumerate(frame.signals):
        rows = np.zeros((frame.height, DEMODULATE_COUNTERS), np.int64)
        demodulate(signal.radiance, signal.albedo, depth, *RULE, index, out[index], mode, rows)
        totals.append(rows.sum(axis=0))
    return out, mode, np.array(totals)
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
    frame = Frame.combined(albedo, albedo=albedo, normal=normal, depth=depth,
                           motion=np.zeros((2, *depth.shape), F32),
                           mesh_id=np.ones(depth.shape, np.int32))
    got = kernel_geometry(frame)
    unit = ref.unit_normals(normal, depth)
    _close(got["unit_normal"], unit, 1e-6, "unit normals")
    ddx, ddy, slope = ref.depth_gradients(depth)
    _close(got["ddx"], ddx, 1e-6, "ddx")
    _close(got["ddy"], ddy, 1e-6, "ddy")
    _close(got["depth_slope"], slope, 1e-6, "slope")
    # The normal gradient is compared on the kernel's own unit normals (stage alone).
    _close(got["normal_width"], ref.normal_gradient(got["unit_normal"], depth), 1e-6, "fwidth")
    if source == "rough":
        # The branches: ties between equal-magnitude sides with opposite signs, pixels with
        # one usable side, pixels with none (zero derivative), degenerate normals.
        left = np.abs(depth[1:-1, 1:-2] - depth[1:-1, :-3])
        right = np.abs(depth[1:-1, 2:-1] - depth[1:-1, 1:-2])
        assert np.any((left == right) & (left > 0))
        assert np.any((got["ddx"] == 0) & (depth > 0) & (np.roll(depth, 1, 1) == 0))
        assert np.all(got["unit_normal"][:, 2:4, -2] == 0) and np.all(depth[2:4, -2] > 0)


# --------------------------------------------------------------------------- values
def test_value_policy_of_the_geometry_matches_reference() -> None:
    """Depth, normal and motion of a frame with every kind of bad value: the Denoiser's
    cleaners and counters against the reference's policy, exactly."""
    frame = scene_frame(2, layout="three")
    plant_extremes(frame)
    frame.depth[1, 1] = -1e20  # beyond the limit but background anyway: still counted
    frame.motion[0, 3, 3] = 1e30  # finite: kept (it only means no history)
    clean = ref.apply_value_policy(frame)
    # Exactly (the reference's 1e15 rounds to the kernels' float32 VALUE_LIMIT).
    np.testing.assert_array_equal(values.cleaned_depth(frame.depth), clean.depth.astype(F32))
    np.testing.assert_array_equal(values.cleaned_normal(frame.normal), clean.normal.astype(F32))
    np.testing.assert_array_equal(values.cleaned_motion(frame.motion), clean.motion.astype(F32))
    counted = values.count_geometry(frame.depth, frame.normal, frame.motion)
    for plane in ("depth", "normal", "motion"):
        nonfinite, extreme = counted[plane]
        assert clean.counts.get(f"nonfinite.{plane}", 0) == nonfinite, plane
        if plane != "motion":  # far-away motion is not a problem: never counted as one
            assert clean.counts.get(f"extreme.{plane}", 0) == extreme, plane
    assert counted["depth"] == (2, 2) and counted["motion"] == (2, 1)
    assert clean.motion[0, 3, 3] == F32(1e30) and np.all(clean.motion[:, 13, 10:12] == 1e15)
    assert np.all(clean.normal[:, 12, 8:10] == 0.0)
    assert clean.depth[13, 5] == clean.depth[14, 6] == clean.depth[15, 7] == 0.0


def test_history_guard_matches_reference() -> None:
    rng = np.random.default_rng(21)
    shape = (3, 7, 9)
    illumination = rng.gamma(2.0, 0.5, (3, 3, 7, 9)).astype(F32)
    moments = rng.gamma(2.0, 0.5, (3, 2, 7, 9)).astype(F32)
    length = rng.choice([0.0, 1.0, 4.0], size=shape).astype(F32)
    # one non-finite value in each plane the guard checks, each at its own pixel
    illumination[0, 0, 5, 1] = np.inf
    illumination[2, 1, 0, 0] = np.nan
    illumination[1, 2, 4, 7] = -np.inf
    moments[2, 0, 1, 6] = np.nan
    moments[0, 1, 3, 4] = -np.inf
    length[1, 6, 8] = np.inf
    moments[1, 0, 2, 2] = 3e38  # finite: not the guard's business
    mode = rng.integers(0, 8, (7, 9)).astype(np.uint16)
    history = ref.History(illumination.astype(np.float64), moments.astype(np.float64),
                          length.astype(np.float64), mode_bits(mode, 3),
                          np.ones((7, 9), bool), np.ones((7, 9)), np.zeros((3, 7, 9)),
                          np.ones((7, 9), np.int32))
    want = ref.reset_nonfinite_history(history)
    got = values.reset_nonfinite_history(illumination, moments, length, mode)
    assert got == want == 6
    np.testing.assert_array_equal(illumination, history.illumination)
    np.testing.assert_array_equal(moments, history.moments)
    np.testing.assert_array_equal(length, history.history_length)
    np.testing.assert_array_equal(mode == NO_HISTORY, ~history.has_history)


# --------------------------------------------------------------------------- 1 demodulation
@pytest.mark.parametrize("layout", ["split", "combined", "three"])
def test_demodulation_round_trip_matches_reference(layout: str) -> None:
    """Each signal by its own colour: the mode rule (black, brighter than a reflectance,
    one black channel floored), the value policy (bad radiance and albedo, a demodulated
    value beyond the limit clamped) and the counts, then the remodulation and the one-pass
    sum with background and emission."""
    frame = scene_frame(2, layout=layout)
    plant_extremes(frame)
    first = frame.signals[0]
    first.radiance[:, 10, 20] = 5e13  # over the 1e-3 floor: 5e16, clamped to 1e15
    first.albedo[:, 10, 20] = 1e-3
    depth = values.cleaned_depth(frame.depth)
    got, mode, totals = kernel_demodulated(frame)
    surface = depth > 0
    clean = ref.apply_value_policy(frame)
    for index, signal in enumerate(frame.signals):
        want, radiance_mode, clamped = ref.demodulate(signal.radiance, signal.albedo, EPS)
        np.testing.assert_array_equal(mode_bits(mode, len(frame.signals))[index], radiance_mode)
        _close(got[index], want, 1e-6, f"demodulate {signal.name}")
        name = signal.name
        assert totals[index].tolist() == [
            clean.counts.get(f"nonfinite.radiance.{name}", 0),
            clean.counts.get(f"extreme.radiance.{name}", 0),
            clean.counts.get(f"nonfinite.albedo.{name}", 0),
            int(np.sum(radiance_mode & surface)),
            int(np.sum((ref.clean_albedo(signal.albedo).max(axis=0) > MAX_REFLECTANCE)
                       & surface)),
            clamped,
        ], name
        back = np.empty_like(signal.radiance)
        remodulate(got[index], signal.albedo, *RULE, back)
        _close(back, ref.remodulate(got[index], signal.albedo, EPS), 1e-6)
        inverse = ref.usable(signal.radiance) & (np.abs(want) < 1e15)
        np.testing.assert_allclose(back[inverse], signal.radiance[inverse], rtol=1e-5,
                                   atol=1e-6)  # exact inverse
    # The branches: black, implausible (in the three layout the glossy copper) and
    # one-channel-black colours; the clamp.
    assert totals[:, 3].sum() > 10 and totals[:, 4].sum() >= 1 and totals[0, 5] == 3
    # Remodulation, background restore, the sum of the signals and the emission in one pass.
    total = np.zeros_like(frame.albedo)
    rows = np.zeros((frame.height, 2), np.int64)
    for index, signal in enumerate(frame.signals):
        remodulate_add(got[index], signal.radiance, signal.albedo, depth, frame.emission,
                       index == 0, *RULE, total, rows)
        if index == 0:
            assert rows.sum(axis=0).tolist() == [clean.counts["nonfinite.emission"],
                                                 clean.counts["extreme.emission"]]
    want = sum(ref.radiance_with_background(ref.remodulate(got[i], s.albedo, EPS), s.radiance,
                                            depth) for i, s in enumerate(frame.signals))
    _close(total, want + ref.clean_value(frame.emission), 1e-6, "remodulate_add")
    # Where each signal's own radiance is wanted too (the light layers): each remodulated
    # alone, then summed with the emission: the same sum bit for bit, the same counts.
    summed = np.zeros_like(frame.albedo)
    for index, signal in enumerate(frame.signals):
        alone = np.zeros_like(frame.albedo)
        remodulate_add(got[index], signal.radiance, signal.albedo, depth, frame.emission,
                       False, *RULE, alone, rows)
        add_remodulated(alone, frame.emission, index == 0, summed, rows)
        if index == 0:
            assert rows.sum(axis=0).tolist() == [clean.counts["nonfinite.emission"],
                                                 clean.counts["extreme.emission"]]
    assert clean.counts["nonfinite.emission"] > 0  # the emission's cleaning is exercised
    np.testing.assert_array_equal(summed.view(np.uint32), total.view(np.uint32))


def test_mode_rule_thresholds() -> None:
    """The rule's edges: brightest channel at 1.05 (in) and above (out), at the black
    floor (in) and below (out); the per-channel floor relative to the brightest channel."""
    albedo = np.ascontiguousarray(np.array(
        [[1.05, 0.5, 0.0], [1.06, 0.5, 0.0], [1e-3, 0.0, 0.0], [9e-4, 9e-4, 9e-4],
         [0.8, 1e-4, 0.01]], F32).T[:, None, :])
    radiance_mode, divisor = ref.effective_albedo(albedo, EPS)
    assert radiance_mode[0].tolist() == [False, True, False, True, False]
    np.testing.assert_allclose(divisor[:, 0, 4], [0.8, 0.016, 0.016])
    np.testing.assert_allclose(divisor[:, 0, 2], [1e-3, 1e-3, 1e-3])
    out = np.empty((3, 1, 5), F32)
    mode = np.zeros((1, 5), np.uint16)
    demodulate(np.ones((3, 1, 5), F32), albedo, np.ones((1, 5), F32), *RULE, 0, out, mode,
               np.zeros((1, DEMODULATE_COUNTERS), np.int64))
    np.testing.assert_array_equal(mode[0] == 1, radiance_mode[0])
    _close(out, 1.0 / divisor, 1e-6)


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


@pytest.mark.parametrize("weights", [REC709, ACESCG], ids=["rec709", "acescg"])
def test_firefly_clamp_matches_reference(weights: tuple) -> None:
    illumination, depth = _spiky_illumination(1)
    out = np.empty_like(illumination)
    firefly_clamp(illumination, depth, F32(1.5), weights, out)
    want = ref.firefly_clamp(illumination, depth, 1.5, weights)
    _close(out, want, 2e-5, "firefly clamp")
    changed = np.any(want != illumination, axis=1)
    assert changed[0, 4, 4] and changed[1, 0, 7] and changed.sum() > 10
    assert np.all(want[:, :, depth <= 0] == illumination[:, :, depth <= 0])


@pytest.mark.parametrize("weights", [REC709, ACESCG], ids=["rec709", "acescg"])
def test_despike_matches_reference(weights: tuple) -> None:
    illumination, depth = _spiky_illumination(4)
    rng = np.random.default_rng(5)
    # Modes per signal: a block filtered as radiance (not a neighbour of the others), and a
    # pixel whose every neighbour is of the other mode (left alone however bright).
    radiance_mode = np.zeros((2, *depth.shape), dtype=bool)
    radiance_mode[0, 5:, 6:] = True
    radiance_mode[1] = rng.uniform(size=depth.shape) < 0.2
    radiance_mode[0, 0:3, 0:3] = True
    radiance_mode[0, 1, 1] = False
    illumination[0, :, 1, 1] *= 50.0
    illumination[1, :, 5, 2] = -illumination[1, :, 5, 2]  # a negative neighbour luminance
    height, width = depth.shape
    illumination[0, :, 3, 0] *= 30.0  # spikes in the first and last columns
    illumination[0, :, 6, width - 1] *= 30.0
    illumination[0, :, 5:8, 0] *= 20.0  # bright, but not the last column's neighbours
    radiance_mode[0, 5:8, 0] = True  # (the same mode as that spike)
    # Around the first row's spike (1, 0, 7): its brightest neighbour in its own row, and a
    # bright last row that is not its neighbour.
    illumination[1, :, 0, 6] *= 6.0
    illumination[1, :, height - 1, 6:9] *= 20.0
    radiance_mode[1, 0:2, 6:9] = radiance_mode[1, height - 1, 6:9] = False
    illumination[1, :, 6:9, 3:6] = 0.0  # a lit pixel among black neighbours: bound 0
    illumination[1, :, 7, 4] = 0.3
    radiance_mode[1, 6:9, 3:6] = False
    illumination[1, :, 3:6, 6:9] = 0.0  # black among black: left alone (no 0/0)
    radiance_mode[1, 3:6, 6:9] = False
    got = illumination.copy()
    clamped = np.zeros((depth.shape[0], 2), dtype=np.int64)
    scratch = np.empty(depth.shape, dtype=F32)
    despike(got, mode_mask(radiance_mode), depth, F32(2.0), weights, scratch, clamped)
    want, changed = ref.despike(illumination, radiance_mode, depth, 2.0, weights)
    _close(got, want, 2e-6, "despike")
    assert clamped.sum(axis=0).tolist() == changed
    moved = np.any(want != illumination, axis=1)
    assert moved[0, 4, 4] and moved[1, 0, 7]  # the planted fireflies
    assert moved[0, 3, 0] and moved[0, 6, width - 1]
    assert moved[1, 7, 4] and not got[1, :, 7, 4].any()
    assert np.all(np.isfinite(got)) and not got[1, :, 4, 7].any()
    assert not moved[0, 1, 1]  # no same-mode neighbour
    assert 0 < moved.sum() < 0.2 * moved.size  # spikes only, not the noise


def test_despike_takes_pairs_and_keeps_lines() -> None:
    """A pair of spikes (a reprojected firefly) is brought down to twice the surroundings,
    side by side or diagonal; a line keeps every pixel but its two ends, which have one
    bright neighbour each."""
    height, width = 12, 12
    illumination = np.ones((1, 3, height, width), dtype=F32)
    bright = [(3, 3), (3, 4), (9, 2), (10, 3)] + [(y, 8) for y in range(2, 9)]
    for y, x in bright:
        illumination[0, :, y, x] = 10.0
    depth = np.full((height, width), 5.0, F32)
    radiance_mode = np.zeros((1, height, width), dtype=bool)
    got = illumination.copy()
    clamped = np.zeros((height, 1), dtype=np.int64)
    despike(got, mode_mask(radiance_mode), depth, F32(2.0), REC709,
            np.empty(depth.shape, dtype=F32), clamped)
    want, changed = ref.despike(illumination, radiance_mode, depth, 2.0)
    _close(got, want, 2e-6, "despike")
    lowered = {(y, x) for y, x in bright if want[0, 1, y, x] < 9.0}
    assert lowered == {(3, 3), (3, 4), (9, 2), (10, 3), (2, 8), (8, 8)}
    np.testing.assert_allclose(want[0, :, 3, 3], 2.0)
    assert clamped.sum() == changed[0] == len(lowered)  # and nothing else moved


@pytest.mark.parametrize("with_emission", [True, False])
def test_despike_lone_matches_reference(with_emission: bool) -> None:
    """Pixels whose mode no surface neighbour shares, in either signal, are bounded in the
    output against their output neighbours; the emission is kept; a pair of same-mode
    pixels, a bright pixel that shares its mode and a lone pixel among black neighbours
    (bound 0) behave as the reference says."""
    height, width = 10, 12
    rng = np.random.default_rng(11)
    output = rng.uniform(0.5, 1.5, (3, height, width)).astype(F32)
    depth = np.full((height, width), 4.0, F32)
    depth[0, :3] = 0.0  # background: not a neighbour, never changed
    modes = np.zeros((2, height, width), dtype=bool)
    modes[0, 2, 2] = True  # lone in signal 0 (radiance among demodulated): a firefly
    output[:, 2, 2] = 40.0
    modes[1, 6:9, 6:9] = True  # lone in signal 1 (demodulated among radiance)
    modes[1, 7, 7] = False
    output[:, 7, 7] = 12.0
    modes[0, 4, 8:10] = True  # a same-mode pair: not lone
    output[:, 4, 8:10] = 30.0
    output[:, 8, 2] = 25.0  # bright, mode shared with all: not lone
    modes[0, 1, 10] = True  # lone, an emitter: only its reflected part counts
    output[:, 1, 10] = 50.0
    modes[0, 9, 0] = True  # lone at the corner among black neighbours
    output[:, 8:10, 0:2] = 0.0
    output[:, 9, 0] = 0.5
    emission = np.zeros_like(output)
    emission[:, 1, 10] = 49.5
    got = output.copy()
    clamped = np.zeros(height, dtype=np.int64)
    despike_lone(got, emission if with_emission else got, with_emission, mode_mask(modes),
                 depth, 2, F32(2.0), REC709, np.empty(depth.shape, F32), clamped)
    want, changed = ref.despike_lone(output, emission if with_emission else None, modes,
                                     depth, 2.0)
    _close(got, want, 2e-6, "despike_lone")
    assert clamped.sum() == changed
    moved = np.any(want != output, axis=0)
    assert moved[2, 2] and moved[7, 7] and moved[9, 0]
    assert not moved[4, 8] and not moved[4, 9] and not moved[8, 2]
    assert moved[1, 10] != with_emission  # 50 = 49.5 emitted + 0.5 reflected: kept
    assert not got[:, 9, 0].any()
    assert not moved[0, :3].any()


def _firefly_case(seed: int) -> tuple[np.ndarray, ...]:
    """Three signals over 14x16 with a history (moments of a steady level), fireflies on
    flat ground, at the border, next to a depth edge and between radiance-mode pixels, a
    lit block (a lighting change: every pixel above its history), and the third signal
    glossy (a firefly at (5, 5))."""
    height, width = 14, 16
    rng = np.random.default_rng(seed)
    current = rng.gamma(2.0, 0.25, (3, 3, height, width)).astype(F32)
    level = F32(0.5)
    moments = np.empty((3, 2, height, width), F32)
    moments[:, 0] = level
    moments[:, 1] = level * level * F32(1.4)
    depth = np.full((height, width), 5.0, F32)
    depth[:, 11:] = 9.0  # a second surface: no share crosses to it
    depth[0, 0:3] = 0.0  # background
    radiance_mode = np.zeros((3, height, width), dtype=bool)
    radiance_mode[0, 9:12, 2:5] = True
    radiance_mode[0, 10, 3] = False  # alone among radiance-mode pixels
    for s, y, x, gain in [(0, 5, 5, 80.0), (0, 0, 7, 60.0), (0, 7, 10, 50.0),
                          (0, 10, 3, 40.0), (1, 12, 14, 90.0), (2, 5, 5, 80.0)]:
        current[s, :, y, x] *= gain
    current[1, :, 2:6, 2:6] *= 12.0  # the lit block
    return current, moments, mode_mask(radiance_mode), radiance_mode, depth


@pytest.mark.parametrize("weights", [REC709, ACESCG], ids=["rec709", "acescg"])
def test_firefly_spreading_matches_reference(weights: tuple) -> None:
    current, moments, mask, radiance_mode, depth = _firefly_case(3)
    got = current.copy()
    keep = np.empty(depth.shape, F32)
    albedo = [np.full((3, *depth.shape), 0.5, F32)] * 3
    counts = spread_fireflies(got, albedo, (False,) * 3, moments, mask, depth,
                              (RADIUS, RADIUS, 0), 10.0, weights, keep)
    want, found = ref.spread_fireflies(current, radiance_mode, moments, depth,
                                       [True, True, False], 10.0, weights)
    _close(got, want, 2e-6, "firefly spreading")
    assert counts == found
    lum = ref.luminance(current, weights)
    after = ref.luminance(want, weights)
    # The planted fireflies are found and brought down at least fivefold ...
    for s, y, x in [(0, 5, 5), (0, 0, 7), (0, 7, 10), (0, 10, 3), (1, 12, 14)]:
        assert after[s, y, x] < lum[s, y, x] / 5, (s, y, x)
    # ... with their energy kept on their own surface, in their own mode.
    for s in range(2):
        np.testing.assert_allclose(np.sum(got[s], axis=(1, 2)), np.sum(current[s], axis=(1, 2)),
                                   rtol=1e-5)
    assert np.array_equal(got[0][:, radiance_mode[0]], current[0][:, radiance_mode[0]])
    np.testing.assert_array_equal(want[0][:, :, 11:], current[0][:, :, 11:])  # edge kept
    assert np.array_equal(got[2], current[2])  # the glossy signal is left alone
    assert np.array_equal(got[:, :, depth <= 0], current[:, :, depth <= 0])
    # Inside the lit block every neighbour rose too: no pixel there is a firefly (they
    # only gain shares of one nearby).
    inner = after[1, 3:5, 3:5] / lum[1, 3:5, 3:5]
    assert inner.min() >= 1.0 - 1e-6
    assert sum(counts) <= 8  # fireflies, not the noise


def test_firefly_spreading_leaves_a_converged_history_alone() -> None:
    """A sample within k sigma of its history is no firefly however far above its
    neighbours, and one above every neighbour fourfold but within its history is kept."""
    current, moments, mask, radiance_mode, depth = _firefly_case(4)
    moments[:, 0, 5, 5] = 100.0  # the history knows this pixel is bright
    moments[:, 1, 5, 5] = 100.0 ** 2 * 1.1
    got = current.copy()
    albedo = [np.full((3, *depth.shape), 0.5, F32)] * 3
    counts = spread_fireflies(got, albedo, (False,) * 3, moments, mask, depth,
                              (RADIUS, RADIUS, 0), 10.0, REC709, np.empty(depth.shape, F32))
    want, found = ref.spread_fireflies(current, radiance_mode, moments, depth,
                                       [True, True, False], 10.0)
    _close(got, want, 2e-6, "firefly spreading")
    assert counts == found
    assert ref.luminance(want, REC709)[0, 5, 5] >= ref.luminance(current, REC709)[0, 5, 5]


@pytest.mark.parametrize("seed", [5, 6])
def test_firefly_spreading_keeps_a_glossy_firefly_in_its_3x3(seed: int) -> None:
    """A glossy signal's firefly (spread with ``GLOSSY_RADIUS``) is brought down and its
    excess shared over its own 3x3 alone: a rare hit of a small highlight stays where the
    highlight is. Other signals keep the 9x9; a signal with radius 0 is left alone."""
    current, moments, mask, radiance_mode, depth = _firefly_case(seed)
    got = current.copy()
    albedo = [np.full((3, *depth.shape), 0.5, F32)] * 3
    counts = spread_fireflies(got, albedo, (False,) * 3, moments, mask, depth,
                              (RADIUS, 0, GLOSSY_RADIUS), 10.0, REC709,
                              np.empty(depth.shape, F32), capped=(False, False, True))
    want, found = ref.spread_fireflies(current, radiance_mode, moments, depth,
                                       [True, False, False], 10.0)
    want, found_glossy = ref.spread_fireflies(want, radiance_mode, moments, depth,
                                              [False, False, True], 10.0, radius=1, cap=True)
    _close(got, want, 2e-6, "firefly spreading, glossy")
    assert counts == [a + b for a, b in zip(found, found_glossy, strict=True)]
    assert counts[2] >= 1 and counts[1] == 0
    assert np.array_equal(got[1], current[1])
    lum, after = ref.luminance(current, REC709), ref.luminance(want, REC709)
    assert after[2, 5, 5] < lum[2, 5, 5] / 4  # the planted glossy firefly
    changed = np.any(got[2] != current[2], axis=0)
    # Every change lies within one pixel of a glossy firefly the reference found.
    lowered = ref.luminance(want, REC709)[2] < lum[2] - 1e-6
    near = np.zeros_like(changed)
    for y, x in zip(*np.nonzero(lowered), strict=True):
        near[max(y - 1, 0):y + 2, max(x - 1, 0):x + 2] = True
    assert changed[5, 5] and not np.any(changed & ~near)
    assert np.any(changed[4:7, 4:7] & (got[2, 0, 4:7, 4:7] > current[2, 0, 4:7, 4:7]))
    # No pixel gains more than the bounded fireflies beside it keep (the cap), so nothing
    # is created: the signal's light can only fall.
    gain = ref.luminance(got, REC709)[2] - lum[2]
    assert gain[~lowered].max() <= after[2][lowered].max() * (1 + 1e-5)
    assert got[2].astype(np.float64).sum() <= current[2].astype(np.float64).sum() * (1 + 1e-6)


@pytest.mark.parametrize("capped", [False, True])
def test_a_capped_share_gives_no_pixel_more_than_the_firefly_keeps(capped: bool) -> None:
    """One glossy firefly 400 times its surroundings over a flat surface: uncapped, its
    excess is shared equally over its 3x3 (energy kept); capped, every receiver gains
    exactly the firefly's bound (the excess is larger than 9 times it) and the rest is
    dropped."""
    height, width = 9, 11
    current = np.full((1, 3, height, width), 0.5, F32)
    current[0, :, 4, 5] = 200.0
    moments = np.empty((1, 2, height, width), F32)
    moments[:, 0] = 0.5
    moments[:, 1] = 0.25 * 1.01
    depth = np.full((height, width), 2.0, F32)
    radiance_mode = np.zeros((1, height, width), dtype=bool)
    got = current.copy()
    counts = spread_fireflies(got, [np.full((3, height, width), 0.5, F32)], (False,),
                              moments, mode_mask(radiance_mode), depth, (GLOSSY_RADIUS,), 10.0,
                              REC709, np.empty(depth.shape, F32), capped=(capped,))
    want, found = ref.spread_fireflies(current, radiance_mode, moments, depth, [True], 10.0,
                                       radius=1, cap=capped)
    _close(got, want, 2e-6, "firefly spreading, capped" if capped else "firefly spreading")
    assert counts == found == [1]
    bound = 4.0 * 0.5  # 4x the second-brightest neighbour (above m1 + 10 sigma = 1.0)
    gain = (want[0] - current[0])[0]
    outside = np.ones((height, width), dtype=bool)
    outside[3:6, 4:7] = False
    assert np.all(gain[outside] == 0.0)
    if capped:
        others = ~outside
        others[4, 5] = False
        np.testing.assert_allclose(gain[others], bound, rtol=1e-9)
        np.testing.assert_allclose(want[0, 0, 4, 5], 2 * bound, rtol=1e-9)
    else:
        np.testing.assert_allclose(want.sum(), current.astype(np.float64).sum(), rtol=1e-9)
        np.testing.assert_allclose(gain[3:6, 4:7][0, 0], (200.0 - bound) / 9, rtol=1e-9)


def test_firefly_spreading_keeps_to_its_colour_under_the_g_buffer_albedo() -> None:
    """A signal demodulated by the G-buffer albedo (a combined colour) shares a firefly's
    excess only with pixels of a similar colour (within 25 %): that albedo is no reflectance
    of the glossy light such a signal carries, and shared onto a brighter colour the light
    would come back brighter. A signal demodulated by its own reflectance shares across
    colours (its illumination is what is smooth)."""
    height, width = 12, 12
    current = np.full((1, 3, height, width), 0.5, F32)
    current[0, :, 5, 5] = 50.0  # one firefly, on a dark square
    moments = np.empty((1, 2, height, width), F32)
    moments[:, 0] = 0.5
    moments[:, 1] = 0.25 * 1.01
    depth = np.full((height, width), 5.0, F32)
    radiance_mode = np.zeros((1, height, width), dtype=bool)
    checker = np.where((np.indices(depth.shape).sum(axis=0) // 2) % 2 == 1, 0.12, 0.48)
    assert checker[5, 5] == 0.12
    albedo = np.broadcast_to(checker.astype(F32), (1, 3, height, width)).copy()
    window = (slice(1, 10), slice(1, 10))
    light = checker[window] == 0.48
    others = np.ones((9, 9), dtype=bool)
    others[4, 4] = False  # the firefly itself, which loses its excess
    for guide in (True, False):
        got = current.copy()
        counts = spread_fireflies(got, [albedo[0]], (guide,), moments, mode_mask(radiance_mode),
                                  depth, (RADIUS,), 10.0, REC709, np.empty(depth.shape, F32))
        want, found = ref.spread_fireflies(current, radiance_mode, moments, depth, [True], 10.0,
                                           albedo=albedo, guide=[guide])
        _close(got, want, 2e-6, "firefly spreading")
        assert counts == found == [1]
        gained = (want[0] - current[0])[1][window]
        assert gained[4, 4] < 0.0
        if guide:  # only the dark squares share it
            assert np.all(gained[light] == 0.0) and np.all(gained[~light & others] > 0.0)
        else:
            assert np.all(gained[others] > 0.0)
        np.testing.assert_allclose(want[0].sum(), current[0].astype(np.float64).sum(),
                                   rtol=1e-9)  # the excess is kept, as demodulated light


def test_history_clamp_matches_reference() -> None:
    current, depth = _spiky_illumination(2)
    rng = np.random.default_rng(3)
    history = (current * rng.uniform(0.2, 3.0, current.shape)).astype(F32)
    # Per signal: a signal's pixels without history are left alone, the other's clamped.
    length = rng.choice([0.0, 1.0, 2.5, 8.0], size=(2, *depth.shape)).astype(F32)
    weights = (F32(0.2126), F32(0.7152), F32(0.0722))
    lum = np.einsum("c,scyx->syx", np.array(weights, dtype=np.float64), history)
    moments = np.stack([lum, lum * lum * 1.5], axis=1).astype(F32)
    moments[0, :, 3, 3] = 0.0  # a black history somewhere (if clamped: moments from l')
    got, got_moments = history.copy(), moments.copy()
    history_clamp(got, got_moments, length, current, depth, F32(1.0), weights)
    want, want_moments = ref.history_clamp(history, moments, length, current, depth, 1.0,
                                           weights)
    _close(got, want, 2e-5, "history clamp")
    _close(got_moments, want_moments, 5e-5, "history clamp moments")
    assert np.sum(want != history) > 50  # it clamps, ...
    # ... and the moments follow the clamped luminance exactly where the colour moved.
    moved = np.any(want != history, axis=1)
    assert np.all(want_moments[:, 0][~moved] == moments[:, 0][~moved])
    assert np.all(np.abs(want_moments[:, 0][moved] - moments[:, 0][moved]) > 0)
    for s in range(2):
        untouched = (length[s] <= 0) | (depth <= 0)
        assert untouched.any() and np.all(want[s][:, untouched] == history[s][:, untouched])
    assert np.any((length[0] <= 0) & (length[1] > 0) & np.any(want[1] != history[1], axis=0))


CLAMP_WEIGHTS = (F32(0.2126), F32(0.7152), F32(0.0722))


def _clamp_case(height: int, width: int, seed: int) -> tuple:
    """Two signals' spiky current values and depth, a history 0.2-3x them, history lengths
    0, 1 or 4 and moments from the history's luminance (relative spread 0.5); and the
    generator, for more."""
    current, depth = _spiky_illumination(2, height=height, width=width)
    rng = np.random.default_rng(seed)
    history = (current * rng.uniform(0.2, 3.0, current.shape)).astype(F32)
    length = rng.choice([0.0, 1.0, 4.0], size=(2, *depth.shape)).astype(F32)
    lum = np.einsum("c,scyx->syx", np.array(CLAMP_WEIGHTS, dtype=np.float64), history)
    moments = np.stack([lum, lum * lum * 1.5], axis=1).astype(F32)
    return current, depth, history, length, moments, rng


def test_heavy_tailed_pixels_match_reference() -> None:
    """``heavy_tailed`` against the float64 reference: relative variance above the
    threshold, history long enough, a surface, and not on a rough object; the count
    returned is the plane's."""
    rng = np.random.default_rng(11)
    height, width = 23, 31
    m1 = rng.uniform(0.0, 2.0, (height, width)).astype(F32)
    m1[rng.random((height, width)) < 0.1] = 0.0  # black histories are never heavy-tailed
    relative = rng.choice([0.0, 0.5, 1.5, 2.5, 9.0], size=(height, width))
    moments = np.stack([m1, m1 * m1 * (1.0 + relative)]).astype(F32)
    length = rng.choice([0.0, 0.5, 1.0, 3.0, 12.0], size=(height, width)).astype(F32)
    depth = np.where(rng.random((height, width)) < 0.1, 0.0, 1.0).astype(F32)
    mesh = rng.integers(3, 9, size=(height, width)).astype(np.int32)
    table = np.zeros(6, np.uint8)
    table[[1, 4]] = 1  # objects 4 and 7 are rough
    got = np.empty((height, width), dtype=np.bool_)
    count = heavy_tailed(moments, length, depth, mesh, 3, table, F32(2.0), got)
    want = ref.heavy_tailed(moments, length, depth, mesh, {4, 7}, 2.0)
    assert np.array_equal(got, want) and count == int(want.sum()) > 20
    assert not np.any(got & np.isin(mesh, [4, 7]))
    assert np.any(ref.heavy_tailed(moments, length, depth, mesh, set(), 2.0) & (mesh == 4))
    # No rough table (ids outside it, or none found): every object counts.
    count = heavy_tailed(moments, length, depth, mesh, 0, np.zeros(0, np.uint8), F32(2.0), got)
    assert np.array_equal(got, ref.heavy_tailed(moments, length, depth, mesh, set(), 2.0))


def test_history_clamp_heavy_tailed_pixels_take_the_wide_window() -> None:
    """A 3x3 signal's pixels in ``wide_where`` are clamped over the wider window, as if the
    3x3 pass had not touched them; every other pixel of it and the other signal get what a
    call without ``wide_where`` gives (float64 reference with a radius per pixel)."""
    current, depth, history, length, moments, rng = _clamp_case(BAND_ROWS + 9, 14, seed=7)
    weights = CLAMP_WEIGHTS
    wide = rng.random(depth.shape) < 0.3
    got, got_moments = history.copy(), moments.copy()
    history_clamp(got, got_moments, length, current, depth, F32(1.0), weights, [1, 1],
                  [None, wide], 3)
    want, want_moments = ref.history_clamp(history, moments, length, current, depth, 1.0,
                                           weights, [1, np.where(wide, 3, 1)])
    _close(got, want, 2e-5, "history clamp, wide where heavy-tailed")
    _close(got_moments, want_moments, 5e-5, "history clamp moments, wide where heavy-tailed")
    plain, plain_moments = history.copy(), moments.copy()
    history_clamp(plain, plain_moments, length, current, depth, F32(1.0), weights, [1, 1])
    assert np.array_equal(got[0], plain[0]) and np.array_equal(got[1][:, ~wide],
                                                                plain[1][:, ~wide])
    assert np.array_equal(got_moments[1][:, ~wide], plain_moments[1][:, ~wide])
    assert np.sum(np.any(got[1] != plain[1], axis=0) & wide) > 20  # the window counts
    # A radius of 1 (small images) or no plane: the call without it, bit for bit.
    for args in (([None, wide], 1), ([None, None], 3)):
        same, same_moments = history.copy(), moments.copy()
        history_clamp(same, same_moments, length, current, depth, F32(1.0), weights, [1, 1],
                      *args)
        assert np.array_equal(same, plain) and np.array_equal(same_moments, plain_moments)


@pytest.mark.parametrize("radii", [[2, 2], [1, 3], [3, 1]])
def test_history_clamp_wider_windows_match_reference(radii: list[int]) -> None:
    """A wider window per signal (``radius``), each against the float64 reference, over
    more rows than a band of the wider windows' kernel (``clamp.BAND_ROWS``); the 3x3
    signal of a mixed call gets exactly what a 3x3 call alone gives it."""
    current, depth, history, length, moments, _ = _clamp_case(2 * BAND_ROWS + 7, 12, seed=5)
    depth[BAND_ROWS - 1:BAND_ROWS + 2, 3:6] = 0.0  # background across a band's edge
    weights = CLAMP_WEIGHTS
    got, got_moments = history.copy(), moments.copy()
    history_clamp(got, got_moments, length, current, depth, F32(1.0), weights, radii)
    want, want_moments = ref.history_clamp(history, moments, length, current, depth, 1.0,
                                           weights, radii)
    _close(got, want, 2e-5, "history clamp")
    _close(got_moments, want_moments, 5e-5, "history clamp moments")
    narrow = ref.history_clamp(history, moments, length, current, depth, 1.0, weights, 1)[0]
    for s, radius in enumerate(radii):
        assert np.sum(want[s] != narrow[s]) > (20 if radius > 1 else -1)  # the window counts
        if radius == 1:
            alone, alone_moments = history[s:s + 1].copy(), moments[s:s + 1].copy()
            history_clamp(alone, alone_moments, length[s:s + 1], current[s:s + 1], depth,
                          F32(1.0), weights)
            assert np.array_equal(alone[0], got[s]) and np.array_equal(alone_moments[0],
                                                                       got_moments[s])
    with pytest.raises(ValueError, match="at least 1"):
        history_clamp(got, got_moments, length, current, depth, F32(1.0), weights, 0)
    # The bands are fixed: one thread gives the same bits as two.
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        single, single_moments = history.copy(), moments.copy()
        history_clamp(single, single_moments, length, current, depth, F32(1.0), weights, radii)
    finally:
        numba.set_num_threads(threads)
    again, again_moments = history.copy(), moments.copy()
    history_clamp(again, again_moments, length, current, depth, F32(1.0), weights, radii)
    assert np.array_equal(single, again) and np.array_equal(single_moments, again_moments)


def test_history_clamp_raised_from_near_black_keeps_finite_moments() -> None:
    """A history almost black where the frame is lit (a light came on) is raised to the
    frame's band: scaling its moments by (l'/l)^2 overflowed to inf (and NaN variance) from
    l ~ 1e-30; raised more than a millionfold it counts as black (m2 = m1^2 = l'^2)."""
    height, width = 5, 5
    current = np.full((1, 3, height, width), 2.0, dtype=F32)
    current[0, :, ::2, ::2] = 3.0
    history = np.full_like(current, 1e-30)
    moments = np.stack([np.full((height, width), 1e-30), np.full((height, width), 0.25)])
    moments = moments[None].astype(F32)
    length = np.full((1, height, width), 4.0, dtype=F32)
    depth = np.ones((height, width), dtype=F32)
    weights = (F32(0.2126), F32(0.7152), F32(0.0722))
    got_history, got_moments = history.copy(), moments.copy()
    history_clamp(got_history, got_moments, length, current, depth, 1.0, weights)
    want_history, want_moments = ref.history_clamp(history, moments, length, current, depth,
                                                   1.0, weights)
    assert np.all(np.isfinite(got_moments))
    _close(got_history, want_history, 1e-6, "history")
    _close(got_moments, want_moments, 1e-5, "moments")
    raised = got_history[0, 1] > 1.0
    assert raised.all()
    lum = np.einsum("c,cyx->yx", np.array(weights, dtype=np.float64), got_history[0])
    np.testing.assert_allclose(got_moments[0, 0], lum, rtol=1e-6)
    np.testing.assert_allclose(got_moments[0, 1], lum * lum, rtol=1e-5)



def test_history_clamp_keeps_a_firefly_spread_finite() -> None:
    """A dim history whose moments hold a huge spread (a firefly of 1e15 once passed) is
    raised a hundred-thousandfold: the scaled second moment stays finite (capped at 1e36),
    so the variance does too."""
    current = np.full((1, 3, 3, 3), 100.0, dtype=F32)
    history = np.full_like(current, 1e-3)
    moments = np.stack([np.full((3, 3), 1e-3), np.full((3, 3), 1e30)])[None].astype(F32)
    length = np.full((1, 3, 3), 4.0, dtype=F32)
    depth = np.ones((3, 3), dtype=F32)
    weights = (F32(0.2126), F32(0.7152), F32(0.0722))
    got_history, got_moments = history.copy(), moments.copy()
    history_clamp(got_history, got_moments, length, current, depth, 1.0, weights)
    _, want_moments = ref.history_clamp(history, moments, length, current, depth, 1.0, weights)
    assert np.all(np.isfinite(got_moments))
    assert np.all(np.isfinite(got_moments[0, 1] - got_moments[0, 0] ** 2))
    _close(got_moments, want_moments, 1e-5, "moments")

# --------------------------------------------------------------------------- 2 reprojection
def _history_for(prev: Frame, seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    shape = prev.depth.shape
    return {
        "illumination": rng.gamma(2.0, 0.5, (2, 3, *shape)).astype(F32),
        "moments": rng.gamma(2.0, 0.5, (2, 2, *shape)).astype(F32),
        "length": rng.choice([1.0, 2.0, 3.5, 6.0, 32.0], size=(2, *shape)).astype(F32),
    }


def _run_reproject(prev: Frame, cur: Frame, history: dict[str, np.ndarray],
                   tolerances: tuple[float, float, float] = (10.0, 0.002, 16.0),
                   mode: np.ndarray | None = None, prev_mode: np.ndarray | None = None,
                   catmull_rom: bool = False):
    """The kernel and the reference on the same float32 geometry; returns both.

    ``mode`` and ``prev_mode`` are the kernels' uint16 masks (default: every signal
    demodulated everywhere); ``prev_mode`` may carry ``NO_HISTORY``."""
    g_prev, g_cur = kernel_geometry(prev), kernel_geometry(cur)
    num_signals = history["illumination"].shape[0]
    height, width = cur.depth.shape
    mode = np.zeros((height, width), np.uint16) if mode is None else mode
    prev_mode = np.zeros((height, width), np.uint16) if prev_mode is None else prev_mode
    out = (np.full((num_signals, 3, height, width), np.nan, F32),
           np.full((num_signals, 2, height, width), np.nan, F32),
           np.full((num_signals, height, width), np.nan, F32))
    reproject(cur.motion, cur.depth, g_cur["unit_normal"], cur.mesh_id, mode,
              g_cur["depth_slope"], g_cur["normal_width"], prev.depth, g_prev["unit_normal"],
              prev.mesh_id, prev_mode, history["illumination"], history["moments"],
              history["length"], *(F32(t) for t in tolerances), *out, catmull_rom=catmull_rom)
    previous = ref.History(history["illumination"].astype(np.float64),
                           history["moments"].astype(np.float64),
                           history["length"].astype(np.float64),
                           mode_bits(prev_mode, num_signals), prev_mode & NO_HISTORY == 0,
                           prev.depth.astype(np.float64),
                           g_prev["unit_normal"].astype(np.float64), prev.mesh_id)
    want = ref.reproject(cur.motion, as_reference(g_cur), cur.mesh_id,
                         mode_bits(mode, num_signals), previous, *tolerances, catmull_rom)
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
        assert np.sum(want.path[0] == ref.BILINEAR) > 250
        assert np.sum(want.path[0] == ref.FALLBACK) >= 5
        if t % 2 == 0:
            assert np.sum((want.path[0] == ref.REJECTED) & surface) >= 2


def test_reprojection_of_a_window_matches_the_whole_frame() -> None:
    """``origin``: the current frame's arrays cut to a window (object_history's box) give
    that window of the whole frame's result, bit for bit, taps outside the window included."""
    prev, cur = scene_frame(1), scene_frame(2)
    history = _history_for(prev, seed=3)
    out, want = _run_reproject(prev, cur, history)
    _assert_reprojection_matches(out, want)
    g_prev, g_cur = kernel_geometry(prev), kernel_geometry(cur)
    rows, columns = slice(3, 13), slice(5, 20)
    cut = np.ascontiguousarray
    height, width = rows.stop - rows.start, columns.stop - columns.start
    window = (np.full((2, 3, height, width), np.nan, F32),
              np.full((2, 2, height, width), np.nan, F32),
              np.full((2, height, width), np.nan, F32))
    reproject(cut(cur.motion[:, rows, columns]), cut(cur.depth[rows, columns]),
              cut(g_cur["unit_normal"][:, rows, columns]), cut(cur.mesh_id[rows, columns]),
              np.zeros((height, width), np.uint16), cut(g_cur["depth_slope"][rows, columns]),
              cut(g_cur["normal_width"][rows, columns]), prev.depth, g_prev["unit_normal"],
              prev.mesh_id, np.zeros(prev.depth.shape, np.uint16), history["illumination"],
              history["moments"], history["length"], F32(10.0), F32(0.002), F32(16.0),
              *window, origin=(rows.start, columns.start))
    for got, whole in zip(window, out, strict=True):
        np.testing.assert_array_equal(got, whole[..., rows, columns])
    # The window's taps reach outside it: a crop of last frame's arrays would lose them.
    reach = cur.motion[0, rows, columns] + np.arange(columns.start, columns.stop)
    assert np.any((reach < columns.start) | (reach >= columns.stop - 1))
    assert np.count_nonzero(window[2]) > 100  # 2 signals x 150 pixels


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
    assert np.sum(want.path[0] == ref.FALLBACK) > 10
    assert np.all(want.history_length[:, 5:8, :2][:, np.isnan(cur.motion[0, 5:8, :2])] == 0)


def _flat(width: int, height: int, **planes: np.ndarray) -> Frame:
    depth = np.full((height, width), 5.0, F32)
    normal = np.zeros((3, height, width), F32)
    normal[2] = 1.0
    frame = Frame.combined(np.ones((3, height, width), F32),
                           albedo=np.full((3, height, width), 0.5, F32), normal=normal,
                           depth=depth, motion=np.zeros((2, height, width), F32),
                           mesh_id=np.ones((height, width), np.int32))
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
    assert np.all(want.path[:, 1, 1] == ref.FALLBACK)
    box = [(ty, tx) for ty in range(1, 4) for tx in range(1, 4) if prev.mesh_id[ty, tx] == 1]
    for s in range(2):
        np.testing.assert_allclose(out[2][s, 1, 1],
                                   np.mean([history["length"][s][q] for q in box]), rtol=1e-6)
    assert np.all(want.path[:, 4, 4] == ref.BILINEAR)
    assert np.all(want.path[:, 8, 9] == ref.REJECTED) and np.all(out[2][:, 8, 9] == 0.0)
    assert np.all(want.path[:, 5, 0] == ref.BILINEAR)
    np.testing.assert_allclose(out[2][:, 5, 0], history["length"][:, 5, 0], rtol=1e-6)


def _guarded(history: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The history planes as views into buffers with a plane of NaN before and after: a
    kernel reading outside an array (even with weight 0) turns its output NaN."""
    guarded = {}
    for key, array in history.items():
        guard = array.shape[-2] * array.shape[-1]
        buffer = np.full(array.size + 2 * guard, np.nan, array.dtype)
        view = buffer[guard:guard + array.size].reshape(array.shape)
        view[...] = array
        guarded[key] = view
    return guarded


def test_reprojection_at_the_image_border_reads_only_inside() -> None:
    """Positions less than a pixel outside each side (and a corner): the bilinear taps
    outside get weight 0 and the inside ones are renormalised; the outside taps' memory is
    never read (the history sits between NaN guard planes)."""
    height, width = 10, 12
    prev = _flat(width, height)
    motion = np.zeros((2, height, width), F32)
    motion[1, 0, 3] = -0.4  # above the top row
    motion[1, height - 1, 3] = 0.4  # below the last row
    motion[0, 3, 0] = -0.4  # left of the first column
    motion[0, 3, width - 1] = 0.4  # right of the last column
    motion[:, 0, 0] = -0.4  # the top-left corner
    motion[:, height - 1, width - 1] = 0.4  # the bottom-right corner
    cur = _flat(width, height, motion=motion)
    out, want = _run_reproject(prev, cur, _guarded(_history_for(prev, seed=3)))
    assert all(np.isfinite(plane).all() for plane in out)
    _assert_reprojection_matches(out, want)
    for y, x in ((0, 3), (height - 1, 3), (3, 0), (3, width - 1), (0, 0),
                 (height - 1, width - 1)):
        assert np.all(want.path[:, y, x] == ref.BILINEAR)


def test_reprojection_from_just_outside_the_image_takes_the_fallback() -> None:
    """A position up to 1.5 pixels outside the image (both bilinear taps outside) rounds to
    the row or column next to the image, whose 3x3 box reaches the border pixels: the
    fallback averages them. Beyond 1.5 pixels the box is all outside: rejected. Each side."""
    height, width = 10, 12
    prev = _flat(width, height)
    motion = np.zeros((2, height, width), F32)
    motion[1, 0, 3], motion[1, 0, 6] = -1.4, -1.6  # above the top row
    motion[0, 3, 0], motion[0, 6, 0] = -1.4, -1.6  # left of the first column
    motion[1, height - 1, 3], motion[1, height - 1, 6] = 1.4, 1.6  # below the last row
    motion[0, 3, width - 1], motion[0, 6, width - 1] = 1.4, 1.6  # right of the last column
    cur = _flat(width, height, motion=motion)
    out, want = _run_reproject(prev, cur, _guarded(_history_for(prev, seed=2)))
    assert all(np.isfinite(plane).all() for plane in out)
    _assert_reprojection_matches(out, want)
    for inside, outside in (((0, 3), (0, 6)), ((3, 0), (6, 0)),
                            ((height - 1, 3), (height - 1, 6)),
                            ((3, width - 1), (6, width - 1))):
        assert np.all(want.path[(slice(None), *inside)] == ref.FALLBACK)
        assert np.all(out[2][(slice(None), *inside)] > 0)
        assert np.all(want.path[(slice(None), *outside)] == ref.REJECTED)
        assert np.all(out[2][(slice(None), *outside)] == 0)


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
    history["length"][:, :, width // 2:] = 2.0
    out, want = _run_reproject(prev, cur, history)
    _assert_reprojection_matches(out, want)
    length = out[2][1]
    inside = (slice(2, -2), slice(2, width // 2 - 2))
    assert np.all(length[inside] == 3.0)
    assert np.all(length[inside] + 1.0 >= 4.0)  # the next frame's h reaches the threshold
    mixed = length[2:-2, width // 2 - 1:width // 2 + 1]
    assert np.any((mixed > 2.0) & (mixed < 3.0))


def test_catmull_rom_reprojection_matches_reference() -> None:
    """The Catmull-Rom fetch against the float64 reference on the moving scene with a
    perturbed previous frame (ids, depths, normals, holes), reset pixels, radiance-mode
    pixels and sub-pixel jitter: where a tap of the 4x4 support fails (not only one of the
    bilinear four) the pixel keeps the renormalised bilinear fetch or the 3x3 fallback;
    positions whole in one axis use one column or row."""
    rng = np.random.default_rng(21)
    prev, cur = scene_frame(2), scene_frame(3)
    shape = prev.depth.shape
    surface = prev.depth > 0
    prev.mesh_id[(rng.random(shape) < 0.01) & surface] += 5
    prev.depth[(rng.random(shape) < 0.01) & surface] *= F32(0.9)
    prev.depth[rng.random(shape) < 0.01] = 0.0
    cur.motion += rng.uniform(-0.45, 0.45, cur.motion.shape).astype(F32)
    cur.motion[0, ::5] = np.round(cur.motion[0, ::5])  # whole in x: one column
    cur.motion[1, :, ::4] = np.round(cur.motion[1, :, ::4])  # whole in y: one row
    history = _history_for(prev, seed=5)
    # A bright spot: the spline's lobes overshoot it, the clamp must hold them.
    history["illumination"][:, :, 8:10, 10:12] *= 40.0
    prev_mode = np.zeros(shape, np.uint16)
    prev_mode[(rng.random(shape) < 0.01) & surface] = NO_HISTORY
    prev_mode[(rng.random(shape) < 0.01) & surface] = 2  # signal 1 was radiance there
    mode = np.zeros(shape, np.uint16)
    mode[10:12, 4:8] = 1  # signal 0 is radiance here now
    out, want = _run_reproject(prev, cur, history, mode=mode, prev_mode=prev_mode,
                               catmull_rom=True)
    _assert_reprojection_matches(out, want)
    assert np.all(out[0] >= 0.0)
    sharp = want.path == ref.CATMULL_ROM
    # The random moments are no pair of moments; the fetch makes them one where it applies.
    assert np.all(out[1][:, 1][sharp] >= out[1][:, 0][sharp] ** 2)
    assert sharp[0].sum() > 60
    assert np.sum(want.path[0] == ref.BILINEAR) > 30  # a support tap failed
    assert np.sum(want.path[0] == ref.FALLBACK) >= 5
    single_axis = sharp[0] & ((cur.motion[0] == np.round(cur.motion[0]))
                              | (cur.motion[1] == np.round(cur.motion[1])))
    assert single_axis.sum() > 20
    # It changed the history where it applies (bilinear blurs), and only there.
    bilinear, _ = _run_reproject(prev, cur, history, mode=mode, prev_mode=prev_mode)
    assert np.array_equal(out[2], bilinear[2])
    changed = np.any(out[0] != bilinear[0], axis=1)
    assert np.all(~changed | sharp) and changed[sharp].mean() > 0.9


def _scene_modes(frame: Frame) -> np.ndarray:
    """The uint16 mode mask of a frame's signals by the reference's rule."""
    return mode_mask(np.stack([ref.effective_albedo(signal.albedo, EPS)[0]
                               for signal in frame.signals]))


def test_reprojection_matches_taps_by_mode_per_signal() -> None:
    """Three signals with modes of their own (the moving black stripe changes the diffuse
    signal's mode under the history of some pixels, the glossy and transmission colours
    change mode at the object's edges) and reset (no-history) previous pixels: each signal
    uses only the taps of its own current mode, so the signals take different branches at
    the same pixel; reset taps serve no signal."""
    rng = np.random.default_rng(31)
    for t in (2, 3):
        prev, cur = scene_frame(t - 1, layout="three"), scene_frame(t, layout="three")
        shape = prev.depth.shape
        history = _history_for(prev, seed=t)
        history = {k: np.concatenate([v, v[:1]]) for k, v in history.items()}  # 3 signals
        prev_mode = _scene_modes(prev)
        reset = (rng.random(shape) < 0.06) & (prev.depth > 0)
        prev_mode[reset] = NO_HISTORY
        mode = _scene_modes(cur)
        out, want = _run_reproject(prev, cur, history, mode=mode, prev_mode=prev_mode)
        _assert_reprojection_matches(out, want)
        # Without the modes (and the resets) the same pixels would reproject differently.
        blind, blind_want = _run_reproject(prev, cur, history)
        _assert_reprojection_matches(blind, blind_want)
        surface = cur.depth > 0
        differ = (want.path != blind_want.path) & surface
        assert differ[0].sum() >= 4 and differ[2].sum() >= 2
        # The signals part: at some pixels one signal is rejected or falls back while
        # another resamples bilinearly.
        parted = np.any(want.path != want.path[:1], axis=0) & surface
        assert parted.sum() >= 4


def test_shared_weights_give_the_per_signal_bits() -> None:
    """Where every usable tap has the pixel's modes the kernel uses one set of weights for
    all signals; forcing the per-signal path (a third signal whose mode changed everywhere)
    must give signals 0 and 1 the same bits, and the third no history at all."""
    prev, cur = scene_frame(1), scene_frame(2)
    cur.motion += np.random.default_rng(5).uniform(-0.4, 0.4, cur.motion.shape).astype(F32)
    history = _history_for(prev, seed=4)
    shared, _ = _run_reproject(prev, cur, history)
    third = {k: np.concatenate([v, v[:1]]) for k, v in history.items()}
    shape = prev.depth.shape
    forced, want = _run_reproject(prev, cur, third, mode=np.zeros(shape, np.uint16),
                                  prev_mode=np.full(shape, 4, np.uint16))
    _assert_reprojection_matches(forced, want)
    for a, b in zip(shared, forced, strict=True):
        assert a.tobytes() == b[:2].tobytes()
    assert np.all(forced[2][2] == 0.0) and np.all(want.path[2] == ref.REJECTED)
    assert np.sum(want.path[0] == ref.FALLBACK) >= 5 and np.sum(want.path[0] == ref.BILINEAR)


# --------------------------------------------------------------------------- 2 accumulation
@pytest.mark.parametrize(("alpha", "moments_alpha", "cap", "weights"),
                         [(0.2, 0.2, 32.0, REC709), (0.05, 0.2, 8.0, ACESCG)])
def test_accumulation_matches_reference(alpha: float, moments_alpha: float, cap: float,
                                        weights: tuple) -> None:
    rng = np.random.default_rng(5)
    height, width = 6, 8
    current = rng.gamma(2.0, 0.5, (2, 3, height, width)).astype(F32)
    history = rng.gamma(2.0, 0.5, (2, 3, height, width)).astype(F32)
    moments = rng.gamma(2.0, 0.5, (2, 2, height, width)).astype(F32)
    lengths = [0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 7.5, 19.0, 31.0, 31.5, 40.0]
    # Each signal its own history length: signal 1's are signal 0's reversed.
    previous = rng.choice(lengths, size=(2, height, width)).astype(F32)
    previous[0, 0, :len(lengths)] = lengths[:width]
    previous[0, 1, :len(lengths) - width] = lengths[width:]
    previous[1] = previous[0, ::-1, ::-1]
    depth = np.full((height, width), 3.0, F32)
    depth[5, 2:5] = 0.0  # background: h = 0, current values
    out = (np.empty_like(current), np.empty_like(moments), np.empty_like(previous))
    accumulate(current, history, moments, previous, depth, F32(alpha), F32(moments_alpha),
               F32(cap), weights, *out)
    want = ref.accumulate(current, history, moments, previous, depth, alpha, moments_alpha, cap,
                          weights)
    _close(out[0], want[0], 1e-6, "illumination")
    _close(out[1], want[1], 1e-6, "moments")
    _close(out[2], want[2], 0.0, "history length")
    # The 1/h ramp, colour and moments alike: h_prev = 1 gives h = 2 and a blend of 1/2.
    lum = float(np.asarray(weights, np.float64) @ current[0, :, 0, 2])
    assert previous[0, 0, 2] == 1.0 and previous[1, 0, 2] != 1.0
    np.testing.assert_allclose(out[1][0, 0, 0, 2], 0.5 * moments[0, 0, 0, 2] + 0.5 * lum,
                               rtol=1e-6)
    np.testing.assert_allclose(out[0][0, :, 0, 2], 0.5 * (history + current)[0, :, 0, 2],
                               rtol=1e-6)
    assert not np.allclose(out[0][1, :, 0, 2], 0.5 * (history + current)[1, :, 0, 2])


# --------------------------------------------------------------------------- 3 variance
def _variance_inputs(seed: int) -> tuple[np.ndarray, ...]:
    """Accumulated-looking inputs of the three-signal scene (its modes) with mixed history
    lengths, different per signal: (illumination, moments, length, mode mask, frame)."""
    rng = np.random.default_rng(seed)
    frame = scene_frame(3, layout="three", luminance_weights=ACESCG_LUMINANCE)
    planes = [ref.demodulate(s.radiance, s.albedo, EPS) for s in frame.signals]
    illumination = np.stack([c for c, _, _ in planes]).astype(F32)
    mode = mode_mask(np.stack([m for _, m, _ in planes]))
    lum = ref.luminance(illumination, ACESCG_LUMINANCE)
    spread = rng.uniform(0.0, 0.5, lum.shape)
    moments = np.stack([lum, lum * lum + spread], axis=1).astype(F32)
    length = rng.choice([1.0, 2.0, 3.0, 3.5, 4.0, 6.0], size=(3, *frame.depth.shape))
    length[:, :, :6] = 1.0  # a cold band over the black patch and the left border
    length[1, :, 18:] = 6.0  # one signal long-history where the others are not
    length[:, frame.depth <= 0] = 0.0
    return illumination, moments, length.astype(F32), mode, frame


@pytest.mark.parametrize(("radius", "sigma_normal"), [(3, 128.0), (1, 128.0), (2, 64.0),
                                                      (3, 100.0)])
def test_spatial_variance_matches_reference(radius: int, sigma_normal: float) -> None:
    illumination, moments, length, mode, frame = _variance_inputs(seed=radius)
    g = kernel_geometry(frame)
    variance = np.full((3, *frame.depth.shape), -1.0, F32)
    blurred = np.full_like(illumination, -1.0)
    spatial_variance(illumination, moments, length, mode, frame.depth, g["ddx"], g["ddy"],
                     g["unit_normal"], F32(4.0), radius, F32(1.0), F32(10.0),
                     normal_squarings(sigma_normal), F32(sigma_normal), True, variance, blurred)
    radiance_mode = mode_bits(mode, 3)
    want_variance, want_colour, short = ref.spatial_variance(
        illumination, moments, length, radiance_mode, as_reference(g), 4.0, radius, 1.0, 10.0,
        sigma_normal)
    assert short.sum() > 300 and (~short & (frame.depth > 0)).sum() > 150
    _close(variance[short], want_variance[short], 2e-5, "spatial variance",
           float(moments[:, 1].max()))
    _close(np.moveaxis(blurred, 1, -1)[short], np.moveaxis(want_colour, 1, -1)[short], 2e-5,
           "blurred colour")
    assert np.all(variance[~short] == -1.0)  # other pixels untouched
    # The estimate is not trivially the temporal one, radiance-mode pixels are in it, and
    # the mode test matters: without it the estimate moves by far more than the tolerance.
    assert np.mean(np.abs(want_variance - ref.temporal_variance(moments))[short]) > 0.05
    assert np.any(short & radiance_mode)
    blind, _, _ = ref.spatial_variance(illumination, moments, length, np.zeros_like(short),
                                       as_reference(g), 4.0, radius, 1.0, 10.0, sigma_normal)
    assert np.sum(np.abs(blind - want_variance)[short] > 1e-3 * want_variance[short]) > 20


@pytest.mark.parametrize("blur", [False, True])
def test_variance_estimate_with_boost_matches_reference(blur: bool) -> None:
    from svgf_cli.filters.params import resolve_params

    illumination, moments, length, mode, frame = _variance_inputs(seed=11)
    g = kernel_geometry(frame)
    params = resolve_params("paper", spatial_variance_blur_color=blur)
    variance = np.empty((3, *frame.depth.shape), F32)
    colour = np.empty_like(illumination) if blur else None
    estimate_variance(illumination, moments, length, mode, frame.depth, g["ddx"], g["ddy"],
                      g["unit_normal"], history_threshold=4.0, radius=3, sigma_depth=1.0,
                      sigma_luminance=10.0, squarings=7, sigma_normal=128.0,
                      out_variance=variance, out_illumination=colour)
    want_variance, want_colour = ref.estimate_variance(illumination, moments, length,
                                                       mode_bits(mode, 3), as_reference(g),
                                                       params)
    m2_scale = float(moments[:, 1].max())
    _close(variance, want_variance, 2e-5, "variance", m2_scale)
    if blur:
        _close(colour, want_colour, 2e-5, "colour")
    temporal = np.empty_like(variance)
    temporal_variance(moments, temporal)
    _close(temporal, ref.temporal_variance(moments), 1e-6, "temporal variance", m2_scale)
    long_history = length >= 4.0
    np.testing.assert_array_equal(variance[long_history], temporal[long_history])
    boosted = variance.copy()
    boost_short_history(boosted, length, F32(4.0))
    _close(boosted, ref.boost_short_history(variance, length, 4.0), 1e-6, "boost")
    # The boost is 4 / h: h = 1, 2, 3, 3.5 pixels all present; signals decide on their own.
    assert {1.0, 2.0, 3.0, 3.5} <= set(np.unique(length[(length > 0) & (length < 4)]).tolist())
    assert np.any(long_history[1] & (length[0] < 4.0) & (length[0] > 0))


# --------------------------------------------------------------------------- TAA
def _two_surfaces(height: int, width: int) -> np.ndarray:
    """Depth: a far wall (8) with a near block (2) and a background corner (0)."""
    depth = np.full((height, width), 8.0, dtype=F32)
    depth[2:7, 2:9] = 2.0
    depth[:2, -3:] = 0.0
    return depth


def test_taa_outline_matches_reference_and_ignores_slopes() -> None:
    depth = _two_surfaces(9, 12)
    got = np.array([[on_outline(depth, y, x) and depth[y, x] > 0 for x in range(12)]
                    for y in range(9)])
    want = ref.taa_outline(depth)
    np.testing.assert_array_equal(got, want)
    # Both sides of the block's edge, two pixels wide, and the wall around the background.
    ring = want[1:8, 1:9].copy()
    ring[3, 3:6] = True
    assert ring.all() and not want[4, 4:7].any() and want[:3, -4].all()
    assert not want[8, 11] and not want[:2, -3:].any()  # far from any outline; background
    # A floor at a grazing angle: depth grows 4 % a row, 40 % over the image: no outline.
    slope = (2.0 * 1.04 ** np.arange(9, dtype=np.float64))[:, None] * np.ones((1, 12))
    assert not ref.taa_outline(slope).any()
    assert not any(on_outline(slope.astype(F32), y, x) for y in range(9) for x in range(12))


def test_taa_matches_reference() -> None:
    rng = np.random.default_rng(6)
    height, width = 9, 12
    current = rng.gamma(2.0, 0.5, (3, height, width)).astype(F32)
    current[:, 3, 4] = 40.0  # a light in the neighbourhood of outline pixels
    previous = rng.gamma(2.0, 0.5, (3, height, width)).astype(F32)
    motion = rng.uniform(-2.5, 2.5, (2, height, width)).astype(F32)
    motion[0, :, 0] = -0.75  # outside on the left (x - 0.75 < -0.5): current value
    motion[0, :, 1] = -1.25  # just inside the image: clamped taps
    motion[1, 0, :] = -0.25
    depth = _two_surfaces(height, width)
    weights = np.array(ACESCG, dtype=F32)
    out = np.empty_like(current)
    taa_resolve(current, previous, motion, depth, weights, F32(0.5), out)
    want = ref.taa_resolve(current, previous, motion, depth, ACESCG, 0.5)
    _close(out, want, 1e-5, "taa")
    outline = ref.taa_outline(depth)
    np.testing.assert_array_equal(out[:, ~outline], current[:, ~outline])
    np.testing.assert_array_equal(out[:, :, 0], current[:, :, 0])
    changed = np.any(out != current, axis=0)
    assert changed[outline].mean() > 0.5  # the blend did run where it may


def test_taa_follows_the_motion_of_a_translating_image() -> None:
    """An image that moved by exactly (+2, +1) px, outlines everywhere (depth alternating
    between columns): with its history reprojected through the backward motion, the blend
    returns the current image unchanged."""
    y, x = np.mgrid[0:12, 0:14].astype(np.float64)

    def image(shift_x: float, shift_y: float) -> np.ndarray:
        u, v = x - shift_x, y - shift_y
        return np.stack([1 + np.sin(0.9 * u), 1 + np.cos(0.7 * v), 1 + np.sin(0.5 * (u + v))]
                        ).astype(F32)

    previous, current = image(0, 0), image(2, 1)
    motion = np.stack([np.full(x.shape, -2.0), np.full(x.shape, -1.0)]).astype(F32)
    depth = np.where(x % 2 == 0, 1.0, 2.0).astype(F32)
    weights = np.array(REC709, dtype=F32)
    out = np.empty_like(current)
    taa_resolve(current, previous, motion, depth, weights, F32(0.1), out)
    inside = (slice(None), slice(1, None), slice(2, None))
    np.testing.assert_allclose(out[inside], current[inside], rtol=1e-6, atol=1e-6)
    _close(out, ref.taa_resolve(current, previous, motion, depth, REC709, 0.1), 1e-6)


# --------------------------------------------------------------------------- pixel filter
@pytest.mark.parametrize("weight", [0.05, 1.0 / 3.0])
def test_pixel_filter_matches_reference(weight: float) -> None:
    rng = np.random.default_rng(8)
    colour = rng.gamma(2.0, 0.5, (3, 7, 11)).astype(F32)
    emission = np.zeros_like(colour)
    emission[:, 2, 3:6] = 30.0  # a light: added back as it is
    colour += emission
    out = np.empty_like(colour)
    pixel_filter(colour, emission, F32(weight), out)
    _close(out, ref.pixel_filter(colour, emission, weight), 1e-6, "pixel filter")
    # Light does not leak: the pixels beside the light see only the rest's blur.
    assert np.all(out[:, 2, 2] < colour[:, 2, 2] + 1.0)


def test_pixel_filter_keeps_constants_and_ramps() -> None:
    y, x = np.mgrid[0:6, 0:9].astype(np.float64)
    ramp = np.stack([1.0 + 0.1 * x, 2.0 + 0.05 * y, np.full_like(x, 3.0)]).astype(F32)
    out = np.empty_like(ramp)
    pixel_filter(ramp, np.zeros_like(ramp), F32(0.05), out)
    # Linear ramps and constants stay; at the replicated edges a ramp bends by w * slope.
    np.testing.assert_allclose(out[:, 1:-1, 1:-1], ramp[:, 1:-1, 1:-1], rtol=1e-6)
    np.testing.assert_allclose(out[2], ramp[2], rtol=1e-6)
