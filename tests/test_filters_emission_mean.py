"""A still light's jittered outline (``filters.emission_mean``, the ``still_emission_mean``
stage): where nothing moves, the emission added back is its running mean, so the outline
shows the light's coverage instead of flipping; what moves, or a light that changes, is
left as sampled."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import reference_svgf as ref

from svgf_cli.filters.denoiser import Denoiser
from svgf_cli.filters.emission_mean import emission_mean
from svgf_cli.filters.params import resolve_params
from svgf_cli.io.exr import read_frame
from svgf_cli.io.layers import build_mapping

F32 = np.float32
DATA = Path(__file__).resolve().parents[1] / "testdata"


def _state(height: int, width: int) -> dict[str, np.ndarray]:
    return {"mean": np.zeros((3, height, width), F32), "length": np.zeros((height, width), F32),
            "still": np.zeros((height, width), np.uint8), "level": np.zeros((height, width), F32)}


def _run(planes: dict[str, np.ndarray], emission: np.ndarray, motion: np.ndarray,
         alpha: float = 0.2, cap: float = 32.0) -> np.ndarray:
    emission_mean(emission, motion, planes["mean"], planes["length"], planes["still"],
                  planes["level"], F32(alpha), F32(cap))
    return planes["mean"].copy()


def _light(rng: np.random.Generator, h: int = 12, w: int = 16, radiance: float = 12.5
           ) -> np.ndarray:
    """A light over rows 4-7 whose outline rows 3 and 8 are hit by a random share of
    jittered samples."""
    lit = np.zeros((h, w), bool)
    lit[4:8, 3:13] = True
    lit[3, 3:13] = rng.random(10) < 0.3
    lit[8, 3:13] = rng.random(10) < 0.6
    return (lit[None] * np.array([radiance, 0.8 * radiance, 0.3 * radiance])[:, None, None]
            ).astype(F32)


def test_the_kernel_matches_the_float64_reference() -> None:
    rng = np.random.default_rng(7)
    h, w = 12, 16
    planes, state = _state(h, w), None
    for frame in range(6):
        emission = _light(rng, radiance=12.5 if frame < 4 else 6.0)  # dims at frame 4
        motion = np.zeros((2, h, w), F32)
        motion[0, :, 12:] = 0.5 if frame == 2 else 0.0  # the right edge moves once
        got = _run(planes, emission, motion)
        want, state = ref.emission_mean(emission, motion, state, 0.2, 32.0)
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)


def test_a_still_outline_converges_to_its_coverage_and_the_rest_stays_exact() -> None:
    rng = np.random.default_rng(1)
    h, w = 12, 16
    planes, motion = _state(h, w), np.zeros((2, h, w), F32)
    frames = [_light(rng) for _ in range(40)]
    for emission in frames:
        got = _run(planes, emission, motion)
    coverage = np.mean(frames, axis=0)  # the samples' own mean over the 40 frames
    outline = (slice(None), slice(8, 9), slice(3, 13))
    # A running mean (weight at least alpha = 0.2 a frame): far nearer the coverage than the
    # last frame's flip between the radiance and nothing (about a third of its distance).
    off_mean = np.abs(got[outline] - coverage[outline]).mean()
    assert off_mean < 0.4 * np.abs(frames[-1][outline] - coverage[outline]).mean()
    inside, away = (slice(None), slice(5, 7), slice(4, 12)), (slice(None), slice(0, 2))
    np.testing.assert_array_equal(got[inside], frames[-1][inside])
    np.testing.assert_array_equal(got[away], frames[-1][away])


def test_what_moves_and_a_light_that_changes_start_over() -> None:
    rng = np.random.default_rng(2)
    h, w = 12, 16
    planes, still = _state(h, w), np.zeros((2, h, w), F32)
    for _ in range(5):
        _run(planes, _light(rng), still)
    moving = still.copy()
    moving[1, 9, 5] = 0.3  # one pixel below the outline moves: its 3x3 starts over
    emission = _light(rng)
    got = _run(planes, emission, moving)
    np.testing.assert_array_equal(got[:, 8, 4:7], emission[:, 8, 4:7])
    assert not np.array_equal(got[:, 8, 8:13], emission[:, 8, 8:13])
    # The light dims to half: every outline pixel shows this frame's sample, no lag.
    dim = _light(rng) * F32(0.5)
    np.testing.assert_array_equal(_run(planes, dim, still), dim)


def _frames(folder: str, count: int) -> list:
    mapping = build_mapping("svgf")
    return [read_frame(DATA / folder / f"in.{f:04d}.exr", mapping).frame
            for f in range(1, count + 1)]


def _outputs(denoiser: Denoiser, frames: list) -> list[np.ndarray]:
    return [denoiser.process(f).color.copy() for f in frames]


def test_mitsubas_still_light_flickers_less_at_its_outline_and_nothing_else_changes() -> None:
    """mitsuba/lag/shadow (still camera and light, jittered): only the light's outline
    and the pixels next to it change, and its outline changes less from frame to frame.
    mitsuba/seq (the camera moves) and seq (pixel centres) are left bit for bit."""
    params = resolve_params("default")
    frames = _frames("mitsuba/lag/shadow", 6)
    on = _outputs(Denoiser(params), frames)
    off = _outputs(Denoiser(params.replace(still_emission_mean=False)), frames)
    lit = np.stack([f.emission.max(axis=0) > 0 for f in frames])
    outline = lit.any(axis=0) & ~lit.all(axis=0)  # lit on some frames, not on others
    near = np.zeros_like(outline)
    for dy in range(-2, 3):
        for dx in range(-2, 3):
            near |= np.roll(np.roll(outline, dy, axis=0), dx, axis=1)
    changed = np.any(np.stack(on) != np.stack(off), axis=(0, 1))
    assert changed[outline].any() and not changed[~near].any()

    def flicker(outs: list[np.ndarray]) -> float:
        return float(np.mean([np.abs(a - b)[:, outline].mean()
                              for a, b in zip(outs[2:], outs[1:], strict=False)]))

    assert flicker(on) < 0.7 * flicker(off)
    for folder in ("mitsuba/seq", "seq"):
        plain = _frames(folder, 3)
        assert all(np.array_equal(a, b) for a, b in zip(
            _outputs(Denoiser(params), plain),
            _outputs(Denoiser(params.replace(still_emission_mean=False)), plain),
            strict=True)), folder


def test_the_means_carry_over_in_a_saved_state() -> None:
    params = resolve_params("default")
    frames = _frames("mitsuba/lag/shadow", 5)
    whole = _outputs(Denoiser(params), frames)
    first = Denoiser(params)
    _outputs(first, frames[:3])
    state = first.state()
    assert "emission_mean_mean" in state
    resumed = Denoiser(params)
    resumed.load_state(state)
    for want, got in zip(whole[3:], _outputs(resumed, frames[3:]), strict=True):
        np.testing.assert_array_equal(got, want)
