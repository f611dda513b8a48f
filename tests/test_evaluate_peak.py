"""`metrics.peak_ratio`: the hot-pixel figure of issue 14 (output over the reference's local
5x5 maximum)."""

from __future__ import annotations

import numpy as np

from svgf_cli.evaluate.metrics import PEAK_FACTOR, PEAK_FLOOR, peak_ratio


def test_the_reference_itself_has_no_hot_pixel() -> None:
    reference = np.random.default_rng(1).uniform(0.1, 2.0, (3, 12, 16)).astype(np.float32)
    worst, share = peak_ratio(reference, reference)
    assert worst <= 1.0 and share == 0.0


def test_the_window_is_5x5_around_each_pixel() -> None:
    reference = np.full((3, 11, 11), 0.5, np.float32)
    reference[:, 5, 5] = 10.0  # a bright reference pixel lights its 5x5 neighbourhood
    image = reference.copy()
    image[1, 5, 7] = 25.0  # two pixels away: inside the window, 2.5x the local max
    worst, share = peak_ratio(image, reference)
    assert worst == 2.5 and share == 0.0
    image[1, 5, 8] = 25.0  # three away: outside, 50x the local 0.5
    worst, share = peak_ratio(image, reference)
    assert worst == 50.0 and share == 1 / 121


def test_black_references_use_the_floor_and_the_border_clips() -> None:
    reference = np.zeros((3, 6, 6), np.float32)
    image = np.zeros_like(reference)
    image[0, 0, 0] = 2.0 * PEAK_FLOOR  # dim: not hot
    worst, share = peak_ratio(image, reference)
    assert abs(worst - 2.0) < 1e-6 and share == 0.0
    image[2, 5, 5] = 5.0 * PEAK_FLOOR
    worst, share = peak_ratio(image, reference)
    assert abs(worst - 5.0) < 1e-6 and worst > PEAK_FACTOR and share == 1 / 36
