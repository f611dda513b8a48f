"""The whole SVGF pipeline through the public Denoiser API."""

from __future__ import annotations

import dataclasses
from typing import Any

import numba
import numpy as np
import pytest
from synthetic import (
    edge_geometry,
    make_frame,
    static_sequence,
    texture,
    translating_sequence,
)

from svgf_cli.filters.bidirectional import STATIC_MOTION
from svgf_cli.filters.denoiser import Denoiser
from svgf_cli.filters.params import (
    AUTO_ANTILAG_RADIUS,
    AUTO_ITERATIONS,
    AUTO_PIXEL_FILTER,
    AUTO_SAMPLES,
    AUTO_STOP_SCALE,
    SVGFParams,
    antilag_radius_for,
    colour_blend_for,
    luminance_stop_scale_for,
    params_for_samples,
    resolve_params,
)
from svgf_cli.frame import Frame

F32 = np.float32


def _radiance(frame) -> np.ndarray:
    return frame.total_radiance()


def _run(params: SVGFParams, frames, debug: bool = False):
    denoiser = Denoiser(params, debug_layers=debug)
    return [denoiser.process(f) for f in frames], denoiser


def _run_each(frames: list[Frame], **variants: SVGFParams
              ) -> tuple[dict[str, list[np.ndarray]], dict[str, Denoiser]]:
    """Each named parameter set's output colours over ``frames``, and its denoiser."""
    runs = {name: Denoiser(params) for name, params in variants.items()}
    return {name: [d.process(f).color for f in frames] for name, d in runs.items()}, runs


@pytest.mark.parametrize("split", [True, False])
def test_constant_input_stays_constant_everywhere(split: bool) -> None:
    h, w = 20, 26
    albedo = texture(w, h, seed=4)
    depth = np.full((h, w), 4.0, dtype=F32)
    depth[:3] = 0.0  # background rows pass through
    motion = np.zeros((2, h, w), dtype=F32)
    motion[0] = -0.6  # sub-pixel pan: bilinear history everywhere, 3x3 at the border
    frames = [
        make_frame(w, h, illumination=(0.7, 0.5, 0.3), albedo=albedo, emission=(0.1, 0.0, 0.2),
                   depth=depth, motion=motion, split=split, seed=i)
        for i in range(4)
    ]
    outputs, _ = _run(resolve_params("paper"), frames)
    for frame, out in zip(frames, outputs, strict=True):
        np.testing.assert_allclose(out.color, _radiance(frame), rtol=2e-5, atol=1e-6)


@pytest.mark.parametrize("kind", ["depth", "normal"])
def test_no_spatial_leakage_across_geometry_edges(kind: str) -> None:
    h, w = 16, 32
    z, normal, mesh = edge_geometry(w, h, kind)
    illumination = np.ones((3, h, w), dtype=F32)
    illumination[:, :, w // 2:] = 3.0
    # Luminance stop disabled: only depth/normal may stop the blur.
    params = resolve_params("paper", sigma_luminance=1e6)

    def left_of_edge(edge_kind: str) -> float:
        zz, nn, mm = edge_geometry(w, h, edge_kind)
        frame = make_frame(w, h, illumination=illumination, albedo=1.0, noise=0.2, seed=1,
                           split=False, depth=zz, normal=nn, mesh_id=mm)
        out = Denoiser(params).process(frame).color
        return float(out[:, :, w // 2 - 3:w // 2].mean())

    assert abs(left_of_edge(kind) - 1.0) < 0.1
    assert left_of_edge("none") > 1.3  # the same setup without the edge does blur across


def test_no_temporal_leakage_across_mesh_id_change() -> None:
    h, w = 12, 16
    params = resolve_params("paper", atrous_iterations=0)
    mesh_before = np.ones((h, w), dtype=np.int32)
    mesh_after = mesh_before.copy()
    mesh_after[:, 8:] = 2  # a different object now covers the right half, same depth/normal
    illum_after = np.ones((3, h, w), dtype=F32)
    illum_after[:, :, 8:] = 4.0
    frames = [make_frame(w, h, split=False, mesh_id=mesh_before, seed=i) for i in range(3)]
    frames.append(make_frame(w, h, split=False, mesh_id=mesh_after, illumination=illum_after))
    outputs, _ = _run(params, frames, debug=True)
    last = outputs[-1]
    np.testing.assert_array_equal(last.layers["history_length.color"][:, 8:], 1.0)
    np.testing.assert_array_equal(last.layers["history_length.color"][:, :8], 4.0)
    np.testing.assert_allclose(last.color[:, :, 8:], _radiance(frames[-1])[:, :, 8:], rtol=1e-6)


def test_static_noisy_sequence_converges_and_variance_tracks_truth() -> None:
    """Plain accumulation of a static scene against the exponential moving average's
    statistics. Measured over 6 seeds: the output's rms error is 0.970-1.003 of the
    prediction, the final variance 0.997-1.014 and the frame-4 variance 0.982-1.004, so the
    bounds (7 %, 4 %, 5 %) sit at about 3 sigma; the effects they guard are larger (the
    (1 - sum w^2) factor of the moments is 11 %, dropping the 1/h ramp of the moments
    shrinks the frame-4 variance by 12.5 %)."""
    h, w, n, noise, alpha = 48, 48, 30, 0.25, 0.2
    frames = static_sequence(n, w, h, split=False, illumination=1.0, albedo=0.5, noise=noise)
    params = resolve_params("paper", atrous_iterations=0)
    outputs, _ = _run(params, frames, debug=True)
    truth = 0.5  # albedo * illumination
    error = outputs[-1].color - truth
    assert abs(float(error.mean())) < 0.005
    # An exponential moving average keeps sum(w_i^2) of the per-frame noise.
    weight_sq = 0.0
    for h_len in range(1, n + 1):
        a = max(alpha, 1.0 / h_len)
        weight_sq = (1.0 - a) ** 2 * weight_sq + a**2
    expected_rms = 0.5 * noise * np.sqrt(weight_sq)
    rms = float(np.sqrt(np.mean(error**2)))
    assert 0.93 < rms / expected_rms < 1.07
    assert float(np.sqrt(np.mean((_radiance(frames[-1]) - truth) ** 2))) > 2.5 * rms
    # Integrated moments: E[m2 - m1^2] = sigma^2 (1 - sum w^2) (illumination luminance).
    variance = outputs[-1].layers["variance.color"]
    expected_variance = noise**2 * (1.0 - weight_sq)
    assert abs(float(variance.mean()) / expected_variance - 1.0) < 0.04
    # Frame 4 (h = 4, the first temporal estimate): with the 1/h ramp the moments are the
    # plain mean of 4 frames, whose population variance is sigma^2 (1 - 1/4).
    early = outputs[3].layers["variance.color"]
    assert abs(float(early.mean()) / (noise**2 * 0.75) - 1.0) < 0.05
    np.testing.assert_array_equal(outputs[-1].layers["history_length.color"], float(n))


def test_filtering_reduces_error_of_noisy_input() -> None:
    frames = static_sequence(6, 32, 24, illumination=1.0, noise=0.3, seed=3)
    outputs, _ = _run(resolve_params("paper"), frames)
    truth = make_frame(32, 24, illumination=1.0)
    noisy_rms = np.sqrt(np.mean((_radiance(frames[-1]) - _radiance(truth)) ** 2))
    out_rms = np.sqrt(np.mean((outputs[-1].color - _radiance(truth)) ** 2))
    assert out_rms < 0.25 * noisy_rms


def test_translating_sequence_without_noise_is_reproduced() -> None:
    frames = translating_sequence(4, 40, 24, velocity=(1.5, 0.25), split=True, frequency=0.12)
    params = resolve_params("paper", atrous_iterations=0)
    outputs, _ = _run(params, frames)
    inner = np.s_[:, 4:-4, 8:-4]  # away from where the pan uncovers new content
    error = np.abs(outputs[-1].color - _radiance(frames[-1]))[inner]
    assert error.max() < 1e-3


def test_disocclusion_resets_history() -> None:
    h, w, speed = 16, 32, 6
    frames = []
    for i in range(4):
        depth = np.full((h, w), 8.0, dtype=F32)
        mesh = np.ones((h, w), dtype=np.int32)
        x0 = 2 + speed * i  # a box moving right over a wall
        depth[4:12, x0:x0 + 6] = 3.0
        mesh[4:12, x0:x0 + 6] = 2
        motion = np.zeros((2, h, w), dtype=F32)
        motion[0, 4:12, x0:x0 + 6] = -speed
        frames.append(make_frame(w, h, depth=depth, mesh_id=mesh, motion=motion, noise=0.1,
                                 seed=i))
    outputs, _ = _run(resolve_params("paper"), frames, debug=True)
    length = outputs[-1].layers["history_length.direct"]
    x0 = 2 + speed * 3
    # Wall uncovered this frame. Its rim may reuse the wall that was visible right next to
    # it (the paper's 3x3 fallback); the interior has no consistent history at all.
    uncovered = length[4:12, x0 - speed:x0]
    assert np.all(uncovered[1:-1, 1:-1] == 1.0)
    assert np.all(length[4:12, x0:x0 + 6] == 4.0)  # the box, followed by its motion
    assert np.all(length[:4] == 4.0)  # static wall


def test_motion_outside_frame_and_zero_albedo_do_not_blow_up() -> None:
    h, w = 12, 14
    albedo = np.full((3, h, w), 0.6, dtype=F32)
    albedo[:, 4:8, 4:8] = 0.0
    motion = np.zeros((2, h, w), dtype=F32)
    motion[0, :, :5] = -1e4
    frames = [make_frame(w, h, albedo=albedo, motion=motion, noise=0.3, seed=i,
                         emission=(0.0, 0.0, 0.0)) for i in range(3)]
    outputs, _ = _run(resolve_params("paper"), frames, debug=True)
    for out in outputs:
        assert np.all(np.isfinite(out.color))
    # Black albedo: radiance there is only noise around 0; the output stays that small.
    assert float(np.abs(outputs[-1].color[:, 4:8, 4:8]).max()) < 0.5
    np.testing.assert_array_equal(outputs[-1].layers["history_length.direct"][:, :5], 1.0)


def test_two_runs_are_bit_identical_across_thread_counts() -> None:
    frames = translating_sequence(3, 36, 20, noise=0.2, seed=9)
    params = resolve_params("paper", firefly_clamp=3.0, history_clamp=2.0, taa=True)
    first, _ = _run(params, frames, debug=True)
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        second, _ = _run(params, frames, debug=True)
    finally:
        numba.set_num_threads(threads)
    for a, b in zip(first, second, strict=True):
        assert a.color.tobytes() == b.color.tobytes()
        assert a.layers.keys() == b.layers.keys()
        for key in a.layers:
            assert a.layers[key].tobytes() == b.layers[key].tobytes()


def test_state_round_trip_continues_bit_identically() -> None:
    frames = translating_sequence(5, 30, 18, noise=0.2, seed=4)
    params = resolve_params("falcor", taa=True)
    reference, denoiser = _run(params, frames[:3])
    state = denoiser.state()
    tail_a = [denoiser.process(f).color for f in frames[3:]]
    resumed = Denoiser(params)
    resumed.load_state(state)
    assert resumed.frames_processed == 3
    tail_b = [resumed.process(f).color for f in frames[3:]]
    for a, b in zip(tail_a, tail_b, strict=True):
        assert a.tobytes() == b.tobytes()
    with pytest.raises(ValueError, match="different parameters"):
        Denoiser(resolve_params("paper")).load_state(state)
    broken = dict(state)
    broken["history_length"] = np.zeros((4, 4), dtype=F32)
    with pytest.raises(ValueError, match="history_length"):
        Denoiser(params).load_state(broken)


@pytest.mark.parametrize("missing", ["params", "frames_processed"])
def test_a_state_without_its_header_is_refused_as_not_a_state(missing: str) -> None:
    """A history file from elsewhere (an npz without svgf's keys) is a ValueError that says
    so (the runner reports it as "cannot use history" naming the file), not a KeyError."""
    params = resolve_params("paper")
    state = Denoiser(params).state()
    del state[missing]
    with pytest.raises(ValueError, match="not a denoiser state"):
        Denoiser(params).load_state(state)


def test_reset_makes_the_next_frame_cold() -> None:
    frames = static_sequence(3, 16, 12, noise=0.2)
    denoiser = Denoiser(resolve_params("paper"), debug_layers=True)
    for f in frames:
        denoiser.process(f)
    denoiser.reset()
    assert denoiser.frames_processed == 0
    out = denoiser.process(frames[0])
    np.testing.assert_array_equal(out.layers["history_length.direct"], 1.0)


def test_a_cold_frame_shows_no_anti_lag_response() -> None:
    """The anti-lag debug layer of a frame that had no history to test (after a reset) is 0,
    not the response the workspace still holds from the frame before the reset."""
    lights = [1.0, 1.0, 4.0, 4.0]  # a light switched up: anti-lag responds on frame 3
    frames = [make_frame(32, 24, illumination=light, noise=0.05, seed=k)
              for k, light in enumerate(lights)]
    denoiser = Denoiser(resolve_params("default"), debug_layers=True)
    responses = [denoiser.process(f).layers["antilag.direct"] for f in frames[:3]]
    assert responses[2].max() > 0.0
    denoiser.reset()
    cold = denoiser.process(frames[3]).layers["antilag.direct"]
    assert not cold.any()


def test_resolution_change_raises() -> None:
    denoiser = Denoiser(resolve_params("paper"))
    denoiser.process(make_frame(32, 24))
    with pytest.raises(ValueError, match="resolution changed from 32x24 to 16x16"):
        denoiser.process(make_frame(16, 16))


def test_temporal_off_filters_every_frame_cold() -> None:
    frames = static_sequence(3, 20, 16, noise=0.3)
    outputs, _ = _run(resolve_params("paper", temporal=False), frames, debug=True)
    for frame, out in zip(frames, outputs, strict=True):
        np.testing.assert_array_equal(out.layers["history_length.direct"], 1.0)
        assert not np.allclose(out.color, _radiance(frame))
    single = Denoiser(resolve_params("paper", temporal=False)).process(frames[2]).color
    assert single.tobytes() == outputs[2].color.tobytes()


def test_atrous_off_outputs_the_temporal_accumulation() -> None:
    frames = static_sequence(2, 20, 16, noise=0.3, split=False)
    outputs, _ = _run(resolve_params("paper", atrous_iterations=0), frames)
    # Frame 1 is cold (output = input); frame 2 blends with alpha = 1/2.
    np.testing.assert_allclose(outputs[0].color, _radiance(frames[0]), rtol=1e-6, atol=1e-7)
    expected = 0.5 * (_radiance(frames[0]) + _radiance(frames[1]))
    np.testing.assert_allclose(outputs[1].color, expected, rtol=1e-5, atol=1e-6)


def test_firefly_clamp_removes_an_isolated_spike() -> None:
    frame = make_frame(16, 16, noise=0.05, seed=2, split=False)
    frame.signal("color").radiance[:, 8, 8] = 200.0
    plain = Denoiser(resolve_params("paper", atrous_iterations=0)).process(frame).color
    clamped = Denoiser(resolve_params("paper", atrous_iterations=0, firefly_clamp=3.0))
    out = clamped.process(frame).color
    assert plain[0, 8, 8] > 100.0
    assert out[0, 8, 8] < 1.0


@pytest.mark.parametrize("iterations", [5, 1], ids=["feedback-then-more", "output-is-history"])
def test_despike_bounds_a_firefly_the_atrous_kept_and_leaves_history_alone(
    iterations: int,
) -> None:
    """A firefly in a noisy frame survives the a-trous as a spike (its neighbours reject it);
    despike brings it to 2x its brightest neighbour, counts it, and changes nothing else:
    not the other pixels (beyond a few noise spikes), not the colour history (also when the
    last iteration's output is the history itself)."""
    frames = static_sequence(2, 16, 16, noise=0.3, split=False)
    frames[1].signal("color").radiance[:, 8, 8] = 1000.0
    plain = Denoiser(resolve_params("paper", atrous_iterations=iterations))
    guarded = Denoiser(resolve_params("paper", atrous_iterations=iterations, despike=2.0))
    for frame in frames:
        kept, out = plain.process(frame), guarded.process(frame)
    neighbours = np.delete(out.color[1, 7:10, 7:10].ravel(), 4)
    assert kept.color[1, 8, 8] > 4.0 * neighbours.max()  # the spike the a-trous leaves
    assert out.color[1, 8, 8] <= 2.0 * neighbours.max() * 1.5  # bound (in luminance, ~rgb)
    assert out.counts["despiked.color"] >= 1
    changed = np.any(out.color != kept.color, axis=0)
    assert changed[8, 8] and changed.sum() <= out.counts["despiked.color"]
    history_plain, history_guarded = plain.state(), guarded.state()
    for name in ("history_illumination", "history_moments", "history_length"):
        np.testing.assert_array_equal(history_plain[name], history_guarded[name])


def test_history_clamp_removes_lag_after_a_lighting_change() -> None:
    h, w = 16, 16
    before = static_sequence(8, w, h, split=False, illumination=1.0, noise=0.02)
    after = make_frame(w, h, split=False, illumination=3.0, noise=0.02, seed=99)

    def last(params: SVGFParams) -> float:
        outputs, _ = _run(params, [*before, after])
        return float(outputs[-1].color[:, 4:-4, 4:-4].mean())

    lagging = last(resolve_params("paper", atrous_iterations=0))
    clamped = last(resolve_params("paper", atrous_iterations=0, history_clamp=1.0))
    assert lagging < 0.5 * (1.0 + 0.2 * 2.0) + 0.05  # alpha 0.2: mostly old lighting
    assert clamped > 0.5 * 3.0 * 0.9


def _outline_frame(block: slice, flip: bool, *, emission: float = 0.0,
                   block_motion: float = 0.0) -> Frame:
    """A dark wall (depth 8, illumination 0.2) behind a block (depth 2) over ``block``'s
    columns: lit (illumination 2) or, with ``emission``, a light; ``flip`` moves the
    block's left column onto the wall, as a jittered sample of that pixel would."""
    h, w = 12, 24
    depth = np.full((h, w), 8.0, dtype=F32)
    illumination = np.full((h, w), 0.2, dtype=F32)
    glow = np.zeros((3, h, w), dtype=F32)
    depth[:, block] = 2.0
    illumination[:, block] = 0.0 if emission else 2.0
    glow[:, :, block] = emission
    if flip:
        depth[:, block.start] = 8.0
        illumination[:, block.start] = 0.2
        glow[:, :, block.start] = 0.0
    motion = np.zeros((2, h, w), dtype=F32)
    motion[0][depth == 2.0] = block_motion
    return make_frame(w, h, split=False, illumination=illumination, depth=depth,
                      mesh_id=np.where(depth == 2.0, 2, 1), motion=motion,
                      emission=glow if emission else None)


def test_taa_averages_a_jittered_outline_toward_its_coverage() -> None:
    """An outline pixel whose sample lands on the block or on the wall at random (a
    jittered renderer, coverage 1/2): SVGF keeps the two surfaces apart and its output
    flips; TAA's output there moves far less, near the two surfaces' mean."""
    rng = np.random.default_rng(3)
    frames = [_outline_frame(slice(12, 18), bool(flip)) for flip in rng.integers(0, 2, 30)]
    params = resolve_params("paper", atrous_iterations=0, temporal=False)
    plain, _ = _run(params, frames)
    taa, _ = _run(params.replace(taa=True, taa_alpha=0.5), frames)
    np.testing.assert_array_equal(taa[0].color, plain[0].color)  # nothing to blend yet

    def outline(outs) -> np.ndarray:
        return np.array([o.color[1, 6, 12] for o in outs[5:]])

    mix = 0.5 * (0.2 + 2.0) * 0.5  # the mean of the two surfaces (albedo 0.5)
    assert outline(taa).std() < 0.7 * outline(plain).std()  # alpha 0.5: sqrt(1/3) ideally
    assert abs(outline(taa).mean() - mix) < 0.25 * mix
    # Away from the outline nothing changes.
    for a, b in zip(plain, taa, strict=True):
        np.testing.assert_array_equal(a.color[:, :, :9], b.color[:, :, :9])
        np.testing.assert_array_equal(a.color[:, :, 21:], b.color[:, :, 21:])


def test_taa_leaves_no_trail_behind_a_moving_light() -> None:
    """A light (radiance 50) crossing a dark wall one pixel a frame: the wall it uncovers
    is back to the wall's value two pixels behind it (the clip against the current 3x3),
    and never holds more than a fifth of the light right behind it."""
    frames = [_outline_frame(slice(4 + t, 8 + t), False, emission=50.0, block_motion=-1.0)
              for t in range(12)]
    params = resolve_params("paper", atrous_iterations=0, temporal=False)
    taa, _ = _run(params.replace(taa=True, taa_alpha=0.5), frames)
    wall = 0.2 * 0.5
    for t, out in enumerate(taa[1:], start=1):
        behind = out.color[:, 6, :4 + t]  # the wall left of the light
        assert behind[:, -1].max() < 0.2 * 50.0
        np.testing.assert_allclose(behind[:, :-1], wall, rtol=1e-5)
    # Nothing blends where the outline does not reach: a sudden change shows at once.
    bright = make_frame(24, 12, split=False, illumination=5.0, depth=8.0)
    denoiser = Denoiser(params.replace(taa=True, taa_alpha=0.5))
    for f in frames:
        denoiser.process(f)
    np.testing.assert_allclose(denoiser.process(bright).color, _radiance(bright), rtol=1e-6)


def test_pixel_filter_auto_blurs_only_centre_sampled_frames() -> None:
    """``auto`` (the default preset) applies the 3-tap pixel filter to frames whose header
    says they are pixel-centre samples and to no other; an explicit weight applies to all.
    The emission is added back unfiltered."""
    h, w = 12, 16
    illumination = np.full((h, w), 0.2, dtype=F32)
    illumination[:, 8:] = 2.0  # a sharp shading edge
    glow = np.zeros((3, h, w), dtype=F32)
    glow[:, 2:4, 2:4] = 40.0

    def frames(centre: bool) -> list[Frame]:
        sequence = static_sequence(3, w, h, split=False, illumination=illumination,
                                   emission=glow)
        return [dataclasses.replace(f, centre_sampled=centre) for f in sequence]

    params = resolve_params("paper", atrous_iterations=0, temporal=False)
    sharp, _ = _run(params, frames(True))
    auto, _ = _run(params.replace(pixel_filter=AUTO_PIXEL_FILTER), frames(True))
    jittered, _ = _run(params.replace(pixel_filter=AUTO_PIXEL_FILTER), frames(False))
    forced, _ = _run(params.replace(pixel_filter=0.05), frames(False))
    np.testing.assert_array_equal(jittered[-1].color, sharp[-1].color)
    np.testing.assert_array_equal(forced[-1].color, auto[-1].color)
    edge = auto[-1].color[1, 6]
    left, right = sharp[-1].color[1, 6, 7], sharp[-1].color[1, 6, 8]
    assert edge[7] == pytest.approx(0.95 * left + 0.05 * right, rel=1e-5)
    assert edge[8] == pytest.approx(0.95 * right + 0.05 * left, rel=1e-5)
    # The light keeps its own value (its neighbours' rest is blurred into it, not it out).
    assert np.all(auto[-1].color[:, 2:4, 2:4] >= glow[:, 2:4, 2:4])
    assert auto[-1].color[1, 2, 1] < 1.0


def test_a_frame_of_several_samples_is_blended_as_that_many_frames() -> None:
    """A frame whose header says N samples per pixel is blended with ``1 - (1 - alpha)^N``
    (and the moments likewise) under ``auto``; the same frames marked 1 sample with those
    blends set explicitly give the very same output, and 1 sample changes nothing. (The
    colours' running means blend at their own rate, which no setting names: off here.)"""
    frames = static_sequence(5, 28, 20, noise=0.3)
    auto = resolve_params("default", warm_start=0)
    assert auto.samples_per_pixel == AUTO_SAMPLES

    def marked(n: int) -> list[Frame]:
        return [dataclasses.replace(f, samples_per_pixel=n) for f in frames]

    plain = auto.replace(temporal_albedo=False)
    four, _ = _run(plain, marked(4))
    blend = 1.0 - 0.8**4
    # And one a-trous iteration fewer (atrous_iterations_for): 28x20 frames 3 -> 2; the
    # anti-lag window halved (antilag_radius_for): 2 -> 1.
    explicit, _ = _run(plain.replace(alpha=blend, moments_alpha=blend, atrous_iterations=2,
                                     antilag_radius=1), marked(1))
    for a, b in zip(four, explicit, strict=True):
        np.testing.assert_array_equal(a.color, b.color)
    one, _ = _run(auto, marked(1))
    forced_one, _ = _run(auto.replace(samples_per_pixel=1), marked(4))
    paper_like, _ = _run(auto.replace(samples_per_pixel=1), marked(1))
    for a, b, c in zip(one, forced_one, paper_like, strict=True):
        np.testing.assert_array_equal(a.color, b.color)
        np.testing.assert_array_equal(a.color, c.color)
    # The larger blend is a different, shorter-memory filter.
    assert not np.array_equal(four[-1].color, one[-1].color)
    forced_four, _ = _run(plain.replace(samples_per_pixel=4), marked(1))
    np.testing.assert_array_equal(forced_four[-1].color, four[-1].color)


def test_a_frame_of_several_samples_has_its_own_colour_blend_and_anti_lag_window(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The stages are handed the rates of the frame's sample count: the colours' running
    means blend at ``colour_blend_for`` (0.36 at 4 samples, not the light's 0.59), anti-lag,
    the history gain and the turning objects' test use ``antilag_radius_for``'s halved
    window; at one sample ``alpha`` and the image's window, as before."""
    from svgf_cli.filters.stages import antilag, temporal_albedo

    blends: list[float] = []
    radii: list[int] = []
    real_accumulate, real_antilag = temporal_albedo.accumulate_albedo, antilag.antilag

    def accumulate(*args: Any, **kwargs: Any) -> None:
        blends.append(float(args[8]))
        real_accumulate(*args, **kwargs)

    def tested(*args: Any, **kwargs: Any) -> int:
        radii.append(int(args[5]))
        return real_antilag(*args, **kwargs)

    monkeypatch.setattr(temporal_albedo, "accumulate_albedo", accumulate)
    monkeypatch.setattr(antilag, "antilag", tested)
    frames = static_sequence(4, 28, 20, noise=0.3)
    auto = resolve_params("default", warm_start=0)
    _run(auto, [dataclasses.replace(f, samples_per_pixel=4) for f in frames])
    assert blends and set(blends) == {float(np.float32(colour_blend_for(auto, 4)))}
    assert colour_blend_for(auto, 4) == pytest.approx(0.358, abs=1e-3)
    assert radii and set(radii) == {1}
    blends.clear()
    radii.clear()
    _run(auto, frames)
    assert set(blends) == {float(np.float32(0.2))}
    assert radii and set(radii) == {2}


def test_params_for_samples() -> None:
    params = resolve_params("default")
    assert params_for_samples(params, 1) is params
    four = params_for_samples(params, 4)
    assert four.alpha == pytest.approx(1 - 0.8**4)
    assert four.moments_alpha == pytest.approx(1 - 0.8**4)
    assert four.samples_per_pixel == params.samples_per_pixel  # the setting itself is kept
    assert params_for_samples(params.replace(samples_per_pixel=2), 16).alpha == pytest.approx(
        1 - 0.8**2)
    assert params_for_samples(params.replace(samples_per_pixel=1), 16) is not None
    assert params_for_samples(params.replace(samples_per_pixel=1), 16).alpha == 0.2
    assert params_for_samples(resolve_params("paper"), 4).alpha == 0.2  # paper: 1 sample


def test_feedback_iteration_output_becomes_the_history() -> None:
    frame = make_frame(24, 16, noise=0.3, seed=5)
    params = resolve_params("paper")  # 5 iterations, feedback from the first

    def history(p: SVGFParams) -> np.ndarray:
        denoiser = Denoiser(p)
        denoiser.process(frame)
        return denoiser.state()["history_illumination"]

    first_only = history(params.replace(atrous_iterations=1))
    assert history(params).tobytes() == first_only.tobytes()
    unfiltered = history(params.replace(feedback_iteration=-1))
    assert not np.array_equal(unfiltered, first_only)
    np.testing.assert_array_equal(unfiltered, history(params.replace(atrous_iterations=0)))


@pytest.mark.parametrize("share", [0.0, 0.4])
def test_moving_pixels_keep_a_share_of_the_feedback_output(share: float) -> None:
    """``moving_feedback_share``: where the pixel moves the history is ``w F + (1 - w) U``
    (``F`` the feedback iteration's output, ``U`` the unfiltered accumulation, ``w`` the
    share), where it stands still ``F`` as in the paper."""
    from moving_scene import scene_sequence

    frames = scene_sequence(3, wall_speed=0.0)
    still = np.all(np.abs(frames[-1].motion) < STATIC_MOTION, axis=0)
    moving = ~still & (frames[-1].depth > 0)
    assert still.mean() > 0.3 and moving.mean() > 0.02
    # default feeds nothing back since 2026-11-27 (docs/stability.md): the paper's first
    # iteration, so that there is a feedback output to share
    params = resolve_params("default").replace(feedback_iteration=0)

    def last_history(p: SVGFParams) -> tuple[np.ndarray, np.ndarray]:
        """The history after the last frame, and the history that frame started from."""
        denoiser = Denoiser(p.replace(moving_feedback_share=share))
        for frame in frames[:-1]:
            denoiser.process(frame)
        state = denoiser.state()
        denoiser.process(frames[-1])
        return denoiser.state()["history_illumination"], state

    got, state = last_history(params)

    def from_state(p: SVGFParams) -> np.ndarray:
        """The last frame from the same history with other parameters."""
        denoiser = Denoiser(p)
        denoiser.load_state({**state, "params": Denoiser(p).state()["params"]})
        denoiser.process(frames[-1])
        return denoiser.state()["history_illumination"]

    filtered = from_state(params.replace(moving_feedback_share=1.0))
    unfiltered = from_state(params.replace(feedback_iteration=-1))
    np.testing.assert_array_equal(got[:, :, still], filtered[:, :, still])
    want = unfiltered + F32(share) * (filtered - unfiltered)
    np.testing.assert_allclose(got[:, :, moving], want[:, :, moving], rtol=1e-6, atol=1e-7)
    assert not np.allclose(filtered[:, :, moving], unfiltered[:, :, moving])


# Each parameter at the edge of its range (accepted) and just past it (refused with its own
# message): a library caller gets no Denoiser that would divide by zero or never converge.
_EDGES = {
    "atrous_iterations": (-1, -2, "atrous_iterations = -2: must be 0..12 or auto"),
    "alpha": (1.0, 0.0, r"alpha = 0.0: must be \(0, 1\]"),
    "moments_alpha": (1.0, 1.5, r"moments_alpha = 1.5: must be \(0, 1\]"),
    "history_cap": (1, 0, "history_cap = 0: must be >= 1"),
    "sigma_normal": (1e-3, 0.0, "sigma_normal = 0.0: must be > 0"),
    "sigma_luminance": (1e-3, 0.0, "sigma_luminance = 0.0: must be > 0"),
    "sigma_depth": (1e-3, 0.0, "sigma_depth = 0.0: must be > 0"),
    "spatial_variance_sigma_luminance": (1e-3, 0.0, "spatial_variance_sigma_luminance = 0.0"),
    "spatial_variance_radius": (0, -1, "spatial_variance_radius = -1: must be >= 0"),
    "albedo_epsilon": (1e-9, 0.0, "albedo_epsilon = 0.0: must be > 0"),
    "taa_alpha": (1.0, 0.0, r"taa_alpha = 0.0: must be \(0, 1\]"),
    "moving_feedback_share": (1.0, 1.5, r"moving_feedback_share = 1.5: must be \[0, 1\]"),
}


@pytest.mark.parametrize("name", sorted(_EDGES))
def test_parameters_outside_their_range_are_refused(name: str) -> None:
    accepted, refused, message = _EDGES[name]
    Denoiser(resolve_params("paper", **{name: accepted}))
    with pytest.raises(ValueError, match=message):
        Denoiser(resolve_params("paper", **{name: refused}))


def test_atrous_iterations_stop_at_twelve() -> None:
    Denoiser(resolve_params("paper", atrous_iterations=12))
    with pytest.raises(ValueError, match=r"atrous_iterations = 13: must be 0\.\.12 or auto"):
        Denoiser(resolve_params("paper", atrous_iterations=13))


def test_auto_iterations_filter_like_the_count_the_image_size_gives() -> None:
    """``atrous_iterations`` auto runs exactly the count ``atrous_iterations_for`` picks for
    the frame (3 on a small image), in every frame and in the colour history."""
    frames = static_sequence(3, 24, 16, noise=0.3, split=False)
    auto = resolve_params("default")
    assert auto.atrous_iterations == AUTO_ITERATIONS
    out, runs = _run_each(frames, auto=auto, three=auto.replace(atrous_iterations=3),
                          five=auto.replace(atrous_iterations=5))
    for frame_index in range(len(frames)):
        np.testing.assert_array_equal(out["auto"][frame_index], out["three"][frame_index])
        assert np.any(out["auto"][frame_index] != out["five"][frame_index])
    np.testing.assert_array_equal(runs["auto"].state()["history_illumination"],
                                  runs["three"].state()["history_illumination"])


def test_despike_bounds_a_firefly_filtered_alone_as_radiance() -> None:
    """A specular firefly whose G-buffer albedo is no reflectance is filtered as radiance;
    with no neighbour in that mode neither the a-trous nor the per-signal despike touch it,
    so the output guard compares it with its output neighbours and brings it down."""
    frames = static_sequence(2, 16, 16, noise=0.3, split=False)
    signal = frames[1].signal("color")
    signal.albedo[:, 8, 8] = 25.0
    signal.radiance[:, 8, 8] = 1000.0
    plain = Denoiser(resolve_params("paper"))
    guarded = Denoiser(resolve_params("paper", despike=2.0))
    for frame in frames:
        kept, out = plain.process(frame), guarded.process(frame)
    assert kept.counts["implausible_albedo.color"] >= 1
    neighbours = np.sort(np.delete(out.color[1, 7:10, 7:10].ravel(), 4))
    assert kept.color[1, 8, 8] > 100.0  # the sample, unfiltered
    assert out.color[1, 8, 8] <= 2.0 * neighbours[-2] * 1.5
    assert out.counts["despiked_lone"] >= 1


def test_luminance_stop_scale_multiplies_every_stop_and_auto_follows_the_image() -> None:
    """``luminance_stop_scale`` is a factor on the a-trous sigma_l of every signal: 2 with
    sigma_luminance 2 filters exactly as 1 with 4, glossy and mixed stops included (a direct
    signal, a mixed one), and looser than 1 with 2. Auto is 0.5 below 120 rows, so a small
    image filters as the explicit 0.5."""
    frames = static_sequence(3, 24, 16, noise=0.3, split=True)
    base = resolve_params("default")
    assert base.luminance_stop_scale == AUTO_STOP_SCALE
    out, _ = _run_each(
        frames, scaled=base.replace(luminance_stop_scale=2.0),
        wider=base.replace(luminance_stop_scale=1.0, sigma_luminance=4.0,
                           mixed_sigma_luminance=3.0, glossy_sigma_luminance=2.0),
        one=base.replace(luminance_stop_scale=1.0),
        half=base.replace(luminance_stop_scale=0.5), auto=base)
    np.testing.assert_array_equal(out["scaled"], out["wider"])
    np.testing.assert_array_equal(out["auto"], out["half"])
    assert all(np.any(a != b) for a, b in zip(out["scaled"], out["one"], strict=True))
    assert [luminance_stop_scale_for(base, rows, 2 * rows) for rows in
            (72, 119, 120, 319, 320, 639, 640, 1080)] == [0.5, 0.5, 1, 1, 1.75, 1.75, 3, 3]
    assert luminance_stop_scale_for(base, 1080, 720) == 3  # the shorter side
    assert luminance_stop_scale_for(base.replace(luminance_stop_scale=0.5), 1080, 1920) == 0.5
    assert luminance_stop_scale_for(resolve_params("paper"), 1080, 1920) == 1.0


def test_antilag_radius_auto_follows_the_image() -> None:
    """``antilag_radius`` auto is 2 below 160 rows (a small frame filters exactly as the
    explicit 2: the bundled fixtures are unchanged), 4 below 320, 6 from 320; an explicit radius
    wins, and a wider window changes what anti-lag does on a lighting change."""
    base = resolve_params("default")
    assert base.antilag_radius == AUTO_ANTILAG_RADIUS
    rows = (72, 159, 160, 319, 320, 1080)
    assert [antilag_radius_for(base, r, 2 * r) for r in rows] == [2, 2, 4, 4, 6, 6]
    assert antilag_radius_for(base, 1080, 720) == 6  # the shorter side
    assert antilag_radius_for(base.replace(antilag_radius=3), 1080, 1920) == 3
    frames = static_sequence(4, 40, 24, noise=0.3, split=True)
    for frame in frames[2:]:  # the light dims to a third: anti-lag's case
        for signal in frame.signals:
            signal.radiance *= F32(1 / 3)
    out, _ = _run_each(frames, auto=base, two=base.replace(antilag_radius=2),
                       four=base.replace(antilag_radius=4))
    np.testing.assert_array_equal(out["auto"], out["two"])
    assert np.any(out["two"][-1] != out["four"][-1])
