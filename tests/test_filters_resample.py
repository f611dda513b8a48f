"""Properties of the Catmull-Rom history fetch (``filters.resample`` through ``reproject``).

The float64 reference comparison is ``test_reference_stages``'s
``test_catmull_rom_reprojection_matches_reference``; here: what it must never do (go
negative, move a constant, change a whole-pixel reprojection, depend on the threads) and
what it is for (less blur than bilinear when resampled frame after frame).
"""

from __future__ import annotations

import numba
import numpy as np
import reference_svgf as ref

from svgf_cli.filters.reproject import reproject
from svgf_cli.filters.resample import catmull_rom_weights

F32 = np.float32


def _flat_reproject(motion: np.ndarray, illumination: np.ndarray, moments: np.ndarray,
                    catmull_rom: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Reproject a history over a flat plane (every tap consistent) with ``motion``."""
    # Contiguous, as the Denoiser passes them: a view compiles the kernel again.
    motion, illumination, moments = (np.ascontiguousarray(a)
                                     for a in (motion, illumination, moments))
    num_signals, _, height, width = illumination.shape
    depth = np.full((height, width), 4.0, F32)
    normal = np.zeros((3, height, width), F32)
    normal[2] = 1.0
    mesh = np.ones((height, width), np.int32)
    mode = np.zeros((height, width), np.uint16)
    zeros = np.zeros((height, width), F32)
    length = np.full((num_signals, height, width), 5.0, F32)
    out = (np.full_like(illumination, np.nan), np.full_like(moments, np.nan),
           np.full_like(length, np.nan))
    reproject(motion, depth, normal, mesh, mode, zeros, zeros, depth, normal, mesh, mode,
              illumination, moments, length, F32(10.0), F32(0.002), F32(16.0), *out,
              catmull_rom=catmull_rom)
    return out


def _history(rng: np.random.Generator, shape: tuple[int, int]) -> tuple[np.ndarray, ...]:
    illumination = rng.gamma(1.5, 0.6, (2, 3, *shape)).astype(F32)
    m1 = rng.gamma(1.5, 0.6, (2, *shape)).astype(F32)
    moments = np.stack([m1, m1 * m1 * F32(1.3)], axis=1)
    return illumination, moments


def test_weights_are_the_catmull_rom_spline() -> None:
    for t in (0.0, 0.1, 0.25, 0.5, 0.75, 0.999):
        got = np.array(catmull_rom_weights(F32(t)), np.float64)
        np.testing.assert_allclose(got, ref.catmull_rom_weights(t), atol=1e-6)
        assert abs(got.sum() - 1.0) < 1e-6
    assert catmull_rom_weights(F32(0.0)) == (0.0, 1.0, 0.0, 0.0)


def test_never_negative_where_the_spline_overshoots() -> None:
    """Isolated bright pixels on black: the spline's negative lobes would give negative
    colour and moments around them; the clamp to the bilinear taps' range keeps 0."""
    rng = np.random.default_rng(3)
    shape = (20, 24)
    illumination = np.zeros((1, 3, *shape), F32)
    illumination[:, :, 4::6, 5::7] = 50.0
    moments = np.zeros((1, 2, *shape), F32)
    moments[:, 0, 4::6, 5::7] = 50.0
    moments[:, 1, 4::6, 5::7] = 2500.0
    motion = rng.uniform(-0.9, 0.9, (2, *shape)).astype(F32)
    colour, mom, _ = _flat_reproject(motion, illumination, moments, catmull_rom=True)
    assert colour.min() >= 0.0 and mom.min() >= 0.0
    assert np.all(mom[:, 1] >= mom[:, 0] ** 2)
    # The test can fail: unclamped, a spike under an outer tap's negative weight gives a
    # negative sum.
    assert catmull_rom_weights(F32(0.5))[0] < 0.0
    bilinear, _, _ = _flat_reproject(motion, illumination, moments, catmull_rom=False)
    assert np.any(colour != bilinear)


def test_constant_history_stays_constant() -> None:
    rng = np.random.default_rng(4)
    shape = (12, 16)
    illumination = np.full((2, 3, *shape), 0.37, F32)
    moments = np.stack([np.full((2, *shape), 0.37, F32),
                        np.full((2, *shape), F32(0.37) * F32(0.37), F32)], axis=1)
    motion = rng.uniform(-0.99, 0.99, (2, *shape)).astype(F32)
    colour, mom, length = _flat_reproject(motion, illumination, moments, catmull_rom=True)
    inside = (slice(None), slice(None), slice(2, -2), slice(2, -2))
    assert np.all(colour[inside] == F32(0.37))
    assert np.all(mom[inside] == moments[inside])
    assert np.all(length[:, 2:-2, 2:-2] == 5.0)


def test_whole_pixel_motion_is_exactly_the_bilinear_result() -> None:
    rng = np.random.default_rng(5)
    shape = (12, 16)
    illumination, moments = _history(rng, shape)
    motion = rng.integers(-2, 3, (2, *shape)).astype(F32)
    sharp = _flat_reproject(motion, illumination, moments, catmull_rom=True)
    bilinear = _flat_reproject(motion, illumination, moments, catmull_rom=False)
    for a, b in zip(sharp, bilinear, strict=True):
        assert a.tobytes() == b.tobytes()


def test_bit_identical_across_runs_and_thread_counts() -> None:
    rng = np.random.default_rng(6)
    shape = (17, 23)
    illumination, moments = _history(rng, shape)
    motion = rng.uniform(-1.5, 1.5, (2, *shape)).astype(F32)
    first = _flat_reproject(motion, illumination, moments, catmull_rom=True)
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        single = _flat_reproject(motion, illumination, moments, catmull_rom=True)
    finally:
        numba.set_num_threads(threads)
    again = _flat_reproject(motion, illumination, moments, catmull_rom=True)
    for a, b, c in zip(first, single, again, strict=True):
        assert a.tobytes() == b.tobytes() == c.tobytes()


def test_repeated_resampling_blurs_less_than_bilinear() -> None:
    """A stripe pattern of period 6 pixels resampled ten times at half-pixel offsets
    (motion +0.5 then -0.5: back where it started): bilinear halves its contrast every two
    frames or so, the spline keeps most of it."""
    height, width = 8, 48
    x = np.arange(width)
    pattern = (1.0 + 0.5 * np.sin(2 * np.pi * x / 6.0)).astype(F32)
    contrast = {}
    for catmull_rom in (False, True):
        colour = np.broadcast_to(pattern, (1, 3, height, width)).astype(F32)
        moments = np.stack([colour[:, 0], colour[:, 0] ** 2], axis=1)
        for frame in range(10):
            motion = np.zeros((2, height, width), F32)
            motion[0] = 0.5 if frame % 2 == 0 else -0.5
            colour, moments, _ = _flat_reproject(motion, colour, moments, catmull_rom)
        row = colour[0, 0, 4, 12:36]
        contrast[catmull_rom] = float(row.max() - row.min())
    assert contrast[False] < 0.3
    assert contrast[True] > 2.0 * contrast[False]
