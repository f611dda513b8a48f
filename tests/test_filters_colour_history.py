"""Anti-aliased demodulation colours (``filters.colour_history``): the float64 reference,
convergence to the pixel's footprint average under motion, nothing where nothing moves, and
the bound that keeps a colour from brightening light that does not follow it."""

from __future__ import annotations

import numpy as np
import reference_svgf as ref
from moving_scene import scene_frame
from test_reference_stages import RULE, _close, as_reference, kernel_geometry

from svgf_cli.filters import modulate
from svgf_cli.filters.colour_history import accumulate_colours, antialias_remodulation
from svgf_cli.filters.denoiser import Denoiser
from svgf_cli.filters.params import PRESETS
from svgf_cli.frame import Frame, Signal

F32 = np.float32
TOLERANCES = (10.0, 0.002, 16.0)  # depth tolerance, depth slack, normal tolerance


GUIDE_BLACK = 0.1  # a G-buffer albedo's demodulation floor (the default preset's)


def _run_accumulate(t: int, seed: int) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Kernel and reference on the moving scene's frames t - 1 and t: two colours (the
    scene's albedo, and a darker copy under the G-buffer floor) into slots 2 and 0 of three,
    with a random previous accumulation; returns (kernel (3 slots), reference (2), colours)."""
    prev, cur = scene_frame(t - 1), scene_frame(t)
    rng = np.random.default_rng(seed)
    height, width = cur.depth.shape
    prev_colours = rng.uniform(0.0, 1.0, (3, 3, height, width)).astype(F32)
    colour = cur.albedo.copy()
    colour[:, 3, 5] = (2.0, 0.5, 0.5)  # no reflectance: stays radiance
    colour[:, 6, 7] = np.nan  # cleaned to 0, black: radiance
    dark = (cur.albedo * F32(0.3)).astype(F32)  # partly below the guide floor
    g_prev, g_cur = kernel_geometry(prev), kernel_geometry(cur)
    got = np.full((3, 3, height, width), np.nan, F32)
    slots = np.array([2, 0])
    blacks = np.array([RULE[0], GUIDE_BLACK], F32)
    accumulate_colours(cur.motion, cur.depth, g_cur["unit_normal"], cur.mesh_id,
                       g_cur["depth_slope"], g_cur["normal_width"], prev.depth,
                       g_prev["unit_normal"], prev.mesh_id, prev_colours, (colour, dark),
                       slots, blacks, F32(0.2), *(F32(t) for t in TOLERANCES), *RULE[1:], got)
    shape = prev.depth.shape
    previous = ref.History(np.zeros((1, 3, *shape)), np.zeros((1, 2, *shape)),
                           np.zeros((1, *shape)), np.zeros((1, *shape), bool),
                           np.ones(shape, bool), prev.depth.astype(np.float64),
                           g_prev["unit_normal"].astype(np.float64), prev.mesh_id)
    want = [ref.accumulate_colour(cur.motion, as_reference(g_cur), cur.mesh_id, previous,
                                  prev_colours[slot].astype(np.float64), c, 0.2, *TOLERANCES,
                                  float(black))
            for c, slot, black in zip((colour, dark), slots, blacks, strict=True)]
    assert np.isnan(got[1]).all()  # a slot no colour names is not written
    return got[slots], np.stack(want), [colour, dark]


def test_colour_accumulation_matches_reference() -> None:
    for t in (1, 2, 3):
        got, want, colours = _run_accumulate(t, seed=t)
        _close(got, want, 1e-6, f"frame {t}")
        for k, colour in enumerate(colours):
            clean = np.nan_to_num(colour, nan=0.0)
            changed = np.any(got[k] != clean, axis=0)
            assert changed.sum() > 50  # the history took part
            assert (~changed).sum() > 20  # disocclusions, background, radiance mode
        assert np.array_equal(got[0, :, 3, 5], colours[0][:, 3, 5])
        assert np.all(got[0, :, 6, 7] == 0.0)
        # Under the G-buffer floor the dark copy is radiance where the albedo is not.
        below = (colours[1].max(axis=0) < GUIDE_BLACK) & (colours[0].max(axis=0) > 0.01)
        assert below.any()
        assert np.array_equal(got[1][:, below], colours[1][:, below])


def _bound_case(seed: int) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    height, width = 9, 11
    light = rng.gamma(2.0, 0.5, (3, height, width)).astype(F32)
    light[:, 4, 5] = 40.0  # light that does not follow the colour: a glint over a dark texel
    colour = np.where(rng.random((1, height, width)) < 0.5, 0.8, 0.05) * np.ones((3, 1, 1))
    colour[:, 4, 5] = 0.05
    colour[:, 0, 0] = (3.0, 1.0, 1.0)  # radiance mode
    accumulated = np.clip(colour + rng.normal(0.0, 0.2, colour.shape), 0.0, 1.0)
    accumulated[:, 4, 5] = 0.8
    accumulated[:, 2, 2] = colour[:, 2, 2]  # unchanged: the light is kept exactly
    depth = np.ones((height, width), F32)
    depth[8, :3] = 0.0  # background
    return light, colour.astype(F32), accumulated.astype(F32), depth


def test_remodulation_bound_matches_reference() -> None:
    for seed in (1, 2, 3):
        light, colour, accumulated, depth = _bound_case(seed)
        zero = np.zeros_like(light)
        plain = np.zeros_like(light)
        rows = np.zeros((light.shape[1], 2), np.int64)
        modulate.remodulate_add(light, zero, colour, depth, zero, False, *RULE, plain, rows)
        got = plain.copy()
        antialias_remodulation(light, colour, accumulated, depth, *RULE, got)
        bounded = ref.bound_remodulation(light, colour, accumulated, depth, float(RULE[0]))
        want = ref.remodulate(bounded, colour, float(RULE[0]))
        surface = depth > 0
        _close(got[:, surface], want[:, surface], 1e-6, f"seed {seed}")
        # Untouched: unchanged colour, radiance mode, background.
        for y, x in ((2, 2), (0, 0), (8, 0), (8, 1), (8, 2)):
            assert np.array_equal(got[:, y, x], plain[:, y, x])
        # The glint over the dark texel: the brighter accumulated colour would have made it
        # 16x brighter; it stays within its neighbours' remodulated values.
        value = got[:, 4, 5]
        near = (light * colour)[:, 3:6, 4:7].reshape(3, -1)
        assert np.all(value <= near.max(axis=1) * (1 + 1e-6))
        assert np.all(light[:, 4, 5] * accumulated[:, 4, 5] > 2 * near.max(axis=1))


def _stripes(shift: float, width: int = 24, height: int = 6, motion: float = 0.0,
             light: float = 1.0) -> Frame:
    """A flat wall of vertical stripes 4 px wide (albedo 0.8 / 0.1) moved ``shift`` pixels
    right, lit by a constant ``light``, point-sampled at the pixel centres; ``motion``
    (pixels, backward) is the wall's motion since the frame before."""
    xs = np.arange(width) + 0.5 - shift
    albedo = np.where(np.floor(xs / 4.0) % 2 == 0, 0.8, 0.1).astype(F32)
    albedo = np.broadcast_to(albedo, (3, height, width)).copy()
    normal = np.zeros((3, height, width), F32)
    normal[2] = 1.0
    motion_plane = np.zeros((2, height, width), F32)
    motion_plane[0] = -motion
    radiance = (albedo * F32(light)).astype(F32)
    return Frame(signals=[Signal("light", radiance, albedo)], normal=normal,
                 depth=np.full((height, width), 5.0, F32), motion=motion_plane,
                 mesh_id=np.ones((height, width), np.int32), albedo=albedo)


def test_a_moving_edge_converges_to_the_footprint_average() -> None:
    """A noise-free wall moving 0.5 px a frame: the point samples at an edge pixel alternate
    between the stripes, the accumulated colour settles between them (the output with
    it), and the output at that pixel lies strictly inside the two stripes' values."""
    params = PRESETS["default"]
    on, off = Denoiser(params), Denoiser(params.replace(antialias_colours=False))
    for t in range(16):
        frame = _stripes(0.5 * t, motion=0.5 if t else 0.0)
        out_on, out_off = on.process(frame).color, off.process(frame).color
    edges = np.flatnonzero(np.abs(np.diff(frame.albedo[0, 3])) > 0.5)
    pixel = int(edges[1]) + 1  # the first pixel past an edge, not at the image border
    np.testing.assert_allclose(out_off[0, 3, pixel], frame.albedo[0, 3, pixel], rtol=1e-3)
    assert 0.2 < out_on[0, 3, pixel] < 0.7
    # Away from the edges nothing changes.
    inner = int(edges[1]) - 2
    np.testing.assert_allclose(out_on[:, 3, inner], out_off[:, 3, inner], rtol=1e-5)


def test_a_still_sequence_is_bit_identical_with_and_without() -> None:
    params = PRESETS["default"]
    on, off = Denoiser(params), Denoiser(params.replace(antialias_colours=False))
    rng = np.random.default_rng(4)
    for _ in range(4):
        frame = _stripes(0.0)
        noisy = frame.signals[0].radiance * rng.gamma(4.0, 0.25, frame.albedo.shape)
        frame.signals[0].radiance[...] = noisy.astype(F32)
        assert np.array_equal(on.process(frame).color, off.process(frame).color)


def test_the_colours_are_part_of_the_state() -> None:
    """A run resumed from state() continues bit-identically (the accumulated colours are
    saved with the history)."""
    params = PRESETS["default"]
    whole, first = Denoiser(params), Denoiser(params)
    frames = [_stripes(0.5 * t, motion=0.5 if t else 0.0) for t in range(6)]
    for frame in frames[:3]:
        whole.process(frame)
        first.process(frame)
    state = first.state()
    assert "history_colour" in state
    resumed = Denoiser(params)
    resumed.load_state(state)
    for frame in frames[3:]:
        assert np.array_equal(whole.process(frame).color, resumed.process(frame).color)
    assert "history_colour" not in Denoiser(params.replace(antialias_colours=False)).state()
