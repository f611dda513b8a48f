"""The anti-lag stage against a float64 transcription of its equations, and its behaviour
on noise alone (no false alarms), on a lighting step and on a moving edge."""

from __future__ import annotations

import numpy as np
import pytest

from svgf_cli.filters.antilag import MIN_SAMPLES, antilag

F32 = np.float32
REC709 = np.array([0.2126, 0.7152, 0.0722], dtype=F32)


def _reference(current, history, moments, history_length, depth, weights, radius, sigma,
               spatial_samples, tolerance):
    """Window statistics, blend weight, 3x3 dilation and the shortened history length for
    every pixel and signal, in float64, one window at a time."""
    w = weights.astype(np.float64)
    num_signals, _, height, width = current.shape
    lam = np.zeros((num_signals, height, width))
    new_length = history_length.astype(np.float64).copy()
    for s in range(num_signals):
        lum = np.einsum("c,chw->hw", w, current[s].astype(np.float64))
        lum_h = np.einsum("c,chw->hw", w, history[s].astype(np.float64))
        m1 = moments[s, 0].astype(np.float64)
        temporal = np.maximum(moments[s, 1].astype(np.float64) - m1 * m1, 0.0)
        valid = (history_length[s] > 0) & (depth > 0)
        raw = np.zeros((height, width))
        for y in range(height):
            for x in range(width):
                window = (slice(max(y - radius, 0), y + radius + 1),
                          slice(max(x - radius, 0), x + radius + 1))
                v = valid[window]
                n = v.sum()
                if n < MIN_SAMPLES:
                    continue
                c = lum[window][v]
                mean_c = c.mean()
                mean_h = lum_h[window][v].mean()
                var = max(c.var(ddof=1), temporal[window][v].mean())
                level = max(mean_c, mean_h)
                diff2 = (mean_h - mean_c) ** 2
                if diff2 > sigma**2 * var / n + (tolerance * level) ** 2:
                    bias2 = diff2 - var / n
                    raw[y, x] = bias2 / (bias2 + var / spatial_samples)
        for y in range(height):
            for x in range(width):
                best = raw[max(y - 1, 0):y + 2, max(x - 1, 0):x + 2].max()
                if valid[y, x] and best > 0:
                    lam[s, y, x] = best
                    new_length[s, y, x] = min(new_length[s, y, x], max(1.0 / best - 1.0, 0.0))
    return lam, new_length


def _case(seed: int, height: int = 20, width: int = 28, num_signals: int = 2,
          step: float = 1.0, edge_shift: int = 0):
    """History of a lit surface with a dark band; the current frame 1-spp-like noisy, its
    light scaled by ``step`` and its band moved by ``edge_shift`` pixels."""
    rng = np.random.default_rng(seed)
    x = np.arange(width)[None, :].repeat(height, 0)
    truth_h = np.where((x >= 8) & (x < 14), 0.2, 1.0)
    truth_c = step * np.where((x >= 8 + edge_shift) & (x < 14 + edge_shift), 0.2, 1.0)
    current = np.empty((num_signals, 3, height, width))
    history = np.empty_like(current)
    moments = np.empty((num_signals, 2, height, width))
    for s in range(num_signals):
        noise = rng.exponential(1.0, (height, width))
        current[s] = (truth_c * noise)[None]
        history[s] = (truth_h * (1.0 + 0.05 * rng.standard_normal((height, width))))[None]
        moments[s, 0] = truth_h
        moments[s, 1] = 2.0 * truth_h**2  # exponential noise: variance = mean^2
    depth = np.full((height, width), 3.0)
    depth[0, :5] = 0.0  # background
    length = np.full((num_signals, height, width), 8.0)
    length[:, 5:7, 3:6] = 0.0  # a disocclusion
    length[:, depth <= 0] = 0.0
    return (current.astype(F32), history.astype(F32), moments.astype(F32),
            length.astype(F32), depth.astype(F32))


def _run(case, radius=4, sigma=3.0, spatial_samples=16.0, tolerance=0.02, weights=REC709):
    current, history, moments, length, depth = case
    length = length.copy()
    num_signals, _, height, width = current.shape
    scratch = np.empty((5, height, width), F32)
    lam = np.empty((num_signals, height, width), F32)
    count = antilag(current, history, moments, length, depth, weights, radius, sigma,
                    spatial_samples, tolerance, scratch, lam)
    return lam, length, count


@pytest.mark.parametrize(
    ("step", "shift", "radius", "weights"),
    [(1.0, 0, 4, REC709), (0.45, 0, 4, REC709), (1.0, 4, 2, REC709),
     (0.7, 3, 3, np.array([0.2722, 0.6741, 0.0537], F32))],
)
def test_matches_float64_reference(step, shift, radius, weights):
    case = _case(3, step=step, edge_shift=shift)
    lam, length, count = _run(case, radius=radius, weights=weights)
    ref_lam, ref_length = _reference(*case, weights, radius, 3.0, 16.0, 0.02)
    np.testing.assert_allclose(lam, ref_lam, rtol=2e-4, atol=2e-5)
    np.testing.assert_allclose(length, ref_length, rtol=2e-4, atol=2e-4)
    assert count == int(np.count_nonzero(ref_length < case[3] - 1e-3))


def test_noise_alone_keeps_the_history():
    """Fresh 1-spp noise around an unchanged mean: (almost) no history is shortened."""
    shortened = 0
    total = 0
    for seed in range(6):
        case = _case(seed, height=32, width=48)
        _, length, count = _run(case)
        shortened += count
        total += int(np.count_nonzero(case[3] > 0))
    assert shortened / total < 0.01


def test_lighting_step_drops_the_history():
    """The light dims to 45%: every pixel whose window has enough history is mostly reset
    (with 1-spp noise of variance mean^2 and N = 16 the optimal weight is about 0.8)."""
    case = _case(1, height=32, width=48, step=0.45)
    lam, length, _ = _run(case)
    has_history = case[3] > 0
    assert np.mean(lam[has_history] > 0.7) > 0.95
    assert np.mean(length[has_history] < 0.43) > 0.95


def test_moving_edge_is_local():
    """A dark band that moved by 4 pixels: history drops in and around the band only."""
    case = _case(2, height=32, width=60, edge_shift=4)
    lam, _, _ = _run(case, radius=2)
    changed = lam[:, 8:, :].mean(axis=(0, 1))  # per column, rows clear of the holes
    assert changed[10:16].min() > 0.5  # where the band was and now is
    assert changed[30:].mean() < 0.01  # far from it only rare noise alarms (k = 3)


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e3])
def test_scale_invariant(scale):
    case = _case(4, step=0.6, edge_shift=2)
    scaled = (case[0] * F32(scale), case[1] * F32(scale), case[2] * F32(scale), case[3],
              case[4])
    scaled[2][:, 1] *= F32(scale)  # the second moment scales with the square
    lam, length, _ = _run(case)
    lam_k, length_k, _ = _run(scaled)
    np.testing.assert_allclose(lam_k, lam, rtol=1e-3, atol=1e-5)
    np.testing.assert_allclose(length_k, length, rtol=1e-3, atol=1e-3)
