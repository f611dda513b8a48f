"""Temporal demodulation colour (``filters.albedo_history``, ``--temporal-albedo``).

The kernel against its float64 reference (``reference_svgf.accumulate_albedo``) on a scene
with background, mesh ids, out-of-image and NaN motion, pixels without history and a colour
that changes mode; then what it is for: a colour that flips between two textures from frame
to frame (one sample of a footprint on a texture edge) converges to their mean, a colour that
does not change stays exact, and a history outside the current 3x3 range is pulled into it.
In the Denoiser: the output is remodulated by the running mean, and a state round trip
continues bit-identically. A bidirectional run combines both passes' means by their
effective sample counts (``combine_albedo``, against its reference), also through the
half-float spill.
"""

from __future__ import annotations

import numpy as np
import pytest
import reference_svgf as ref

from svgf_cli.filters.albedo_history import accumulate_albedo, combine_albedo
from svgf_cli.filters.bidirectional import effective_counts
from svgf_cli.filters.denoiser import Denoiser
from svgf_cli.filters.params import resolve_params
from svgf_cli.filters.two_pass import denoise_bidirectional
from svgf_cli.frame import Frame, Signal

F32 = np.float32
BLACK = F32(1e-3)
MAX_REFLECTANCE = F32(ref.MAX_REFLECTANCE)
FLOOR = F32(ref.RELATIVE_ALBEDO_FLOOR)


def _run(albedo, history, length, motion, depth, mesh, prev_depth, prev_mesh,
         alpha=0.2, cap=32.0, catmull_rom=False):
    # Contiguous arrays, as the Denoiser passes: a view would compile the kernel once more
    # for its layout (seconds of a cold test run each).
    albedo, history, length, motion, depth, mesh, prev_depth, prev_mesh = (
        np.ascontiguousarray(a) for a in (albedo, history, length, motion, depth, mesh,
                                          prev_depth, prev_mesh))
    out = np.full(albedo.shape, np.nan, dtype=F32)
    out_length = np.full(depth.shape, np.nan, dtype=F32)
    accumulate_albedo(albedo, history, length, motion, depth, mesh, prev_depth, prev_mesh,
                      F32(alpha), F32(cap), BLACK, MAX_REFLECTANCE, FLOOR, out, out_length,
                      catmull_rom=catmull_rom)
    return out, out_length


@pytest.mark.parametrize("catmull_rom", [False, True])
def test_kernel_matches_the_float64_reference(catmull_rom: bool) -> None:
    rng = np.random.default_rng(5)
    height, width = 13, 17
    albedo = rng.uniform(0.02, 0.9, (3, height, width)).astype(F32)
    albedo[:, 4, 5] = [2.0, 3.0, 1.5]  # not a reflectance: radiance mode
    albedo[:, 6, 6] = 0.0  # black: radiance mode
    albedo[1, 7, 8] = np.nan  # cleaned to 0
    history = rng.uniform(0.0, 1.2, (3, height, width)).astype(F32)
    history[:, 6, 7] = [1.9, 1.9, 1.9]  # a mean in another mode than its neighbours'
    length = rng.integers(0, 6, (height, width)).astype(F32)
    motion = rng.uniform(-1.6, 1.6, (2, height, width)).astype(F32)
    motion[:, 0, :3] = 40.0  # out of the image
    motion[0, 2, 2] = np.nan
    depth = rng.uniform(1.0, 3.0, (height, width)).astype(F32)
    depth[:, 0] = 0.0
    depth[5, 9] = 0.0
    mesh = np.where(np.arange(width)[None, :] < 9, 1, 2).astype(np.int32).repeat(height, 0)
    prev_depth = depth.copy()
    prev_depth[3, :] = 0.0
    prev_mesh = mesh.copy()
    prev_mesh[8:, 10:] = 3
    if catmull_rom:  # positions whole in one axis: one column or row of the spline
        motion[0, ::4] = np.round(motion[0, ::4])
        motion[1, 1::4] = np.round(motion[1, 1::4])
    out, out_length = _run(albedo, history, length, motion, depth, mesh, prev_depth, prev_mesh,
                           catmull_rom=catmull_rom)
    want, want_length = ref.accumulate_albedo(albedo, history, length, motion, depth, mesh,
                                              prev_depth, prev_mesh, 0.2, 32.0, float(BLACK),
                                              catmull_rom)
    np.testing.assert_allclose(out, want, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(out_length, want_length, rtol=1e-6, atol=1e-6)
    # The scene exercises every branch: kept means, rejected taps, background.
    kept = (out_length > 1.0)
    assert 20 < kept.sum() < kept.size - 20
    assert not np.allclose(out[:, kept], ref.clean_albedo(albedo)[:, kept])
    if catmull_rom:  # the spline applied at some pixels (and only changed the means there)
        bilinear, bilinear_length = _run(albedo, history, length, motion, depth, mesh,
                                         prev_depth, prev_mesh)
        assert np.array_equal(out_length, bilinear_length)
        assert np.any(out != bilinear, axis=0).sum() >= 5


def test_catmull_rom_support_across_a_mesh_edge_keeps_the_bilinear_fetch() -> None:
    """Two meshes side by side, last frame's means very different across the edge, half-pixel
    motion: next to the edge the spline's outer taps lie on the other mesh, so the pixel
    keeps the bilinear fetch of its own mesh; away from the edge the spline applies."""
    height, width = 8, 20
    rng = np.random.default_rng(9)
    depth, _, _ = _flat(height, width)
    mesh = np.where(np.arange(width)[None, :] < 10, 1, 2).astype(np.int32).repeat(height, 0)
    albedo = rng.uniform(0.05, 0.95, (3, height, width)).astype(F32)  # a wide 3x3 range
    x = np.arange(width)
    history = np.broadcast_to(0.3 + 0.2 * np.sin(x / 1.3), (3, height, width)).astype(F32)
    history = np.where(mesh[None] == 2, F32(0.9), history).astype(F32)
    length = np.full((height, width), 4.0, F32)
    motion = np.zeros((2, height, width), F32)
    motion[0] = 0.5
    sharp, _ = _run(albedo, history, length, motion, depth, mesh, depth, mesh,
                    catmull_rom=True)
    bilinear, _ = _run(albedo, history, length, motion, depth, mesh, depth, mesh)
    want, _ = ref.accumulate_albedo(albedo, history, length, motion, depth, mesh, depth, mesh,
                                    0.2, 32.0, float(BLACK), True)
    np.testing.assert_allclose(sharp, want, rtol=1e-5, atol=1e-6)
    rows = slice(1, height - 1)
    assert np.array_equal(sharp[:, rows, 8], bilinear[:, rows, 8])  # tap 10 on mesh 2
    assert np.any(sharp[:, rows, 3:7] != bilinear[:, rows, 3:7])


def test_catmull_rom_keeps_a_sharp_texture_under_sub_pixel_motion() -> None:
    """A noise-free stripe texture seen through half-pixel motion frame after frame: the
    bilinear mean washes the stripes out, the spline keeps them; a constant colour stays
    exactly constant, and nothing leaves the current 3x3 range."""
    height, width = 8, 40
    depth, mesh, _ = _flat(height, width)
    x = np.arange(width)
    texture = (0.5 + 0.3 * np.sin(2 * np.pi * x / 6.0)).astype(F32)
    albedo = np.broadcast_to(texture, (3, height, width)).astype(F32)
    contrast = {}
    for catmull_rom in (False, True):
        mean, length = albedo.copy(), np.ones((height, width), F32)
        for frame in range(12):
            motion = np.zeros((2, height, width), F32)
            motion[0] = 0.5 if frame % 2 == 0 else -0.5
            # Each frame samples the texture where the pixel is: the same texture back.
            mean, length = _run(albedo, mean, length, motion, depth, mesh, depth, mesh,
                                catmull_rom=catmull_rom)
        row = mean[0, 4, 8:32]
        contrast[catmull_rom] = float(row.max() - row.min())
    assert contrast[True] > 1.15 * contrast[False]
    flat = np.full((3, height, width), 0.4, F32)
    motion = np.full((2, height, width), 0.3, F32)
    out, _ = _run(flat, flat, np.full((height, width), 5.0, F32), motion, depth, mesh, depth,
                  mesh, catmull_rom=True)
    assert np.all(out == F32(0.4))


def _flat(height: int, width: int) -> tuple[np.ndarray, ...]:
    depth = np.full((height, width), 2.0, dtype=F32)
    mesh = np.ones((height, width), dtype=np.int32)
    motion = np.zeros((2, height, width), dtype=F32)
    return depth, mesh, motion


def test_a_colour_that_flips_between_two_textures_converges_to_their_mean() -> None:
    depth, mesh, motion = _flat(5, 6)
    # A vertical texture edge: columns 0-2 dark, 3-5 light; the edge column 3's single
    # sample lands on either side from frame to frame.
    base = np.where(np.arange(6) < 3, 0.1, 0.7).astype(F32)
    colour = np.broadcast_to(base, (3, 5, 6)).copy()
    history = np.zeros_like(colour)
    length = np.zeros((5, 6), dtype=F32)
    seen = []
    for frame in range(40):
        current = colour.copy()
        current[:, :, 3] = 0.1 if frame % 2 else 0.7
        history, length = _run(current, history, length, motion, depth, mesh, depth, mesh)
        seen.append(float(history[0, 2, 3]))
    # An exponential average of alternating 0.1 / 0.7 with alpha 0.2: within 0.04 of 0.4.
    assert abs(np.mean(seen[-10:]) - 0.4) < 0.02
    assert max(abs(v - 0.4) for v in seen[-10:]) < 0.05
    # Columns that never change stay exact away from the edge, and next to it the first
    # frame's spatial estimate has faded out.
    np.testing.assert_allclose(history[:, :, :2], colour[:, :, :2], rtol=1e-6)
    np.testing.assert_allclose(history[:, :, 5:], colour[:, :, 5:], rtol=1e-6)
    np.testing.assert_allclose(history[:, :, 2], 0.1, atol=1e-4)
    np.testing.assert_allclose(history[:, :, 4], 0.7, atol=1e-4)
    assert length.max() == 32.0


def test_a_history_outside_the_current_range_is_clamped_into_it() -> None:
    depth, mesh, motion = _flat(4, 4)
    current = np.full((3, 4, 4), 0.3, dtype=F32)
    current[:, 1, 1] = 0.5
    history = np.full((3, 4, 4), 0.9, dtype=F32)  # a texture that has changed
    length = np.full((4, 4), 10.0, dtype=F32)
    out, out_length = _run(current, history, length, motion, depth, mesh, depth, mesh)
    # Pixel (3, 3): its 3x3 is all 0.3, so the history becomes 0.3 before the blend.
    np.testing.assert_allclose(out[:, 3, 3], 0.3, rtol=1e-6)
    # Pixel (1, 1): range [0.3, 0.5]; clamped to 0.5, blended with 0.5.
    np.testing.assert_allclose(out[:, 1, 1], 0.5, rtol=1e-6)
    # Pixel (0, 0): range [0.3, 0.5] (its 3x3 holds (1, 1)): 0.5 + 0.2 (0.3 - 0.5).
    np.testing.assert_allclose(out[:, 0, 0], 0.46, rtol=1e-5)
    assert np.all(out_length == 11.0)


def test_only_reflectances_are_averaged() -> None:
    depth, mesh, motion = _flat(3, 4)
    current = np.full((3, 3, 4), 0.5, dtype=F32)
    current[:, :, 0] = [[4.0], [4.0], [4.0]]  # not a reflectance (radiance mode)
    current[:, 1, 2] = [0.0015, 0.0, 0.0]
    current[:, 1, 3] = [0.0, 0.0, 0.0015]
    history = np.full((3, 3, 4), 0.5, dtype=F32)
    history[:, :, 1] = 3.0  # a mean of colours that were not reflectances
    history[:, 1, 2] = [0.0, 0.0, 0.0015]
    length = np.ones((3, 4), dtype=F32)
    out, out_length = _run(current, history, length, motion, depth, mesh, depth, mesh)
    # Radiance-mode pixels keep their colour and restart.
    np.testing.assert_array_equal(out[:, :, 0], current[:, :, 0])
    assert np.all(out_length[:, 0] == 1.0)
    # Column 1's history is no reflectance: no tap, so the first frame's estimate (the
    # column-0 neighbours left out), h = 1.
    assert np.all(out_length[:, 1] == 1.0)
    assert np.all(out[:, :, 1] < 0.51)
    # (1, 2): two reflectances whose blend (0.00075, 0, 0.00075) is none: the colour stays.
    np.testing.assert_array_equal(out[:, 1, 2], current[:, 1, 2])
    assert out_length[1, 2] == 1.0


def test_without_history_the_colour_is_the_gaussian_mean_of_its_surface() -> None:
    depth, mesh, motion = _flat(4, 5)
    mesh[:, 3:] = 2  # another object: never mixed in
    depth[0, 0] = 0.0  # background: never mixed in
    colour = np.full((3, 4, 5), 0.2, dtype=F32)
    colour[:, 1, 1] = 0.8
    colour[:, :, 3:] = 0.9
    length = np.zeros((4, 5), dtype=F32)
    out, out_length = _run(colour, colour, length, motion, depth, mesh, depth, mesh)
    edge, corner = np.exp(-2.0), np.exp(-4.0)
    # (1, 1): centre 0.8, its 8 neighbours but the background corner at 0.2.
    want = (0.8 + 0.2 * (4 * edge + 3 * corner)) / (1 + 4 * edge + 3 * corner)
    np.testing.assert_allclose(out[:, 1, 1], want, rtol=1e-5)
    # (1, 2): next to the other object; (1, 1) is an edge neighbour.
    want = (0.2 + 0.8 * edge + 0.2 * 2 * edge + 0.2 * 2 * corner) / (1 + 3 * edge + 2 * corner)
    np.testing.assert_allclose(out[:, 1, 2], want, rtol=1e-5)
    np.testing.assert_allclose(out[:, :, 3:], colour[:, :, 3:], rtol=1e-6)
    assert out_length[0, 0] == 0.0 and np.all(out_length[depth > 0] == 1.0)


def _frame(colour: np.ndarray, light: float) -> Frame:
    height, width = colour.shape[1:]
    radiance = (colour * F32(light)).astype(F32)
    normal = np.zeros((3, height, width), dtype=F32)
    normal[2] = 1.0
    return Frame(
        signals=[Signal("color", radiance, colour)],
        normal=normal, depth=np.full((height, width), 2.0, dtype=F32),
        motion=np.zeros((2, height, width), dtype=F32),
        mesh_id=np.ones((height, width), dtype=np.int32), albedo=colour,
    )


def _edge_colours(frames: int) -> list[np.ndarray]:
    colours = []
    for index in range(frames):
        colour = np.full((3, 8, 10), 0.1, dtype=F32)
        colour[:, :, 5:] = 0.7
        colour[:, :, 5] = 0.1 if index % 2 else 0.7  # the edge column flips
        colours.append(colour)
    return colours


@pytest.mark.parametrize("on", [False, True])
def test_the_denoiser_remodulates_by_the_running_mean(on: bool) -> None:
    denoiser = Denoiser(resolve_params("default", temporal_albedo=on))
    for colour in _edge_colours(12):
        output = denoiser.process(_frame(colour, 2.0)).color
    edge = output[0, 2:6, 5]
    # Constant light 2: the input flips between 0.2 and 1.4 at the edge column (frame 12
    # has 0.1, i.e. 0.2); with the running mean it is near 2 * 0.4.
    if on:
        assert np.all(np.abs(edge - 0.8) < 0.12)
    else:
        assert np.all(edge < 0.4)
    np.testing.assert_allclose(output[0, 2:6, 7], 1.4, rtol=0.02)  # no edge: unchanged


def test_state_round_trip_continues_bit_identically() -> None:
    params = resolve_params("default", temporal_albedo=True)
    colours = _edge_colours(6)
    straight = Denoiser(params)
    outputs = [straight.process(_frame(c, 1.5)).color for c in colours]
    first = Denoiser(params)
    for colour in colours[:3]:
        first.process(_frame(colour, 1.5))
    state = first.state()
    assert "albedo_history" in state and "albedo_length" in state
    second = Denoiser(params)
    second.load_state(state)
    resumed = [second.process(_frame(c, 1.5)).color for c in colours[3:]]
    for got, want in zip(resumed, outputs[3:], strict=True):
        np.testing.assert_array_equal(got, want)


def test_combine_albedo_matches_the_float64_reference() -> None:
    rng = np.random.default_rng(9)
    height, width = 9, 11
    forward = rng.uniform(0.05, 0.9, (3, height, width)).astype(F32)
    reverse = rng.uniform(0.05, 0.9, (3, height, width)).astype(F32)
    albedo = rng.uniform(0.05, 0.9, (3, height, width)).astype(F32)
    forward_length = rng.integers(0, 40, (height, width)).astype(F32) * F32(0.75)
    reverse_length = rng.integers(0, 40, (height, width)).astype(F32) * F32(0.75)
    forward[:, 2, 3] = [1.04, 0.2, 0.2]  # the mean of 1.04 and 1.06 ...
    reverse[:, 2, 3] = [0.2, 0.2, 1.06]  # ... classifies as a reflectance, the colour not
    albedo[:, 2, 3] = [1.1, 1.1, 1.1]
    forward_length[2, 3] = reverse_length[2, 3] = 4.0
    counts = effective_counts(0.2, 32)
    out = np.empty_like(forward)
    combine_albedo(forward, forward_length, reverse, reverse_length, albedo, counts, BLACK,
                   MAX_REFLECTANCE, FLOOR, out)
    want = ref.combine_albedo(forward, forward_length, reverse, reverse_length, albedo, 0.2,
                              float(BLACK))
    np.testing.assert_allclose(out, want, rtol=1e-5, atol=1e-7)
    np.testing.assert_array_equal(out[:, 2, 3], reverse[:, 2, 3])
    both = (forward_length > 0) & (reverse_length > 0)
    assert not np.allclose(out[:, both], reverse[:, both])
    # In place over the forward means (as the Denoiser calls it).
    combine_albedo(forward, forward_length, reverse, reverse_length, albedo, counts, BLACK,
                   MAX_REFLECTANCE, FLOOR, forward)
    np.testing.assert_array_equal(forward, out)


def test_a_bidirectional_run_remodulates_by_both_passes_means() -> None:
    params = resolve_params("default", temporal_albedo=True)
    frames = [_frame(c, 2.0) for c in _edge_colours(8)]
    outputs = [o.color for o in denoise_bidirectional(frames, params)]
    # Every frame, the first and last included, sees about half its frames at 0.1 and
    # half at 0.7 on the edge column: output near 2 * 0.4 (one pass alone: 0.2 or 1.4 on
    # the end frame).
    for output in (outputs[0], outputs[3], outputs[-1]):
        assert np.all(np.abs(output[0, 2:6, 5] - 0.8) < 0.15)
    # Spilled as a file run spills (half floats): the same within half rounding.
    spilled = [o.color for o in denoise_bidirectional(frames, params, half=True)]
    for got, want in zip(spilled, outputs, strict=True):
        np.testing.assert_allclose(got, want, rtol=2e-3, atol=1e-4)


def _pair(colour: np.ndarray, light: float) -> Frame:
    """Direct and indirect light over one colour array (as a reader gives them)."""
    single = _frame(colour, light)
    radiance = single.signals[0].radiance
    return Frame.direct_indirect(radiance * F32(0.75), radiance * F32(0.25), albedo=colour,
                                 normal=single.normal, depth=single.depth,
                                 motion=single.motion, mesh_id=single.mesh_id)


def test_signals_sharing_a_colour_share_one_mean_also_bidirectionally() -> None:
    params = resolve_params("default", temporal_albedo=True)
    frames = [_pair(c, 2.0) for c in _edge_colours(8)]
    denoiser = Denoiser(params)
    for frame in frames[:3]:
        denoiser.process(frame)
    state = denoiser.state()
    assert state["albedo_history"].shape[0] == 1
    np.testing.assert_array_equal(state["albedo_slots"], [0, 0])
    outputs = [o.color for o in denoise_bidirectional(frames, params, half=True)]
    assert np.all(np.abs(outputs[-1][0, 2:6, 5] - 0.8) < 0.15)


def test_a_glossy_signal_keeps_its_colour() -> None:
    """Only the diffuse signal is remodulated by its running mean: a glossy signal over the
    same flipping edge keeps this frame's colour (its light follows reflections, not the
    texture), with or without the option."""
    on = Denoiser(resolve_params("default", temporal_albedo=True), debug_layers=True)
    off = Denoiser(resolve_params("default", temporal_albedo=False), debug_layers=True)
    for colour in _edge_colours(8):
        frame = _frame(colour, 2.0)
        frame.signals.append(Signal("gloss", (colour * F32(0.5)).astype(F32), colour.copy(),
                                    glossy=True))
        with_mean, without = on.process(frame).layers, off.process(frame).layers
    np.testing.assert_array_equal(with_mean["gloss.R"], without["gloss.R"])
    name = frame.signals[0].name
    assert np.abs(with_mean[f"{name}.R"] - without[f"{name}.R"]).max() > 0.1
