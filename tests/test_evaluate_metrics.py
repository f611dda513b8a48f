"""Each metric on cases whose answer is known in closed form."""

from __future__ import annotations

import math

import numpy as np
import pytest

from svgf_cli.evaluate import metrics


def _image(value: float, h: int = 24, w: int = 32) -> np.ndarray:
    return np.full((3, h, w), value, dtype=np.float32)


def _noise_image(seed: int, h: int = 24, w: int = 32) -> np.ndarray:
    return np.random.default_rng(seed).random((3, h, w), dtype=np.float32)


def test_tone_map_known_values() -> None:
    values = np.array([-1.0, 0.0, 1.0, 1e6], np.float32).reshape(1, 1, 4)
    out = metrics.tone_map(values)[0, 0]
    # Negative clamps to 0; c = 1 -> Reinhard 0.5 -> sRGB 1.055 * 0.5^(1/2.4) - 0.055.
    assert out[0] == 0.0
    assert out[1] == 0.0
    assert out[2] == pytest.approx(1.055 * 0.5 ** (1 / 2.4) - 0.055, abs=1e-6)
    assert 0.999 < out[3] <= 1.0
    ramp = metrics.tone_map(np.linspace(0, 50, 200, dtype=np.float32).reshape(1, 1, -1))
    assert np.all(np.diff(ramp[0, 0]) > 0), "the tone map must be strictly increasing"


def test_identical_images_are_perfect() -> None:
    ref = _noise_image(1) * 3.0
    display = metrics.tone_map(ref)
    assert metrics.rmse(ref, ref) == 0.0
    assert metrics.relmse(ref, ref) == 0.0
    assert metrics.psnr(display, display) == math.inf
    assert metrics.ssim(display, display) == pytest.approx(1.0, abs=1e-12)
    flip_mean, flip_map = metrics.flip(display, display)
    assert flip_mean == 0.0
    assert flip_map.shape == ref.shape[1:]
    assert metrics.temporal_error(display, display, display, display) == 0.0


def test_constant_offset_gives_known_rmse_relmse_psnr() -> None:
    ref = _image(0.5)
    out = ref + np.float32(0.1)
    assert metrics.rmse(out, ref) == pytest.approx(0.1, rel=1e-6)
    # relMSE = 0.1^2 / (0.5^2 + 0.01)
    assert metrics.relmse(out, ref) == pytest.approx(0.01 / 0.26, rel=1e-5)
    # PSNR on display images: an offset of 0.1 -> MSE 0.01 -> 20 dB.
    assert metrics.psnr(_image(0.6), _image(0.5)) == pytest.approx(20.0, abs=1e-5)


def test_relmse_epsilon_keeps_black_reference_finite() -> None:
    ref = _image(0.0)
    out = _image(0.1)
    assert metrics.relmse(out, ref) == pytest.approx(0.01 / metrics.RELMSE_EPSILON, rel=1e-5)


def test_ssim_of_constant_images_is_the_luminance_term() -> None:
    # Constant images have zero variance: SSIM = (2ab + C1) / (a^2 + b^2 + C1).
    a, b = 0.5, 0.625  # exact in float32
    c1 = (metrics.SSIM_K1 * 1.0) ** 2
    expected = (2 * a * b + c1) / (a * a + b * b + c1)
    assert metrics.ssim(_image(a), _image(b)) == pytest.approx(expected, rel=1e-7)


def test_ssim_falls_with_noise_and_is_symmetric() -> None:
    ref = metrics.tone_map(_image(0.8))
    ref = ref + 0.05 * np.sin(np.arange(32, dtype=np.float32) / 3.0)  # some structure
    rng = np.random.default_rng(3)
    light = ref + 0.02 * rng.standard_normal(ref.shape).astype(np.float32)
    heavy = ref + 0.2 * rng.standard_normal(ref.shape).astype(np.float32)
    s_light, s_heavy = metrics.ssim(light, ref), metrics.ssim(heavy, ref)
    assert 1.0 > s_light > s_heavy
    assert metrics.ssim(ref, heavy) == pytest.approx(s_heavy, rel=1e-12)


def test_gaussian_window_is_normalised_and_centred() -> None:
    taps = metrics.gaussian_window()
    assert len(taps) == 11
    assert taps.sum() == pytest.approx(1.0)
    assert np.argmax(taps) == 5
    assert taps[0] / taps[5] == pytest.approx(math.exp(-25 / (2 * 1.5**2)))


def test_flip_grows_with_the_difference() -> None:
    ref = metrics.tone_map(_noise_image(5))
    small, _ = metrics.flip(np.clip(ref + 0.02, 0, 1), ref)
    large, _ = metrics.flip(np.clip(ref + 0.3, 0, 1), ref)
    assert 0.0 < small < large <= 1.0


def test_temporal_error_flickering_vs_stable() -> None:
    refs = [metrics.tone_map(_noise_image(10 + t)) for t in range(4)]
    bias = np.float32(0.05)
    stable = [r + bias for r in refs]  # wrong, but wrong the same way every frame
    flicker = [r + bias * (-1) ** t for t, r in enumerate(refs)]
    for t in range(1, 4):
        assert metrics.temporal_error(stable[t], stable[t - 1], refs[t], refs[t - 1]) == (
            pytest.approx(0.0, abs=1e-7)
        )
        # (x_t - x_{t-1}) - (r_t - r_{t-1}) = +-2 * bias at every pixel.
        assert metrics.temporal_error(flicker[t], flicker[t - 1], refs[t], refs[t - 1]) == (
            pytest.approx(2 * bias, rel=1e-5)
        )


def test_nonfinite_pixels_counts_pixels_not_channels() -> None:
    image = _image(0.5)
    image[0, 1, 1] = np.nan
    image[2, 1, 1] = np.inf
    image[1, 3, 4] = -np.inf
    assert metrics.nonfinite_pixels(image) == 2


def _relmse_trimmed_f64(x: np.ndarray, r: np.ndarray, fraction: float, eps: float) -> float:
    """Float64 reference, written out pixel by pixel: sort, drop floor(fraction N), average."""
    _, h, w = x.shape
    errors = []
    for y in range(h):
        for i in range(w):
            e = 0.0
            for c in range(3):
                d = float(x[c, y, i]) - float(r[c, y, i])
                e += d * d / (float(r[c, y, i]) ** 2 + eps)
            errors.append(e / 3.0)
    errors.sort()
    keep = errors[: len(errors) - math.floor(fraction * len(errors))]
    return math.fsum(keep) / len(keep)


def test_relmse_trimmed_matches_the_float64_reference() -> None:
    rng = np.random.default_rng(21)
    ref = (rng.random((3, 40, 50)) * 2.0).astype(np.float32)
    out = ref * (1.0 + 0.2 * rng.standard_normal(ref.shape)).astype(np.float32)
    for y, x in [(3, 4), (20, 33), (39, 49)]:  # fireflies: 3 of 2000 pixels, 2 are dropped
        out[:, y, x] = 500.0
    fraction, eps = metrics.RELMSE_TRIM_FRACTION, metrics.RELMSE_EPSILON
    expected = _relmse_trimmed_f64(out, ref, fraction, eps)
    assert metrics.relmse_trimmed(out, ref) == pytest.approx(expected, rel=1e-12)
    # Two of the three fireflies are gone, one still counts: far below the plain relMSE,
    # far above the firefly-free error.
    clean = out.copy()
    for y, x in [(3, 4), (20, 33), (39, 49)]:
        clean[:, y, x] = ref[:, y, x]
    assert metrics.relmse(clean, ref) < metrics.relmse_trimmed(out, ref) < metrics.relmse(out, ref)
    one_left = _relmse_trimmed_f64(out, ref, 1.0 / 2000, eps)  # drops exactly one
    one_dropped = metrics.relmse_trimmed(out, ref, fraction=1.0 / 2000)
    assert one_dropped == pytest.approx(one_left, rel=1e-12)


def test_relmse_trimmed_drops_nothing_below_a_thousand_pixels() -> None:
    ref, out = _noise_image(1) + 0.5, _noise_image(2) + 0.5  # 768 pixels
    assert metrics.relmse_trimmed(out, ref) == pytest.approx(metrics.relmse(out, ref), rel=1e-12)
    assert metrics.relmse_trimmed(ref, ref) == 0.0


def _hot_ratio_f64(x: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Float64 reference of the hot-pixel ratio: explicit window loops, clipped at the border."""
    wr, wg, wb = 0.2126, 0.7152, 0.0722
    x, r = x.astype(np.float64), r.astype(np.float64)
    lum_x = wr * x[0] + wg * x[1] + wb * x[2]
    lum_r = wr * r[0] + wg * r[1] + wb * r[2]
    floor = 0.01 * math.fsum(lum_r.ravel()) / lum_r.size
    h, w = lum_r.shape
    ratio = np.empty((h, w))
    for y in range(h):
        for i in range(w):
            local = max(
                lum_r[yy, xx]
                for yy in range(max(0, y - 2), min(h, y + 3))
                for xx in range(max(0, i - 2), min(w, i + 3))
            )
            ratio[y, i] = lum_x[y, i] / (local + floor)
    return ratio


def test_hot_pixel_ratio_matches_the_float64_reference() -> None:
    rng = np.random.default_rng(5)
    ref = (rng.random((3, 17, 23)) ** 3).astype(np.float32)
    ref[:, 8, 11] = 40.0  # a bright reference pixel raises its own 5x5 window only
    out = ref * (1.0 + 0.1 * rng.standard_normal(ref.shape)).astype(np.float32)
    out[:, 0, 0] = 25.0  # a firefly in a corner (clipped window)
    out[:, 10, 13] = 30.0  # next to the bright reference pixel: within its window
    out[:, 16, 22] = 7.0
    expected = _hot_ratio_f64(out, ref)
    ratio = metrics.hot_pixel_ratio(out, ref)
    np.testing.assert_allclose(ratio, expected, rtol=1e-12, atol=0)
    worst, share = metrics.hot_pixels(out, ref)
    assert worst == pytest.approx(expected.max(), rel=1e-12)
    assert share == np.count_nonzero(expected > 3.0) / expected.size
    assert ratio[10, 13] < 1.0, "a pixel next to a bright reference pixel is not hot"
    assert ratio[0, 0] > 3.0 and ratio[16, 22] > 3.0


def test_hot_pixel_ratio_is_scale_free_and_finite_on_black() -> None:
    rng = np.random.default_rng(8)
    ref = rng.random((3, 12, 16)).astype(np.float32)
    out = ref.copy()
    out[:, 5, 5] *= 20.0
    base = metrics.hot_pixel_ratio(out, ref)
    for k in (1e-3, 1e3):
        scaled = metrics.hot_pixel_ratio(out * np.float32(k), ref * np.float32(k))
        np.testing.assert_allclose(scaled, base, rtol=1e-5)
    black = np.zeros_like(ref)
    worst, share = metrics.hot_pixels(black, black)
    assert worst == 0.0 and share == 0.0
    assert metrics.hot_pixels(out, out)[0] <= 1.0, "the reference itself is never hot"
