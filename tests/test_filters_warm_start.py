"""The look-ahead warm-up of a shot's first frames (filters.warm_start, docs/stability.md)."""

from __future__ import annotations

import numpy as np
import pytest
from moving_scene import scene_frame, scene_sequence

from svgf_cli.filters.denoiser import Denoiser
from svgf_cli.filters.params import resolve_params
from svgf_cli.filters.taa import taa_resolve
from svgf_cli.filters.two_pass import denoise_bidirectional
from svgf_cli.filters.warm_start import denoise_warm_start, lookahead_params

PARAMS = resolve_params("default")


def _causal(frames: list) -> list[np.ndarray]:
    denoiser = Denoiser(PARAMS)
    return [denoiser.process(frame).color for frame in frames]


def test_warm_frames_are_the_bidirectional_run_the_rest_the_causal_run() -> None:
    frames = scene_sequence(7)
    got = [o.color for o in denoise_warm_start(iter(frames), PARAMS, warm=2, lookahead=4)]
    bidirectional = denoise_bidirectional(frames[:4], PARAMS)
    causal = _causal(frames)
    assert len(got) == len(frames)
    for t in range(2):  # the handover is at frame ``warm``, not ``lookahead``
        np.testing.assert_array_equal(got[t], bidirectional[t].color, err_msg=f"frame {t}")
    for t in range(2, 7):  # the causal run saw every frame from the first: its own history
        np.testing.assert_array_equal(got[t], causal[t], err_msg=f"frame {t}")


def test_the_first_frames_are_closer_to_the_truth_than_a_cold_start() -> None:
    frames = scene_sequence(6)
    truth = [scene_frame(t, noise=False).total_radiance() for t in range(2)]
    warmed = list(denoise_warm_start(frames, PARAMS, warm=2, lookahead=6))
    cold = _causal(frames)
    for t in range(2):
        warm_error = np.mean((warmed[t].color - truth[t]) ** 2)
        cold_error = np.mean((cold[t] - truth[t]) ** 2)
        assert warm_error < 0.9 * cold_error, (t, warm_error, cold_error)


def test_no_warm_frames_is_the_causal_run_and_short_shots_are_looked_ahead_whole() -> None:
    frames = scene_sequence(3)
    causal = _causal(frames)
    plain = [o.color for o in denoise_warm_start(frames, PARAMS, warm=0)]
    short = [o.color for o in denoise_warm_start(frames, PARAMS, warm=2, lookahead=8)]
    bidirectional = denoise_bidirectional(frames, PARAMS)
    for t in range(3):
        np.testing.assert_array_equal(plain[t], causal[t])
    np.testing.assert_array_equal(short[0], bidirectional[0].color)
    np.testing.assert_array_equal(short[2], causal[2])
    with pytest.raises(ValueError, match="warm"):
        next(denoise_warm_start(frames, PARAMS, warm=5, lookahead=4))


def test_taa_anti_aliases_the_warm_colours_and_carries_on_from_them() -> None:
    """With TAA (forced; the default gives it jittered frames) the look-ahead anti-aliases
    the warm colours backwards in time, and they go through the causal run's TAA: the first
    as it is (no history yet), the next blended with it at the outlines (the kernel's blend
    of the two warm colours), nowhere else."""
    import reference_svgf as ref

    # (No noisy outlines' exchanges after TAA: they would carry its change a pixel on.)
    params = PARAMS.replace(taa=True, noisy_outline_weight=0.0)
    frames = scene_sequence(6)
    got = [o.color for o in denoise_warm_start(frames, params, warm=3, lookahead=6)]
    warm = [o.color for o in denoise_bidirectional(frames, lookahead_params(params))[:3]]
    np.testing.assert_array_equal(got[0], warm[0])
    # The look-ahead's own TAA, backwards: the first warm colour anti-aliased at its outlines.
    plain_warm = denoise_bidirectional(frames, params.replace(taa=False))[0].color
    first_outline = ref.taa_outline(frames[0].depth)
    assert np.any(warm[0] != plain_warm)
    np.testing.assert_array_equal(warm[0][:, ~first_outline], plain_warm[:, ~first_outline])
    frame = frames[1]
    want = np.empty_like(warm[1])
    taa_resolve(warm[1], warm[0], frame.motion, frame.depth,
                np.array(frame.luminance_weights, dtype=np.float32),
                np.float32(params.taa_alpha), want)
    np.testing.assert_array_equal(got[1], want)
    near = ref.taa_resolve(warm[1], warm[0], frame.motion, frame.depth,
                           frame.luminance_weights, params.taa_alpha)
    np.testing.assert_allclose(got[1], near, rtol=1e-3, atol=1e-5)  # float32 clip bounds
    outline = ref.taa_outline(frame.depth)
    assert np.any(got[1] != warm[1]) and np.array_equal(got[1][:, ~outline], warm[1][:, ~outline])
    # From frame 3 on the causal output, anti-aliased with the warm frames as its history.
    plain = [o.color for o in denoise_warm_start(frames, params.replace(taa=False), warm=0)]
    assert not np.array_equal(got[3], plain[3])
    np.testing.assert_array_equal(got[3][:, ~ref.taa_outline(frames[3].depth)],
                                  plain[3][:, ~ref.taa_outline(frames[3].depth)])


def test_the_default_warm_start_covers_the_causal_runs_young_history() -> None:
    """The `default` preset's 8 warm frames (docs/stability.md#warm-start): with 4, frames
    5-8 were the causal run's, its history 4 to 7 frames young; from a look-ahead over 16
    (the whole of this 12-frame shot) they are closer to the truth."""
    frames = scene_sequence(12)
    truth = {t: scene_frame(t, noise=False).total_radiance() for t in range(4, 8)}

    def error(warm: int, lookahead: int) -> float:
        out = list(denoise_warm_start(frames, PARAMS, warm=warm, lookahead=lookahead))
        return float(np.mean([np.mean((out[t].color - truth[t]) ** 2) for t in truth]))

    assert PARAMS.warm_start == 8
    before, now = error(4, 8), error(PARAMS.warm_start, 2 * PARAMS.warm_start)
    assert now < 0.95 * before, (now, before)  # measured 0.89x
