"""The anti-lag stage against the float64 reference (``reference_svgf.antilag``), and its
behaviour on noise alone (no false alarms), on a lighting step, on a moving edge, with
temporal gradient samples, and through the Denoiser."""

from __future__ import annotations

import numpy as np
import pytest
from reference_svgf import antilag as reference_antilag

from svgf_cli.filters.antilag import antilag, cell_shape, scratch_shape
from svgf_cli.filters.params import SVGFParams

F32 = np.float32
REC709 = np.array([0.2126, 0.7152, 0.0722], dtype=F32)


def _reference(current, moments, history_length, depth, weights, radius, sigma,
               spatial_samples, tolerance, moments_alpha=0.2, gradients=None,
               sigma_start=None):
    """The float64 reference stage (lambda per cell, new history length), with its own
    minimum of four pixels with history per window."""
    lam, length, _ = reference_antilag(current, moments, history_length, depth, weights,
                                       radius, sigma, spatial_samples, tolerance,
                                       moments_alpha, gradients, sigma_start=sigma_start)
    return lam, length


def _case(seed: int, height: int = 20, width: int = 28, num_signals: int = 2,
          step: float = 1.0, edge_shift: int = 0, noise_sigma: float | None = None):
    """History of a lit surface with a dark band; the current frame 1-spp-like noisy, its
    light scaled by ``step`` and its band moved by ``edge_shift`` pixels. Noise: exponential
    (variance = mean^2), or Gaussian with relative ``noise_sigma``."""
    rng = np.random.default_rng(seed)
    x = np.arange(width)[None, :].repeat(height, 0)
    truth_h = np.where((x >= 8) & (x < 14), 0.2, 1.0)
    truth_c = step * np.where((x >= 8 + edge_shift) & (x < 14 + edge_shift), 0.2, 1.0)
    current = np.empty((num_signals, 3, height, width))
    moments = np.empty((num_signals, 2, height, width))
    for s in range(num_signals):
        if noise_sigma is None:
            noise = rng.exponential(1.0, (height, width))
            relative_var = 1.0
        else:
            noise = 1.0 + noise_sigma * rng.standard_normal((height, width))
            relative_var = noise_sigma**2
        current[s] = (truth_c * noise)[None]
        # an 8-frame history: the first moment carries 1/8 of a sample's variance
        spread = np.sqrt(relative_var / 8.0)
        moments[s, 0] = truth_h * (1.0 + spread * rng.standard_normal((height, width)))
        moments[s, 1] = moments[s, 0] ** 2 + relative_var * truth_h**2
    depth = np.full((height, width), 3.0)
    depth[0, :5] = 0.0  # background
    length = np.full((num_signals, height, width), 8.0)
    length[:, 5:7, 3:6] = 0.0  # a disocclusion
    length[:, depth <= 0] = 0.0
    return current.astype(F32), moments.astype(F32), length.astype(F32), depth.astype(F32)


def _run(case, radius=2, sigma=3.0, spatial_samples=32.0, tolerance=0.02, weights=REC709,
         gradients=None, moments_alpha=0.2, sigma_start=None):
    current, moments, length, depth = case
    length = length.copy()
    num_signals, _, height, width = current.shape
    cells = cell_shape(height, width)
    scratch = np.empty(scratch_shape(num_signals, height, width), F32)
    lam = np.empty((num_signals, *cells), F32)
    count = antilag(current, moments, length, depth, weights, radius, sigma,
                    spatial_samples, tolerance, moments_alpha, scratch, lam, gradients,
                    sigma_start)
    return lam, length, count


@pytest.mark.parametrize(
    ("step", "shift", "radius", "weights"),
    [(1.0, 0, 2, REC709), (0.45, 0, 2, REC709), (1.0, 4, 1, REC709),
     (0.7, 3, 3, np.array([0.2722, 0.6741, 0.0537], F32))],
)
def test_matches_float64_reference(step, shift, radius, weights):
    case = _case(3, height=21, width=27, step=step, edge_shift=shift)  # odd: partial cells
    lam, length, count = _run(case, radius=radius, weights=weights)
    ref_lam, ref_length = _reference(*case, weights, radius, 3.0, 32.0, 0.02)
    np.testing.assert_allclose(lam, ref_lam, rtol=2e-4, atol=2e-5)
    np.testing.assert_allclose(length, ref_length, rtol=2e-4, atol=2e-4)
    assert count == int(np.count_nonzero(ref_length < case[2] - 1e-3))


@pytest.mark.parametrize("step", [0.7, 0.8, 0.9])
def test_matches_float64_reference_when_the_stationary_noise_share_binds(step):
    # With moments_alpha 0.5 the history's stationary noise share a/(2-a) = 1/3 exceeds
    # 1/h = 1/8: the staleness threshold uses it. Moderate light changes put cells on both
    # sides of that threshold.
    case = _case(5, height=21, width=27, step=step)
    lam, length, count = _run(case, moments_alpha=0.5)
    ref_lam, ref_length = _reference(*case, REC709, 2, 3.0, 32.0, 0.02, moments_alpha=0.5)
    np.testing.assert_allclose(lam, ref_lam, rtol=2e-4, atol=2e-5)
    np.testing.assert_allclose(length, ref_length, rtol=2e-4, atol=2e-4)
    assert count == int(np.count_nonzero(ref_length < case[2] - 1e-3))


@pytest.mark.parametrize(("step", "shift"), [(1.0, 0), (0.8, 0), (0.9, 3), (0.45, 0)])
def test_the_ramp_matches_float64_reference(step, shift):
    """The weight ramped in from ``sigma_start`` (2) to ``sigma`` (3.5): cells on the ramp,
    above it and below it (a small dimming and a moved edge under 1-spp noise)."""
    case = _case(7, height=21, width=27, step=step, edge_shift=shift)
    lam, length, count = _run(case, sigma=3.5, sigma_start=2.0)
    ref_lam, ref_length = _reference(*case, REC709, 2, 3.5, 32.0, 0.02, sigma_start=2.0)
    np.testing.assert_allclose(lam, ref_lam, rtol=2e-4, atol=2e-5)
    np.testing.assert_allclose(length, ref_length, rtol=2e-4, atol=2e-4)
    assert count == int(np.count_nonzero(ref_length < case[2] - 1e-3))


def _flat_case(history_mean: float, temporal_variance: float, size: int = 12):
    """One signal, grey current luminance 1 everywhere, an 8-frame history whose first
    moment is ``history_mean`` and whose temporal variance is ``temporal_variance``: every
    window's statistics are known exactly (radius 1: 36 pixels inside, 24 on an edge)."""
    current = np.ones((1, 3, size, size), F32)
    m1 = np.full((size, size), history_mean)
    moments = np.stack([m1, m1 * m1 + temporal_variance])[None].astype(F32)
    length = np.full((1, size, size), 8.0, F32)
    depth = np.ones((size, size), F32)
    return current, moments, length, depth


@pytest.mark.parametrize(("factor", "stale"), [(1.27, False), (1.40, True)])
def test_staleness_threshold_counts_the_stationary_noise_share(factor, stale):
    """With moments_alpha 0.5 the history's own noise share is a/(2-a) = 1/3 (above 1/h):
    a window of n = 36 is stale when diff^2 > k^2 var/n (1 + 1/3). A difference 1.27x the
    bare k^2 var/n stays (it would not with a share of 0.2), 1.40x is stale."""
    temporal_variance = 0.04
    bare = 9.0 * temporal_variance / 36.0  # k = 3, radius 1, an inside window
    case = _flat_case(1.0 + np.sqrt(factor * bare), temporal_variance)
    lam, length, count = _run(case, radius=1, sigma=3.0, tolerance=0.0, moments_alpha=0.5)
    ref_lam, ref_length = _reference(*case, REC709, 1, 3.0, 32.0, 0.0, moments_alpha=0.5)
    np.testing.assert_allclose(lam, ref_lam, rtol=2e-4, atol=2e-5)
    np.testing.assert_allclose(length, ref_length, rtol=2e-4, atol=2e-4)
    inside = lam[0, 1:-1, 1:-1]
    if stale:
        assert np.all(inside > 0) and count > 0
    else:
        assert np.all(lam == 0) and count == 0


@pytest.mark.parametrize("z", [1.9, 2.5, 3.2, 4.0])
def test_the_weight_ramps_in_with_the_standard_errors(z):
    """On a flat window (k0 = 2, k = 3.5, n = 36, share 1/3) a difference of z standard
    errors gets the weight ``r b^2 / (b^2 + var/N)``, r = (z - 2) / 1.5 up to 1: nothing
    below the start, a share on the ramp, all of it from 3.5."""
    temporal_variance = 0.04
    error2 = temporal_variance / 36.0 * (1.0 + 1.0 / 3.0)
    case = _flat_case(1.0 + z * np.sqrt(error2), temporal_variance)
    lam, _, _ = _run(case, radius=1, sigma=3.5, sigma_start=2.0, tolerance=0.0,
                     moments_alpha=0.5)
    bias2 = z * z * error2 - temporal_variance / 36.0
    ramp = min(max((z - 2.0) / 1.5, 0.0), 1.0)
    want = ramp * bias2 / (bias2 + temporal_variance / 32.0)
    np.testing.assert_allclose(lam[0, 1:-1, 1:-1], want, rtol=2e-3, atol=1e-6)
    step, _, _ = _run(case, radius=1, sigma=3.5, tolerance=0.0, moments_alpha=0.5)
    if z < 3.5:  # a step at 3.5 keeps it all; above, the ramp and the step agree
        assert np.all(step == 0)
    else:
        np.testing.assert_array_equal(step, lam)


def _kept_on_noise(sigma: float, sigma_start: float | None) -> float:
    """The share of the history's frames anti-lag keeps on fresh 1-spp noise around an
    unchanged mean (six realisations)."""
    before = after = 0.0
    for seed in range(6):
        case = _case(seed, height=32, width=48)
        _, length, _ = _run(case, sigma=sigma, sigma_start=sigma_start, spatial_samples=64.0)
        before += float(case[2].sum())
        after += float(length.sum())
    return after / before


def test_the_ramp_costs_pure_noise_little_history():
    """At the default's significance the ramp keeps most of the history on noise alone
    (measured 0.957 of its frames; the step at 3.5 all of it) and loses less than half of
    what a step at the ramp's start would (0.883 kept)."""
    params = SVGFParams()
    ramp = _kept_on_noise(params.antilag_sigma, params.antilag_sigma_start)
    step_at_start = _kept_on_noise(params.antilag_sigma_start, None)
    assert _kept_on_noise(params.antilag_sigma, None) == 1.0
    assert ramp > 0.9 and 1.0 - ramp < 0.5 * (1.0 - step_at_start)


@pytest.mark.parametrize(("pixels", "decides"), [(4, True), (3, False)])
def test_a_window_decides_from_four_pixels_with_history(pixels, decides):
    """A window needs four pixels with history: with fewer its statistics are noise and it
    makes no decision, however far the history is off (here 3x the current level)."""
    case = _flat_case(3.0, 0.01)
    length = case[2]
    length[:] = 0.0
    block = [(4, 4), (4, 5), (5, 4), (5, 5)][:pixels]  # one cell
    for y, x in block:
        length[0, y, x] = 8.0
    lam, out_length, count = _run(case, radius=1)
    ref_lam, ref_length = _reference(*case, REC709, 1, 3.0, 32.0, 0.02)
    np.testing.assert_allclose(lam, ref_lam, rtol=2e-4, atol=2e-5)
    np.testing.assert_allclose(out_length, ref_length, rtol=2e-4, atol=2e-4)
    if decides:
        assert count == pixels and np.all(out_length[0, 4:6, 4:6] < 1.0)
    else:
        assert count == 0 and np.all(lam == 0)


def _gradient_samples(seed, height, width, num_signals, change, noise=0.0):
    """One sample per 3x3 stratum; the shading changed by the factor ``change`` (plus some
    re-shading noise)."""
    rng = np.random.default_rng(seed)
    samples = []
    for _ in range(num_signals):
        mask = np.zeros((height, width), F32)
        mask[1::3, 1::3] = 1.0
        previous = (mask * rng.uniform(0.5, 1.5, (height, width))).astype(F32)
        current = previous * F32(change)
        current = (current + mask * noise * rng.standard_normal((height, width))).astype(F32)
        samples.append((mask, previous, np.maximum(current, 0).astype(F32)))
    return samples


@pytest.mark.parametrize(("change", "noise"), [(1.0, 0.0), (0.8, 0.0), (0.9, 0.4)])
def test_gradient_samples_match_float64_reference(change, noise):
    case = _case(5, height=21, width=27, step=0.95)
    gradients = _gradient_samples(6, 21, 27, 2, change, noise)
    gradients[1] = None  # a signal without samples
    lam, length, count = _run(case, gradients=gradients)
    ref_lam, ref_length = _reference(*case, REC709, 2, 3.0, 32.0, 0.02, gradients=gradients)
    np.testing.assert_allclose(lam, ref_lam, rtol=2e-4, atol=2e-5)
    np.testing.assert_allclose(length, ref_length, rtol=2e-4, atol=2e-4)


@pytest.mark.parametrize("samples", [1, 2])
def test_one_gradient_sample_is_no_evidence(samples):
    """A window's gradient samples count only from two on (their spread is unknown with
    one): a single sample that halved decides nothing, two that agree shorten the history.
    The window statistics themselves see no change here."""
    case = _flat_case(1.0, 0.01)
    mask = np.zeros((12, 12), F32)
    mask[5, 5:5 + samples] = 1.0
    previous = mask.copy()
    current = (mask * F32(0.5)).astype(F32)
    gradients = [(mask, previous, current)]
    lam, length, count = _run(case, radius=1, gradients=gradients)
    ref_lam, ref_length = _reference(*case, REC709, 1, 3.0, 32.0, 0.02, gradients=gradients)
    np.testing.assert_allclose(lam, ref_lam, rtol=2e-4, atol=2e-5)
    np.testing.assert_allclose(length, ref_length, rtol=2e-4, atol=2e-4)
    if samples == 1:
        assert count == 0 and np.all(lam == 0)
    else:
        assert count > 0 and lam.max() > 0.5


def test_gradient_samples_see_what_the_noise_hides():
    """A 20% dimming is lost in 1-spp noise for the window statistics but plain in the
    re-shaded samples; unchanged samples change nothing."""
    case = _case(7, height=32, width=48, step=0.8)
    has_history = case[2] > 0
    _, plain, _ = _run(case, sigma=3.5)
    unchanged = _gradient_samples(8, 32, 48, 2, 1.0)
    _, same, _ = _run(case, sigma=3.5, gradients=unchanged)
    dimmed = _gradient_samples(8, 32, 48, 2, 0.8)
    _, shortened, _ = _run(case, sigma=3.5, gradients=dimmed)
    assert np.mean(plain[has_history] < case[2][has_history]) < 0.3
    np.testing.assert_array_equal(same, plain)
    assert np.mean(shortened[has_history] < case[2][has_history]) > 0.9


def test_noise_alone_keeps_the_history():
    """Fresh 1-spp noise around an unchanged mean: (almost) no history is shortened."""
    shortened = 0
    total = 0
    for seed in range(6):
        case = _case(seed, height=32, width=48)
        _, length, count = _run(case)
        shortened += count
        total += int(np.count_nonzero(case[2] > 0))
    assert shortened / total < 0.01


def test_lighting_step_drops_the_history():
    """The light dims to 45%: every pixel with history is mostly reset (with 1-spp noise of
    variance mean^2 and N = 32 the optimal weight is about 0.9)."""
    case = _case(1, height=32, width=48, step=0.45)
    _, length, _ = _run(case)
    has_history = case[2] > 0
    assert np.mean(length[has_history] < 1.0 / 0.8 - 1.0) > 0.95


def test_moving_edge_is_local():
    """A dark band that moved by 4 pixels under moderate noise (30%): history drops in and
    around the band only."""
    case = _case(2, height=32, width=60, edge_shift=4, noise_sigma=0.3)
    _, length, _ = _run(case)
    reset = (length[:, 8:, :] < 1.0).mean(axis=(0, 1))  # per column, rows clear of the holes
    assert reset[8:18].min() > 0.9  # where the band was and now is
    assert reset[30:].mean() < 0.05  # far from it only rare noise alarms (k = 3)


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e3])
def test_scale_invariant(scale):
    case = _case(4, step=0.6, edge_shift=2)
    moments = case[1] * F32(scale)
    moments[:, 1] *= F32(scale)  # the second moment scales with the square
    scaled = (case[0] * F32(scale), moments, case[2], case[3])
    lam, length, _ = _run(case)
    lam_k, length_k, _ = _run(scaled)
    np.testing.assert_allclose(lam_k, lam, rtol=1e-3, atol=1e-5)
    np.testing.assert_allclose(length_k, length, rtol=1e-3, atol=1e-3)


# ---------------------------------------------------------------- through the Denoiser


def _dimming_run(params, dim_at: int, frames: int = 10, factor: float = 0.45):
    """A static textured scene at 1 spp whose light drops to ``factor`` at ``dim_at``;
    per-frame relative error of the output against the noise-free radiance."""
    from synthetic import make_frame, texture, true_radiance

    from svgf_cli.filters.denoiser import Denoiser

    width, height = 48, 32
    # Smooth light over a detailed albedo: the filter's error is then the noise it leaves
    # and the lag, not blurred lighting detail.
    illumination = texture(width, height, seed=5, low=0.6, high=1.4, period=60.0)
    albedo = texture(width, height, seed=6, low=0.2, high=0.9, period=5.0)
    denoiser = Denoiser(params)
    errors = []
    for index in range(frames):
        level = factor if index >= dim_at else 1.0
        frame = make_frame(width, height, illumination=illumination * level, albedo=albedo,
                           noise_kind="exponential", seed=100 + index, split=False)
        out = denoiser.process(frame).color
        truth = true_radiance(illumination * level, width=width, height=height, albedo=albedo,
                              split=False)
        errors.append(float(np.mean(np.abs(out - truth)) / np.mean(truth)))
    return errors


def test_denoiser_drops_stale_history_after_a_light_change():
    """The paper preset drags the old brightness for frames; with anti-lag the frame of the
    change is close to a cold (spatial-only) frame and the next ones are better still."""
    from svgf_cli.filters.params import PRESETS

    paper = _dimming_run(PRESETS["paper"], dim_at=6)
    antilag_on = _dimming_run(PRESETS["default"], dim_at=6)
    cold = _dimming_run(PRESETS["paper"].replace(temporal=False), dim_at=6)
    assert paper[6] > 3.0 * cold[6]  # the lag anti-lag has to remove
    assert antilag_on[6] < 1.5 * cold[6]
    assert antilag_on[7] < cold[7] and antilag_on[8] < cold[8]
    assert max(antilag_on[6:]) < 0.5 * max(paper[6:])


def test_denoiser_keeps_history_when_nothing_changes():
    """Nothing changes: anti-lag shortens (almost) no history and the result matches the
    paper preset's."""
    from svgf_cli.filters.params import PRESETS

    paper = _dimming_run(PRESETS["paper"], dim_at=99)
    antilag_on = _dimming_run(PRESETS["default"], dim_at=99)
    assert np.mean(antilag_on[3:]) < 1.05 * np.mean(paper[3:])
