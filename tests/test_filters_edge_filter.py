"""The pixel filter across outlines (``filters.edge_filter``, stage ``edge_filter``)."""

from __future__ import annotations

import numpy as np
import pytest
import reference_svgf as ref
from synthetic import make_frame

from svgf_cli.filters.denoiser import Denoiser
from svgf_cli.filters.edge_filter import (
    OutlineSpill,
    edge_filter,
    edge_filter_weight,
    exchange,
    isolated_samples,
    lone_samples,
    near,
    noisy_outline_weights,
    outline_share,
)
from svgf_cli.filters.params import AUTO_PIXEL_FILTER, PRESETS, resolve_params
from svgf_cli.filters.pipeline import stage_names

F32 = np.float32


def _scene(seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    height, width = 11, 14
    colour = rng.gamma(1.5, 1.0, (3, height, width)).astype(F32)
    mesh = np.ones((height, width), np.int32)
    mesh[3:8, 4:9] = 2  # an object
    depth = np.full((height, width), 5.0, F32)
    depth[3:8, 4:9] = 3.0
    depth[:, 11:] = 5.0 * 1.1  # a depth step on one object
    depth[0, :3] = 0.0  # background
    mesh[0, :3] = -1
    depth[9, 6] = 5.0 * 1.04  # within DEPTH_JUMP: no outline
    return colour, mesh, depth


@pytest.mark.parametrize("weight", [0.05, 0.2])
def test_matches_a_float64_reference(weight: float) -> None:
    colour, mesh, depth = _scene()
    out = np.empty_like(colour)
    edge_filter(colour, mesh, depth, _plane(depth, weight), out)
    want = ref.edge_filter(colour, mesh, depth, weight)
    np.testing.assert_allclose(out, want, rtol=2e-6, atol=2e-6)
    # What moves: outline pixels only, and all of them.
    moved = np.any(np.abs(out - colour) > 1e-6, axis=0)
    assert moved[3, 4] and moved[2, 4] and moved[4, 11] and moved[0, 2]
    assert not moved[5, 1] and not moved[9, 6] and not moved[5, 6]


def test_the_light_a_pair_holds_is_kept() -> None:
    """Each exchange moves light between two pixels: the frame's total stays."""
    colour, mesh, depth = _scene(3)
    out = np.empty_like(colour)
    edge_filter(colour, mesh, depth, _plane(depth, 0.25), out)
    np.testing.assert_allclose(out.sum(axis=(1, 2)), colour.sum(axis=(1, 2)), rtol=1e-5)
    # Per-pixel weights too: each pair exchanges the mean of its two pixels' weights.
    weights = np.random.default_rng(5).uniform(0.0, 0.25, depth.shape).astype(F32)
    edge_filter(colour, mesh, depth, weights, out)
    np.testing.assert_allclose(out.sum(axis=(1, 2)), colour.sum(axis=(1, 2)), rtol=1e-5)
    np.testing.assert_allclose(out, ref.edge_filter(colour, mesh, depth, weights),
                               rtol=2e-6, atol=2e-6)


def _plane(depth: np.ndarray, weight: float) -> np.ndarray:
    return np.full(depth.shape, weight, dtype=F32)


def _speckled(seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A 24x34 frame: on the left a defocused region whose samples see the ball (id 2) or
    the floor (id 1) at random, on the right a clean outline and a one-pixel wire."""
    rng = np.random.default_rng(seed)
    height, width = 24, 34
    mesh = np.ones((height, width), np.int32)
    mesh[:, :12] = np.where(rng.random((height, 12)) < 0.5, 2, 1)
    mesh[8:16, 18:26] = 3  # a clean object
    mesh[2:22, 30] = 4  # a wire
    depth = np.where(mesh == 2, 3.0, 5.0).astype(F32)
    depth[mesh == 3] = 4.0
    colour = np.where(mesh == 2, 4.0, 0.5).astype(F32)[None].repeat(3, axis=0)
    return colour, mesh, depth


def test_the_outlines_share_matches_a_float64_reference() -> None:
    colour, mesh, depth = _speckled()
    depth[0, 20:] = 0.0  # background counts as another surface
    share = outline_share(mesh, depth)
    np.testing.assert_allclose(share, ref.outline_share(mesh, depth), rtol=1e-6, atol=1e-7)
    assert share[12, 5] > 0.4  # the speckle
    assert share[12, 22] == 0.0  # inside the clean object
    assert share[8, 22] <= 0.2 and share[12, 30] < 0.25  # its outline, the wire


@pytest.mark.parametrize(("height", "width", "radius"), [(7, 9, 2), (3, 2, 2), (1, 5, 1),
                                                     (40, 33, 2), (12, 10, 3)])
def test_the_outlines_share_at_the_image_edges(height: int, width: int, radius: int) -> None:
    """Windows cut by the image's edges count only the pairs inside it (float64 reference,
    random ids and background)."""
    rng = np.random.default_rng(height * width)
    mesh = rng.integers(0, 3, (height, width)).astype(np.int32)
    depth = rng.choice([0.0, 2.0, 5.0], (height, width)).astype(F32)
    np.testing.assert_allclose(outline_share(mesh, depth, radius),
                               ref.outline_share(mesh, depth, radius), rtol=1e-6, atol=1e-7)


def test_noisy_outlines_are_blurred_and_clean_ones_are_not() -> None:
    """The extra weight reaches the speckled region only: the clean object's outline and
    the wire are exchanged exactly as without it; the speckle's contrast falls; the frame's
    light is kept; and the stage matches the float64 reference."""
    colour, mesh, depth = _speckled(1)
    extra = noisy_outline_weights(outline_share(mesh, depth), 0.2)
    assert extra[:, :8].min() > 0.0 and not extra[:, 16:].any()
    frame = make_frame(34, 24, illumination=0.0, albedo=0.5, emission=colour, depth=depth)
    frame.mesh_id[:] = mesh
    frame.centre_sampled = True
    params = resolve_params("paper", temporal=False, atrous_iterations=0)
    plain = Denoiser(params.replace(edge_filter=0.05)).process(frame).color
    noisy = Denoiser(params.replace(edge_filter=0.05, noisy_outline_weight=0.2)
                     ).process(frame).color
    np.testing.assert_array_equal(noisy[:, :, 16:], plain[:, :, 16:])
    assert noisy[:, 4:20, 2:10].std() < 0.6 * plain[:, 4:20, 2:10].std()
    np.testing.assert_allclose(noisy.sum(), plain.sum(), rtol=1e-5)
    want = ref.noisy_outline_filter(plain * 0 + frame.emission, mesh, depth, 0.05, 0.2)
    np.testing.assert_allclose(noisy, want, rtol=1e-5, atol=1e-5)


def test_auto_is_for_centre_sampled_frames_only() -> None:
    assert edge_filter_weight(AUTO_PIXEL_FILTER, True) == 0.05
    assert edge_filter_weight(AUTO_PIXEL_FILTER, False) == 0.0
    assert edge_filter_weight(0.1, False) == 0.1
    assert "edge_filter" in stage_names(PRESETS["default"])
    assert "edge_filter" not in stage_names(PRESETS["paper"])
    # The noisy outlines' part runs on every frame: the stage is on without the base weight.
    assert "edge_filter" in stage_names(PRESETS["paper"].replace(noisy_outline_weight=0.1))


def test_the_denoiser_softens_a_centre_sampled_silhouette_only() -> None:
    """A bright object on a dark background, noise-free: with a centre-sampled header the
    silhouette's pixels exchange light (the outline columns move, the interior does not);
    a jittered frame is left as it was."""
    width, height = 24, 16
    depth = np.full((height, width), 5.0, F32)
    mesh = np.ones((height, width), np.int32)
    mesh[:, 12:] = 2
    illumination = np.where(np.arange(width) < 12, 2.0, 0.2).astype(F32)[None, :]
    outputs = {}
    for centre in (True, False):
        denoiser = Denoiser(PRESETS["default"].replace(pixel_filter=0.0))
        frame = make_frame(width, height, illumination=np.broadcast_to(illumination,
                                                                        (height, width)),
                           depth=depth, mesh_id=mesh)
        frame.centre_sampled = centre
        outputs[centre] = denoiser.process(frame).color
    step = outputs[False][:, :, 11] - outputs[False][:, :, 12]
    soft = outputs[True][:, :, 11] - outputs[True][:, :, 12]
    np.testing.assert_allclose(soft, step * (1.0 - 2 * 0.05), rtol=1e-4)
    np.testing.assert_array_equal(outputs[True][:, :, :10], outputs[False][:, :, :10])


def test_the_spill_made_on_its_box_alone_is_the_whole_frames() -> None:
    """``OutlineSpill.of`` crops the exchanges to the weighted pixels' box grown by one:
    bit for bit what the whole frame gives, including a region at the image's edge."""
    colour, mesh, depth = _speckled(2)
    weights = noisy_outline_weights(outline_share(mesh, depth), 0.25)
    big = np.random.default_rng(3).random((3, 40, 50)).astype(F32)
    big_mesh = np.ones((40, 50), np.int32)
    big_mesh[10:34, 16:50] = mesh  # the speckle inside, the wire's region at the right edge
    big_depth = np.full((40, 50), 5.0, F32)
    big_depth[10:34, 16:50] = depth
    big_weights = np.zeros((40, 50), F32)
    big_weights[10:34, 16:50] = weights
    whole = OutlineSpill(big_mesh, big_depth, big_weights, 2)
    cropped = OutlineSpill.of(big_mesh, big_depth, big_weights, 2)
    assert cropped.mesh_id.size < 0.5 * big_mesh.size
    np.testing.assert_array_equal(cropped.apply(big), whole.apply(big))
    assert not np.array_equal(whole.apply(big), big)
    # The spill's scratch kept from plane to plane: another plane's exchanges are its own.
    other = np.random.default_rng(8).random(big.shape).astype(F32)
    np.testing.assert_array_equal(cropped.apply(other), whole.apply(other))
    np.testing.assert_array_equal(cropped.apply(big), whole.apply(big))


@pytest.mark.parametrize("passes", [3, 4])
def test_the_spill_matches_a_float64_reference_in_place_or_not(passes: int) -> None:
    """A whole-frame spill (no crop: even passes end in the plane handed in) made in place,
    into another array and into a new one: the same bits, each ``passes`` exchanges of the
    float64 reference; the planes handed in are left alone unless they are ``out``."""
    colour, mesh, depth = _speckled(1)
    colour *= np.random.default_rng(4).uniform(0.5, 1.5, colour.shape).astype(F32)
    weights = noisy_outline_weights(outline_share(mesh, depth), 0.25)
    weights[0, 0] = weights[-1, -1] = 0.1  # the box is the whole frame
    spill = OutlineSpill.of(mesh, depth, weights, passes)
    assert spill.mesh_id.shape == mesh.shape
    want = colour.astype(np.float64)
    for _ in range(passes):
        want = ref.edge_filter(want, mesh, depth, weights)
    kept = colour.copy()
    fresh = spill.apply(colour)
    np.testing.assert_array_equal(colour, kept)
    into = np.full_like(colour, np.nan)
    assert spill.apply(colour, into) is into
    in_place = colour.copy()
    assert spill.apply(in_place, in_place) is in_place
    np.testing.assert_array_equal(fresh, into)
    np.testing.assert_array_equal(fresh, in_place)
    np.testing.assert_allclose(fresh, want, rtol=1e-5, atol=1e-6)
    assert not np.allclose(fresh, colour)


def test_the_exchanges_of_many_planes_at_once_are_each_planes() -> None:
    """``exchange`` over six planes gives each three the bits it gives them alone."""
    colour, mesh, depth = _speckled(2)
    other = np.random.default_rng(6).random(colour.shape).astype(F32)
    spill = OutlineSpill.of(mesh, depth, noisy_outline_weights(outline_share(mesh, depth),
                                                               0.25), 1)
    right, down = spill.pairs
    box = (slice(None), *spill.box)
    planes = np.ascontiguousarray(np.concatenate([colour[box], other[box]]))
    both = np.empty_like(planes)
    exchange(planes, right, down, np.empty_like(planes), both)
    for k, alone in enumerate((colour, other)):
        single = np.ascontiguousarray(alone[box])
        out = np.empty_like(single)
        exchange(single, right, down, np.empty_like(single), out)
        np.testing.assert_array_equal(both[3 * k:3 * k + 3], out)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_isolated_samples_and_near_match_float64_references(seed: int) -> None:
    rng = np.random.default_rng(seed)
    height, width = 13, 17
    mesh = np.where(rng.random((height, width)) < 0.15, 2, 1).astype(np.int32)
    depth = np.where(rng.random((height, width)) < 0.1, 0.0, 4.0).astype(F32)
    got = np.empty((height, width), dtype=bool)
    isolated_samples(mesh, depth, got)
    want = ref.isolated_samples(mesh, depth)
    np.testing.assert_array_equal(got, want)
    assert want.any() and not want.all()
    pixels = rng.random((height, width)) < 0.05
    np.testing.assert_array_equal(near(pixels), ref.near(pixels))
    np.testing.assert_array_equal(near(pixels, 1), ref.near(pixels, 1))


def _sparse_speckle() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A 30x40 frame: on the left a defocused edge's sparse speckle (one sample in eleven
    sees the ball, id 2, the rest the floor: too few outlines for the density ramp), on the right
    the clean floor with one lone pixel of a small object in focus (id 3)."""
    height, width = 30, 40
    mesh = np.ones((height, width), np.int32)
    y, x = np.mgrid[:height, :16]
    mesh[:, :16] = np.where((7 * y + 3 * x) % 11 == 0, 2, 1)
    mesh[15, 30] = 3
    depth = np.where(mesh == 2, 3.0, 5.0).astype(F32)
    depth[mesh == 3] = 4.0
    colour = np.where(mesh == 1, 0.5, 4.0).astype(F32)[None].repeat(3, axis=0)
    return colour, mesh, depth


def test_sparse_speckle_is_blurred_and_a_lone_object_in_focus_is_not() -> None:
    """On a centre-sampled frame, lone samples where the window holds outlines (sparse
    defocus speckle) take the full noisy-outline weight although the density ramp gives
    them none; a lone pixel on a clean floor (a small object in focus) keeps its colour, as
    does a lone sample next to a medium pixel (filters.stages.fill_medium's), and a jittered
    frame's lone samples; the stage matches the float64 reference."""
    colour, mesh, depth = _sparse_speckle()
    share = outline_share(mesh, depth)
    lone = np.empty(depth.shape, dtype=bool)
    isolated_samples(mesh, depth, lone)
    speckle = lone[:, 2:14] & (share[:, 2:14] >= 0.15)
    assert speckle.sum() > 10 and share[:, 2:14].max() < 0.3  # below the ramp
    assert lone[15, 30] and share[15, 30] < 0.15
    assert not noisy_outline_weights(share, 0.25)[:, 2:14].any()
    weights = noisy_outline_weights(share, 0.25, lone)
    np.testing.assert_array_equal(weights[:, 2:14][speckle], F32(0.25))
    assert not weights[:, 20:].any()
    frame = make_frame(40, 30, illumination=0.0, albedo=0.5, emission=colour, depth=depth)
    frame.mesh_id[:] = mesh
    params = resolve_params("paper", temporal=False, atrous_iterations=0)
    plain = Denoiser(params).process(frame).color
    # A jittered frame's lone samples may be an outline's other surface: left to the history.
    jittered = Denoiser(params.replace(noisy_outline_weight=0.25)).process(frame).color
    np.testing.assert_array_equal(jittered[:, 2:28, 4:], plain[:, 2:28, 4:])
    np.testing.assert_allclose(jittered, ref.noisy_outline_filter(
        frame.emission, mesh, depth, 0.0, 0.25, centre_sampled=False), rtol=1e-5, atol=1e-5)
    frame.centre_sampled = True
    noisy = Denoiser(params.replace(noisy_outline_weight=0.25)).process(frame).color
    assert noisy[:, :, :14].std() < 0.7 * plain[:, :, :14].std()
    np.testing.assert_array_equal(noisy[:, :, 20:], plain[:, :, 20:])
    np.testing.assert_allclose(noisy.sum(), plain.sum(), rtol=1e-5)
    np.testing.assert_allclose(noisy, ref.noisy_outline_filter(frame.emission, mesh, depth,
                                                               0.0, 0.25),
                               rtol=1e-5, atol=1e-5)
    medium = np.zeros(depth.shape, dtype=bool)
    medium[:, :16] = True
    np.testing.assert_array_equal(lone_samples(mesh, depth), lone)
    beside_medium = lone_samples(mesh, depth, medium)
    assert not beside_medium[:, :18].any() and beside_medium[15, 30]
