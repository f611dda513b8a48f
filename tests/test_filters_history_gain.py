"""The history gain against the float64 reference (``reference_svgf.history_gain``), and its
behaviour: a light switched keeps its history, noise alone and a change beyond the largest
gain leave it alone, a moving shadow is left to anti-lag, bidirectional passes go without."""

from __future__ import annotations

import numpy as np
import pytest
from reference_svgf import history_gain as reference_history_gain

from svgf_cli.filters import pipeline
from svgf_cli.filters.antilag import antilag, cell_shape, scratch_shape
from svgf_cli.filters.history_gain import GAIN_MAX, history_gain
from svgf_cli.filters.params import PRESETS

F32 = np.float32
REC709 = np.array([0.2126, 0.7152, 0.0722], dtype=F32)
SIGMA, START, TOLERANCE, ALPHA = 3.5, 2.0, 0.02, 0.2


def _case(seed: int, height: int = 48, width: int = 64, step: float = 2.0,
          band_shift: int = 0, history: float = 8.0):
    """A lit surface (light 1) with a shadow band (0.2) at columns 20-27, seen with an
    8-frame history; the current frame 1-spp-like (exponential noise: variance = mean^2) with
    its light times ``step`` and its band moved by ``band_shift`` columns. Two signals, a
    patch of background and one of disocclusion (no history)."""
    rng = np.random.default_rng(seed)
    x = np.arange(width)[None, :].repeat(height, 0)
    truth_h = np.where((x >= 20) & (x < 28), 0.2, 1.0)
    truth_c = step * np.where((x >= 20 + band_shift) & (x < 28 + band_shift), 0.2, 1.0)
    current = np.empty((2, 3, height, width))
    illumination = np.empty((2, 3, height, width))
    moments = np.empty((2, 2, height, width))
    for s in range(2):
        current[s] = (truth_c * rng.exponential(1.0, (height, width)))[None]
        m1 = truth_h * (1.0 + np.sqrt(1.0 / history) * rng.standard_normal((height, width)))
        illumination[s] = m1[None] * np.array([1.0, 0.9, 0.8])[:, None, None]
        moments[s, 0] = m1
        moments[s, 1] = m1**2 + truth_h**2
    depth = np.full((height, width), 3.0)
    depth[0, :6] = 0.0  # background
    length = np.full((2, height, width), history)
    length[:, 9:12, 40:44] = 0.0  # a disocclusion
    length[:, depth <= 0] = 0.0
    return tuple(a.astype(F32) for a in (current, illumination, moments, length, depth))


def _gain(case, radius: int = 2):
    current, illumination, moments, length, depth = case
    illumination, moments = illumination.copy(), moments.copy()
    scratch = np.empty(scratch_shape(2, *depth.shape), F32)
    count = history_gain(current, illumination, moments, length, depth, REC709, radius, SIGMA,
                         START, TOLERANCE, ALPHA, scratch)
    return illumination, moments, count


def _antilag(current, moments, length, depth, radius: int = 2):
    length = length.copy()
    scratch = np.empty(scratch_shape(2, *depth.shape), F32)
    lam = np.empty((2, *cell_shape(*depth.shape)), F32)
    antilag(current, moments, length, depth, REC709, radius, SIGMA, 64.0, TOLERANCE, ALPHA,
            scratch, lam, sigma_start=2.0)
    return length


@pytest.mark.parametrize(("step", "shift", "radius", "size"),
                         [(2.0, 0, 2, (48, 64)), (0.5, 0, 1, (37, 51)), (1.6, 6, 2, (48, 64)),
                          (1.0, 0, 2, (48, 64)), (6.0, 0, 2, (30, 40))])
def test_matches_float64_reference(step, shift, radius, size):
    """Every rescaled value as the float64 reference's (odd sizes: partial cells)."""
    case = _case(5, *size, step=step, band_shift=shift)
    illumination, moments, count = _gain(case, radius)
    ref_illumination, ref_moments, _, ref_count = reference_history_gain(
        case[0], case[1], case[2], case[3], case[4], REC709, radius, SIGMA, START, TOLERANCE,
        ALPHA)
    assert count == ref_count
    np.testing.assert_allclose(illumination, ref_illumination, rtol=2e-4, atol=1e-6)
    np.testing.assert_allclose(moments, ref_moments, rtol=4e-4, atol=1e-6)


def test_a_light_switched_on_keeps_its_history():
    """The light doubles: the history is rescaled to the new level (its colour's ratios and
    shadow kept), and anti-lag, which without the gain restarts most of it, keeps it."""
    current, illumination, moments, length, depth = case = _case(11)
    rescaled, rescaled_moments, count = _gain(case)
    valid = (length > 0) & (depth > 0)[None]
    assert count > 0.9 * valid.sum()
    ratio = rescaled[:, 1][valid] / illumination[:, 1][valid]
    assert abs(np.median(ratio) - 2.0) < 0.1
    np.testing.assert_allclose(rescaled[:, 0] * 0.9, rescaled[:, 1] * 1.0, rtol=1e-5)
    kept = _antilag(current, rescaled_moments, length, depth)
    restarted = _antilag(current, moments, length, depth)
    assert np.mean(kept[valid] == 8.0) > 0.9
    assert np.mean(restarted[valid] < 2.0) > 0.5


@pytest.mark.parametrize("seed", range(4))
def test_noise_alone_changes_nothing(seed):
    """No change of light: not one history rescaled, every value the same bits."""
    case = _case(seed, step=1.0)
    illumination, moments, count = _gain(case)
    assert count == 0
    assert np.array_equal(illumination, case[1]) and np.array_equal(moments, case[2])


def test_beyond_the_largest_gain_is_left_to_antilag():
    """A light from (almost) nothing: no level to rescale, the history is left to anti-lag."""
    case = _case(3, step=GAIN_MAX * 1.5)
    _, _, count = _gain(case)
    assert count == 0


def test_a_moving_shadow_is_left_to_antilag():
    """The light brightens a little and the shadow band moves 6 columns: a factor rescales
    the surface around, but every history the band moved over (lit to shadow or back: its
    shape stale, not its level) is still shortened by anti-lag, as without the gain."""
    current, illumination, moments, length, depth = case = _case(7, step=1.3, band_shift=6)
    rescaled, rescaled_moments, count = _gain(case)
    assert count > 0
    moved = np.zeros(depth.shape, bool)
    moved[:, 20:34] = True  # lit then shadowed, or the other way
    valid = (length > 0) & (depth > 0)[None]
    after = _antilag(current, rescaled_moments, length, depth)
    assert np.all(after[valid & moved[None]] < 8.0)
    without = _antilag(current, moments, length, depth)
    assert np.all(without[valid & moved[None]] < 8.0)


def test_a_light_on_half_the_surface_rescales_that_half_only():
    """The light doubles on the left half only (columns below 32): the wide windows across
    the border measure a mixed factor (1.3-1.5). Beyond the anti-lag window's reach of the
    border (columns 40 on) the narrower windows reject it: most histories there are left
    alone and none is rescaled by the mixed factor (one sample a pixel: what is rescaled is
    within the checks' noise, up to 1.24 here); on the left, far from the border, the
    history doubles."""
    width = 64
    halves = np.where(np.arange(width) < 32, 2.0, 1.0)[None, :]
    case = _case(9, width=width, step=halves)
    rescaled, _, count = _gain(case)
    right = ((case[3] > 0) & (case[4] > 0)[None])[:, :, 40:52]
    factor = rescaled[:, 1, :, 40:52][right] / case[1][:, 1, :, 40:52][right]
    assert count > 0
    assert np.mean(factor != 1.0) < 0.35
    assert factor.max() < 1.28
    valid = (case[3] > 0) & (case[4] > 0)[None]
    left = valid[:, :, :20]
    ratio = rescaled[:, 1, :, :20][left] / case[1][:, 1, :, :20][left]
    assert abs(np.median(ratio) - 2.0) < 0.15


def test_the_gain_runs_in_causal_runs_only():
    """In the default's causal pipeline, before the history clamp and anti-lag; not in a
    bidirectional run's passes, nor in the paper's preset."""
    causal = pipeline.stage_names(PRESETS["default"], "causal")
    assert causal.index("history_gain") < causal.index("history_clamp") < causal.index("antilag")
    for kind in ("forward", "reverse"):
        assert "history_gain" not in pipeline.stage_names(PRESETS["default"], kind)
    assert "history_gain" not in pipeline.stage_names(PRESETS["paper"], "causal")
    off = PRESETS["default"].replace(antilag_gain=False)
    assert "history_gain" not in pipeline.stage_names(off, "causal")
