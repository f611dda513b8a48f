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
