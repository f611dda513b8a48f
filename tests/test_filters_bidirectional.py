"""Bidirectional filtering: the combination and motion-inversion kernels against their
float64 references, the spill format's error, and both passes of the whole Denoiser against
``reference_svgf.reference_bidirectional`` frame by frame (the tolerance and its reasoning
are those of ``test_reference_denoiser``)."""

from __future__ import annotations

import numpy as np
import pytest
import reference_svgf as ref
from moving_scene import ACESCG_LUMINANCE, scene_sequence

from svgf_cli.filters.bidirectional import (
    CONSISTENCY_SIGMA,
    GLOSSY_REFERENCE_COUNT,
    PASS_ANTILAG_SIGMA_SCALE,
    STATIC_FILTERED_SHARE,
    STATIC_MOTION,
    SideHistory,
    combine_histories,
    consistent_lengths,
    effective_counts,
    pack_history,
    unpack_history,
)
from svgf_cli.filters.denoiser import Denoiser
from svgf_cli.filters.fastmath import float32_weights
from svgf_cli.filters.invert_motion import NO_MOTION, invert_motion
from svgf_cli.filters.params import resolve_params
from svgf_cli.filters.two_pass import ForwardPass, Keep, ReversePass, denoise_bidirectional

F32 = np.float32
TOLERANCE = 2e-4


def _close(got: np.ndarray, want: np.ndarray, what: str) -> None:
    scale = float(np.max(np.abs(want)))
    np.testing.assert_allclose(got, want, rtol=TOLERANCE, atol=TOLERANCE * scale, err_msg=what)


@pytest.mark.parametrize("alpha", [0.2, 0.05, 0.3])
def test_effective_counts_follow_the_blend_schedule(alpha: float) -> None:
    table = effective_counts(alpha, 32)
    for k in range(33):
        assert table[k] == pytest.approx(ref.effective_count(k, alpha), rel=1e-6)
    # a uniform mean while 1/k >= alpha, then rising towards the exponential average's
    # (2 - a)/a (reached by 32 frames for alpha 0.2 and 0.3, not yet for 0.05)
    uniform = np.arange(1, int(1 / alpha) + 1)
    np.testing.assert_allclose(table[uniform], uniform, rtol=1e-6)
    assert np.all(np.diff(table) >= 0) and table[32] <= (2 - alpha) / alpha * (1 + 1e-6)
    if alpha >= 0.2:
        assert table[32] == pytest.approx((2 - alpha) / alpha, rel=1e-3)


def _random_side(rng: np.random.Generator, lengths: np.ndarray) -> SideHistory:
    shape = lengths.shape
    colour = rng.exponential(1.0, (shape[0], 3, *shape[1:])).astype(F32)
    m1 = rng.exponential(1.0, shape).astype(F32)
    moments = np.stack([m1, m1 * m1 * rng.uniform(1.0, 3.0, shape).astype(F32)], axis=1)
    return SideHistory(colour, moments.astype(F32), lengths.astype(F32))


def test_combine_histories_matches_the_reference() -> None:
    rng = np.random.default_rng(3)
    shape = (2, 9, 11)
    choices = np.array([0.0, 0.4, 1.0, 2.5, 3.0, 7.25, 32.0])
    forward = _random_side(rng, rng.choice(choices, shape))
    reverse = _random_side(rng, rng.choice(choices, shape))
    forward.length[:, :2] = reverse.length[:, :2] = 0.0  # neither side has history there
    current = rng.exponential(2.0, (shape[0], 3, *shape[1:])).astype(F32)
    depth = np.where(rng.random(shape[1:]) < 0.15, 0.0, 4.0).astype(F32)
    params = resolve_params("falcor")  # alpha 0.05, moments alpha 0.2: the two tables differ
    # n_ref per signal: a glossy signal's and a long causal history's count
    reference_counts = [GLOSSY_REFERENCE_COUNT,
                        float(effective_counts(params.moments_alpha, 32)[-1])]
    # in place: the forward history's buffers receive the combination
    out = (forward.colour.copy(), forward.moments.copy(), forward.length.copy())
    combine_histories(current, reverse.colour, reverse.moments, reverse.length, depth,
                      effective_counts(params.alpha, 32),
                      effective_counts(params.moments_alpha, 32),
                      float32_weights(ACESCG_LUMINANCE), np.array(reference_counts, F32), *out)

    def side(s: SideHistory) -> ref.Reprojected:
        return ref.Reprojected(s.colour, s.moments, s.length, np.zeros(s.length.shape))

    want = ref.combine_histories(current, side(forward), side(reverse), depth, params.alpha,
                                 params.moments_alpha, ACESCG_LUMINANCE, reference_counts)
    for got, expected, what in zip(out, want, ("colour", "moments", "length"), strict=True):
        np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-6, err_msg=what)
    # the current sample counts once: with no history on either side the result is it
    alone = (forward.length == 0) & (reverse.length == 0) & (depth > 0)
    assert alone.any()
    np.testing.assert_array_equal(np.moveaxis(out[0], 1, 0)[:, alone],
                                  np.moveaxis(current, 1, 0)[:, alone])
    assert np.all(out[2][:, depth <= 0] == 0)


def _disagreeing_sides(rng: np.random.Generator, shape: tuple[int, int, int]
                       ) -> tuple[SideHistory, SideHistory, np.ndarray]:
    """Two sides with per-sample variance ``v`` and a current frame: on a third of the
    pixels the reverse side is off by 2-12 standard errors, the frame near either side."""
    choices = np.array([0.0, 0.6, 1.0, 2.5, 4.0, 7.25, 32.0])
    forward = _random_side(rng, rng.choice(choices, shape))
    reverse = _random_side(rng, rng.choice(choices, shape))
    var = rng.uniform(0.05, 0.5, shape).astype(F32)
    m1f = rng.uniform(0.5, 2.0, shape).astype(F32)
    offset = np.where(rng.random(shape) < 0.33, rng.uniform(2.0, 12.0, shape), 0.3)
    m1r = (m1f + offset * np.sqrt(var) * rng.choice([-1.0, 1.0], shape)).astype(F32)
    m1r = np.abs(m1r)
    for side, m1 in ((forward, m1f), (reverse, m1r)):
        side.moments[:, 0] = m1
        side.moments[:, 1] = m1 * m1 + var
    # the frame's luminance near the forward side, the reverse side or between them
    share = rng.choice([0.0, 0.15, 0.5, 0.85, 1.0], shape)
    lum = (1.0 - share) * m1f + share * m1r + rng.normal(0, 0.1, shape) * np.sqrt(var)
    current = np.repeat(np.maximum(lum, 0.0)[:, None], 3, axis=1).astype(F32)
    return forward, reverse, current


def test_consistent_lengths_matches_the_reference() -> None:
    rng = np.random.default_rng(7)
    shape = (2, 10, 13)
    forward, reverse, current = _disagreeing_sides(rng, shape)
    depth = np.where(rng.random(shape[1:]) < 0.1, 0.0, 3.0).astype(F32)
    alpha = 0.2
    counts = effective_counts(alpha, 32)
    # in place for the forward side, as a run calls it
    hf, hr = forward.length.copy(), np.empty_like(reverse.length)
    consistent_lengths(current, forward.moments, hf, reverse.moments, reverse.length, depth,
                       counts, float32_weights(ref.REC709), F32(CONSISTENCY_SIGMA), hf, hr)

    def side(s: SideHistory) -> ref.Reprojected:
        return ref.Reprojected(s.colour, s.moments, s.length, np.zeros(s.length.shape))

    want_f, want_r = ref.consistent_lengths(current, side(forward), side(reverse), depth,
                                            alpha, CONSISTENCY_SIGMA)
    np.testing.assert_allclose(hf, want_f, rtol=1e-4, atol=1e-4, err_msg="forward")
    np.testing.assert_allclose(hr, want_r, rtol=1e-4, atol=1e-4, err_msg="reverse")
    # lengths only ever shrink, and somewhere each side did
    assert np.all(hf <= forward.length) and np.all(hr <= reverse.length)
    assert np.any(hf < forward.length - 0.5) and np.any(hr < reverse.length - 0.5)


@pytest.mark.parametrize("frame_at", ["forward", "reverse", "between"])
def test_consistency_drops_the_side_the_frame_disagrees_with(frame_at: str) -> None:
    """Sides 20 per-sample standard deviations apart: the frame decides; between them it
    cannot, and within the noise nothing changes."""
    shape = (1, 1, 3)
    length = np.full(shape, 8.0, F32)
    var = F32(0.04)  # standard deviation 0.2 per sample
    m1f = np.array([[[1.0, 1.0, 1.0]]], F32)
    # pixel 0 and 1: 4 apart (far beyond the noise); pixel 2: 0.1 apart (within it)
    m1r = np.array([[[5.0, 5.0, 1.1]]], F32)
    lum = {"forward": 1.0, "reverse": 5.0, "between": 3.0}[frame_at]
    current = np.full((1, 3, 1, 3), lum, F32)
    current[..., 2] = 1.05

    def moments(m1: np.ndarray) -> np.ndarray:
        return np.stack([m1, m1 * m1 + var], axis=1).astype(F32)

    hf, hr = np.empty_like(length), np.empty_like(length)
    consistent_lengths(current, moments(m1f), length, moments(m1r), length,
                       np.ones(shape[1:], F32), effective_counts(0.2, 32),
                       float32_weights(ref.REC709), F32(CONSISTENCY_SIGMA), hf, hr)
    assert hf[0, 0, 2] == hr[0, 0, 2] == 8.0  # within the noise: both kept
    if frame_at == "between":
        np.testing.assert_array_equal(hf, length)
        np.testing.assert_array_equal(hr, length)
        return
    kept, dropped = (hf, hr) if frame_at == "forward" else (hr, hf)
    assert np.all(kept == 8.0)
    assert np.all(dropped[0, 0, :2] < 0.3)  # of 8 frames


def _two_layer_motion(rng: np.random.Generator, height: int = 14, width: int = 20
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Backward motion and depth of a frame: a near block moving by a sub-pixel amount over a
    far plane moving the other way, some background."""
    depth = np.full((height, width), 9.0, F32) + rng.uniform(0, 0.01, (height, width)).astype(F32)
    motion = np.zeros((2, height, width), F32)
    motion[0], motion[1] = 0.35, -0.2
    block = np.zeros((height, width), bool)
    block[3:9, 5:12] = True
    depth[block] = 3.0
    motion[0, block], motion[1, block] = -2.6, 1.3
    depth[:, -2:] = 0.0  # background
    return motion, depth


def test_invert_motion_matches_the_reference() -> None:
    motion, depth = _two_layer_motion(np.random.default_rng(0))
    out = np.zeros_like(motion)
    holes = invert_motion(motion, depth, out)
    want, want_holes = ref.invert_motion(motion, depth)
    assert holes == want_holes > 0
    np.testing.assert_allclose(out, want, rtol=1e-5, atol=1e-5)
    # the block's own pixels carry its inverse motion; the far plane its own
    landed = out[0] != NO_MOTION
    assert np.any(np.isclose(out[0][landed], 2.6)) and np.any(np.isclose(out[0][landed], -0.35))


def test_pack_history_error_is_half_rounding_at_any_exposure() -> None:
    rng = np.random.default_rng(1)
    lengths = rng.choice(np.array([0.0, 1.0, 3.5, 32.0]), (2, 12, 16))
    side = _random_side(rng, lengths)
    side.colour[0, 1, 4, 4] = 5e4  # a firefly far above the rest
    for scale in (1e-4, 1.0, 1e4):
        scaled = SideHistory(side.colour * F32(scale), side.moments * F32(scale)
                             * np.array([1, scale], F32)[None, :, None, None], side.length)
        names = ("a", "b")
        planes, factors = pack_history(names, scaled)
        assert planes["a.R"].dtype == np.float16 and planes["a.h"].dtype == np.float32
        back = unpack_history(names, planes, factors)
        np.testing.assert_array_equal(back.length, scaled.length)
        np.testing.assert_allclose(back.colour, scaled.colour, rtol=2.0**-11, atol=0)
        np.testing.assert_allclose(back.moments[:, 0], scaled.moments[:, 0], rtol=2.0**-11)
        spread = scaled.moments[:, 1] - scaled.moments[:, 0] ** 2
        np.testing.assert_allclose(back.moments[:, 1] - back.moments[:, 0] ** 2, spread,
                                   rtol=5e-3, atol=2e-3 * float(spread.max()))
    # Unscaled float32 planes (half=False) restore the colour and first moment exactly.
    planes, factors = pack_history(("a", "b"), side, half=False)
    assert planes["a.R"].dtype == np.float32
    back = unpack_history(("a", "b"), planes, factors)
    np.testing.assert_array_equal(back.colour, side.colour)
    np.testing.assert_array_equal(back.moments[:, 0], side.moments[:, 0])
    np.testing.assert_allclose(back.moments[:, 1], side.moments[:, 1], rtol=1e-5)


@pytest.mark.parametrize("preset", ["default", "falcor"])
def test_forward_pass_keeps_the_unfiltered_history_where_pixels_move(preset: str) -> None:
    """Where every pixel moves the forward pass runs as a causal run that feeds back its
    unfiltered accumulation (``feedback_iteration`` -1; with falcor's colour blur, the
    colour entering the a-trous): its stored history is that run's, bit for bit, and not
    the filtered one a causal run feeding back its feedback iteration everywhere keeps.
    Where the wall stands still it keeps ``STATIC_FILTERED_SHARE`` of the filtered one.
    (The mechanism needs a feedback iteration: ``default`` feeds none back since 2026-11-27,
    docs/stability.md, so it runs here with the paper's first iteration.)"""
    params = resolve_params(preset)
    params = params.replace(feedback_iteration=max(params.feedback_iteration, 0))
    frames = scene_sequence(4)
    assert not any(np.any(np.all(np.abs(f.motion) < STATIC_MOTION, axis=0) & (f.depth > 0))
                   for f in frames)
    # The causal run a pass is: its anti-lag at the pass's significance.
    pass_sigma = params.antilag_sigma * PASS_ANTILAG_SIGMA_SCALE
    causal = Denoiser(params.replace(feedback_iteration=-1, antilag_sigma=pass_sigma))
    forward = ForwardPass(params)
    filtered = Denoiser(params.replace(moving_feedback_share=1.0))
    for frame in frames:
        causal.process(frame)
        forward.process(frame, Keep.NOTHING)
        filtered.process(frame)
    a, b = causal.state(), forward.state()
    for key in ("history_illumination", "history_moments", "history_length", "history_mode"):
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    assert not np.array_equal(a["history_illumination"], filtered.state()["history_illumination"])
    # a still wall (first frame: no history carries one pixel's difference to another):
    # the history there is not the unfiltered one, elsewhere it is
    still_frames = scene_sequence(1, wall_speed=0.0)
    causal = Denoiser(params.replace(feedback_iteration=-1, antilag_sigma=pass_sigma))
    forward = ForwardPass(params)
    for frame in still_frames:
        causal.process(frame)
        forward.process(frame, Keep.NOTHING)
    still = np.all(np.abs(still_frames[-1].motion) < STATIC_MOTION, axis=0)
    a, b = causal.state(), forward.state()
    assert still.mean() > 0.3
    moving = ~still & (still_frames[-1].depth > 0)
    np.testing.assert_array_equal(a["history_illumination"][:, :, moving],
                                  b["history_illumination"][:, :, moving])
    assert not np.array_equal(a["history_illumination"][:, :, still],
                              b["history_illumination"][:, :, still])
    assert 0.0 < STATIC_FILTERED_SHARE < 1.0


CASES = {
    "default, motion to the next frame": (resolve_params("default"), {"motion_next": True}),
    "default, derived motion": (resolve_params("default"), {}),
    # Glossy signals keep their rules (history clamp, sigma_l) in the reverse pass too.
    "default, three signals with glossy, light step": (
        resolve_params("default"), {"layout": "three", "light_step": (2, 0.4),
                                    "motion_next": True}),
    # A still wall: the passes keep part of their filtered colour there.
    "default, still wall": (resolve_params("default"), {"wall_speed": 0.0, "motion_next": True}),
    "falcor, three signals, light step": (
        resolve_params("falcor", firefly_clamp=2.0, history_clamp=1.5),
        {"layout": "three", "luminance_weights": ACESCG_LUMINANCE, "light_step": (3, 0.4),
         "motion_next": True}),
}


@pytest.mark.parametrize("case", list(CASES))
def test_bidirectional_denoiser_matches_the_float64_reference(case: str) -> None:
    params, scene = CASES[case]
    frames = scene_sequence(5, **scene)
    got = denoise_bidirectional(frames, params, debug_layers=True)
    want = ref.reference_bidirectional(frames, params)
    for t, (g, w) in enumerate(zip(got, want, strict=True)):
        where = f"frame {t}"
        for index, name in enumerate(frames[t].names):
            length, want_length = g.layers[f"history_length.{name}"], w.history_length[index]
            whole = want_length == np.round(want_length)  # exact: they steer the variance
            np.testing.assert_array_equal(length[whole], want_length[whole], err_msg=where)
            _close(length, want_length, f"{where}: {name} history length")
            rgb = np.stack([g.layers[f"{name}.{c}"] for c in "RGB"])
            _close(rgb, w.radiance[name], f"{where}: {name}")
        _close(g.color, w.color, f"{where}: colour")
        assert g.counts == w.counts, where
    # Both directions reach every frame: the first frame holds the later frames' history.
    first = want[0].history_length
    assert first.max() >= 5 and np.mean(first[first > 0] > 1) > 0.8


def test_a_reverse_pass_holds_no_combination_buffers_between_frames() -> None:
    """Between output frames the reverse pass keeps its history and scratch, not the
    buffers the forward state is combined in (nor the forward colour means): they are
    taken again for the next output frame. What it keeps does not grow."""
    params = resolve_params("default")
    assert params.temporal_albedo
    frames = scene_sequence(5)
    forward = ForwardPass(params)
    kept = [forward.process(frame) for frame in frames]
    reverse = ReversePass(params)
    held = []
    for t in range(len(frames) - 1, -1, -1):
        output = reverse.process(frames[t], kept[t] if t < len(frames) - 1 else None)
        assert (output is None) == (t == len(frames) - 1)
        held.append(reverse.held_bytes())
    assert held[1] == held[2] == held[3] == held[4]
    frame = frames[0]
    into = reverse.forward_buffers(len(frame.names), frame.height, frame.width)
    assert into.albedo is not None and into.albedo_length is not None
    combination = sum(plane.nbytes for plane in (into.colour, into.moments, into.length,
                                                  into.albedo, into.albedo_length))
    assert reverse.held_bytes() - held[-1] == combination


def test_bidirectional_taa_runs_backwards_in_time() -> None:
    """TAA in a bidirectional run: on the reverse pass's output frames, its history the
    frame after (in time), fetched with the motion to it. The last frame is the run's own
    output; earlier ones differ from the run without TAA only at the outlines, and are the
    kernel's blend of the two runs' outputs there."""
    import reference_svgf as ref

    from svgf_cli.filters.taa import taa_resolve

    frames = scene_sequence(4, motion_next=True)
    params = resolve_params("paper", taa=True)
    plain = [o.color for o in denoise_bidirectional(frames, params.replace(taa=False))]
    got = [o.color for o in denoise_bidirectional(frames, params)]
    np.testing.assert_array_equal(got[3], plain[3])
    want = np.empty_like(plain[2])
    taa_resolve(plain[2], got[3], frames[2].motion_next, frames[2].depth,
                np.array(frames[2].luminance_weights, dtype=np.float32),
                np.float32(params.taa_alpha), want)
    np.testing.assert_array_equal(got[2], want)
    outline = ref.taa_outline(frames[2].depth)
    assert np.any(got[2] != plain[2])
    np.testing.assert_array_equal(got[2][:, ~outline], plain[2][:, ~outline])
