"""Named signals, demodulation modes and luminance weights through the Denoiser."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic import make_frame, static_sequence, texture

from svgf_cli.filters.denoiser import STATE_FORMAT, Denoiser
from svgf_cli.filters.params import resolve_params
from svgf_cli.frame import Frame, Signal

F32 = np.float32
ACESCG = (0.2722287168, 0.6740817658, 0.0536895174)


def _lobes(index: int, w: int = 28, h: int = 18, noise: float = 0.3) -> Frame:
    """Three signals with their own colours: diffuse (texture), glossy (grey), transmission
    (black except a patch, so mostly radiance mode), moving right by 0.75 px per frame."""
    rng = np.random.default_rng(index)
    diffuse_colour = texture(w, h, seed=1)
    glossy_colour = np.full((3, h, w), 0.6, F32)
    trans_colour = np.zeros((3, h, w), F32)
    trans_colour[:, 4:12, 8:20] = 0.9
    light = np.stack([np.full((h, w), v, F32) for v in (1.0, 0.8, 0.6)])

    def noisy(colour: np.ndarray, scale: float) -> np.ndarray:
        draw = rng.exponential(1.0, (h, w)).astype(F32) * F32(noise) + F32(1.0 - noise)
        return np.ascontiguousarray(colour * light * scale * draw[None], dtype=F32)

    depth = np.full((h, w), 5.0, F32)
    depth[:2] = 0.0
    normal = np.zeros((3, h, w), F32)
    normal[2] = 1.0
    normal[:, :2] = 0.0
    mesh = np.where(depth > 0, 1, -1).astype(np.int32)
    motion = np.zeros((2, h, w), F32)
    motion[0] = -0.75
    emission = np.zeros((3, h, w), F32)
    emission[:, 14:, :4] = 3.0
    return Frame(
        signals=[Signal("diffuse", noisy(diffuse_colour, 1.0), diffuse_colour),
                 Signal("glossy", noisy(glossy_colour, 0.4), glossy_colour),
                 Signal("transmission", noisy(trans_colour, 0.7), trans_colour)],
        albedo=diffuse_colour, normal=normal, depth=depth, motion=motion, mesh_id=mesh,
        emission=emission,
    )


def test_three_signals_are_filtered_independently_and_summed_with_emission() -> None:
    params = resolve_params("paper")
    frames = [_lobes(i) for i in range(4)]
    together = Denoiser(params, debug_layers=True)
    outputs = [together.process(f) for f in frames]
    last = outputs[-1]
    total = np.zeros_like(last.color)
    for name in ("diffuse", "glossy", "transmission"):
        # Each signal alone (a pair partner, or the lone last one) gives the same bits.
        alone = Denoiser(params)
        for f in frames:
            solo = Frame(signals=[f.signal(name)], albedo=f.albedo, normal=f.normal,
                         depth=f.depth, motion=f.motion, mesh_id=f.mesh_id)
            out = alone.process(solo)
        layer = np.stack([last.layers[f"{name}.{c}"] for c in "RGB"])
        assert layer.tobytes() == out.color.tobytes(), name
        total += layer
    np.testing.assert_allclose(last.color, total + frames[-1].emission, rtol=1e-6, atol=1e-6)
    # Per-signal modes: transmission is radiance mode outside its patch (surface pixels only).
    counts = last.counts
    surface = int((frames[-1].depth > 0).sum())
    assert counts["radiance_mode.transmission"] == surface - 8 * 12
    assert counts["radiance_mode.diffuse"] == counts["radiance_mode.glossy"] == 0
    np.testing.assert_array_equal(last.layers["radiance_mode.transmission"][4:12, 8:20], 0.0)
    # Per-signal history lengths are reported per signal.
    assert last.layers["history_length.glossy"][10, 10] == 4.0


def test_signal_names_must_stay_the_same() -> None:
    denoiser = Denoiser(resolve_params("paper"))
    denoiser.process(_lobes(0))
    with pytest.raises(ValueError, match="signals changed from diffuse\\+glossy\\+transmission"):
        denoiser.process(make_frame(28, 18))


def test_frame_validation_names_the_problem() -> None:
    frame = make_frame(8, 6)
    frame.signals.append(Signal("direct", frame.signals[0].radiance, frame.albedo))
    with pytest.raises(ValueError, match="'direct' is used twice"):
        frame.validate()
    frame = make_frame(8, 6)
    frame.signals[0].name = "dir.ect"
    with pytest.raises(ValueError, match="signal name 'dir.ect'"):
        frame.validate()
    frame = make_frame(8, 6)
    frame.signals[1].albedo = np.ones((3, 5, 8), F32)
    with pytest.raises(ValueError, match="indirect albedo: expected shape"):
        frame.validate()
    frame = make_frame(8, 6)
    frame.luminance_weights = (0.5, 0.5, 0.5)
    with pytest.raises(ValueError, match="must sum to 1"):
        frame.validate()


def test_constructors_take_emission_out_of_the_signal() -> None:
    h, w = 4, 5
    plane = np.full((3, h, w), 2.0, F32)
    emission = np.full((3, h, w), 0.5, F32)
    geometry = dict(albedo=np.full((3, h, w), 0.5, F32), normal=np.zeros((3, h, w), F32),
                    depth=np.ones((h, w), F32), motion=np.zeros((2, h, w), F32),
                    mesh_id=np.zeros((h, w), np.int32), emission=emission)
    split = Frame.direct_indirect(plane, plane, **geometry)
    assert split.names == ("direct", "indirect")
    np.testing.assert_array_equal(split.signal("direct").radiance, 1.5)
    np.testing.assert_array_equal(split.signal("indirect").radiance, 2.0)
    np.testing.assert_array_equal(split.total_radiance(), 4.0)
    combined = Frame.combined(plane, **geometry)
    assert combined.names == ("color",)
    np.testing.assert_array_equal(combined.total_radiance(), 2.0)


def _edge_sequence(frames: int, w: int = 32, h: int = 8) -> list[Frame]:
    """A black/white albedo edge on one plane moving right by half a pixel per frame.

    White (0.8) is demodulated; black (0) is radiance mode, with a constant radiance 0.3 (a
    reflection on black paint) that has nothing to do with the white side's illumination.
    """
    out = []
    x = np.arange(w, dtype=np.float64) + 0.5
    for i in range(frames):
        white = x < 10.25 + 0.5 * i
        albedo = np.where(white, 0.8, 0.0).astype(F32)[None, None].repeat(3, 0).repeat(h, 1)
        radiance = np.where(white, 0.8 * 1.0, 0.3).astype(F32)[None, None].repeat(3, 0)
        radiance = np.ascontiguousarray(radiance.repeat(h, 1))
        albedo = np.ascontiguousarray(albedo)
        out.append(Frame.combined(
            radiance, albedo=albedo, normal=np.tile(np.array([0, 0, 1], F32)[:, None, None],
                                                    (1, h, w)),
            depth=np.full((h, w), 4.0, F32), motion=np.full((2, h, w), [[[-0.5]], [[0.0]]], F32),
            mesh_id=np.ones((h, w), np.int32),
        ))
    return out


@pytest.mark.parametrize("preset", ["paper", "falcor"])
def test_black_white_edge_moving_half_a_pixel_per_frame_comes_out_exact(preset: str) -> None:
    """Radiance history (black side) and illumination history (white side) never mix:
    reprojection rejects taps of the other mode, and the a-trous and the spatial variance
    (with Falcor's colour blur of short-history pixels) give them no weight, so every frame
    equals its input."""
    frames = _edge_sequence(8)
    denoiser = Denoiser(resolve_params(preset), debug_layers=True)
    for frame in frames:
        out = denoiser.process(frame)
        np.testing.assert_allclose(out.color, frame.total_radiance(), rtol=2e-6, atol=1e-7)
    # History survives on both sides, away from the edge (a mode change resets it there).
    length = out.layers["history_length.color"]
    assert np.all(length[:, 2:10] == 8.0) and np.all(length[:, 24:] == 8.0)
    assert out.counts["radiance_mode.color"] == int((frames[-1].albedo[0] == 0).sum())


def test_an_albedo_far_above_one_does_not_make_a_hot_pixel() -> None:
    """Cycles' Denoising Albedo reaches 128 on mirror-like pixels: such a pixel is filtered
    as radiance, never remodulated by 128 (which made 160x hot pixels)."""
    h, w = 16, 16
    albedo = np.full((3, h, w), 0.5, F32)
    albedo[:, 8, 8] = 128.0
    albedo[:, 3, 12] = (0.5, 40.0, 0.5)  # one channel implausible is enough
    frames = []
    for i in range(6):
        frame = make_frame(w, h, illumination=1.0, albedo=albedo, noise=0.4, seed=i,
                           noise_kind="exponential", split=False)
        radiance = frame.signal("color").radiance
        radiance[:, 8, 8] = 0.6  # what the renderer saw there: a specular path, not 128 x L
        radiance[:, 3, 12] = 0.6
        frames.append(frame)
    denoiser = Denoiser(resolve_params("paper"))
    for frame in frames:
        out = denoiser.process(frame)
        radiance = frame.signal("color").radiance
        for y, x in ((8, 8), (3, 12)):
            local_max = float(radiance[:, y - 2:y + 3, x - 2:x + 3].max())
            assert float(out.color[:, y, x].max()) <= 3.0 * local_max
        assert out.counts["implausible_albedo.color"] == 2
        assert out.counts["radiance_mode.color"] == 2
    assert "2 pixel(s) with a demodulation colour above 1" in " ".join(out.warnings())
    # Everywhere else the image is the ordinary filtered one (no hot halo either).
    assert float(out.color.max()) < 3.0 * float(frames[-1].signal("color").radiance.mean())


def test_saturated_colour_with_a_highlight_that_ignores_it_is_not_amplified() -> None:
    """A dark channel of a saturated colour (red paint: 0.9, 1e-3, 1e-3) under a white
    highlight the colour does not describe (a glossy path): the relative floor bounds what
    that channel's division can leak into the neighbours."""
    h, w = 20, 20
    albedo = np.full((3, h, w), 0.5, F32)
    albedo[:, 6:14, 6:14] = np.array([0.9, 1e-3, 1e-3], F32)[:, None, None]
    denoiser = Denoiser(resolve_params("paper"))
    for i in range(5):
        rng = np.random.default_rng(100 + i)
        frame = make_frame(w, h, illumination=1.0, albedo=albedo, noise=0.3, seed=i,
                           noise_kind="exponential", split=False)
        highlight = rng.exponential(0.05, (h, w)).astype(F32)  # white, noisy, unmodulated
        frame.signal("color").radiance[:, 6:14, 6:14] += highlight[None, 6:14, 6:14]
        out = denoiser.process(frame)
    reference = 0.5 * np.ones((3, h, w), F32)
    reference[:, 6:14, 6:14] = (np.array([0.9, 1e-3, 1e-3], F32)[:, None, None] + 0.05)
    # Green/blue of the grey surround next to the red patch: no leak beyond the reference.
    ring = np.zeros((h, w), bool)
    ring[4:16, 4:16] = True
    ring[6:14, 6:14] = False
    assert float(out.color[1][ring].max()) < 2.0 * float(reference[1][ring].max())


def test_luminance_weights_steer_the_edge_stop() -> None:
    """Red and green of equal Rec.709 luminance: with Rec.709 weights the luminance stop
    sees no edge and blurs across it; with ACEScg weights (green 0.674, red 0.272) their
    luminances differ by a quarter and the edge is kept."""
    h, w = 12, 24
    red, green = 1.0, 0.2126 / 0.7152
    colour = np.zeros((3, h, w), F32)
    colour[0, :, : w // 2] = red
    colour[1, :, w // 2:] = green

    def run(weights: tuple[float, float, float]) -> np.ndarray:
        denoiser = Denoiser(resolve_params("paper"))
        for i in range(6):
            frame = make_frame(w, h, illumination=colour, albedo=1.0, split=False, seed=i)
            frame.luminance_weights = weights
            out = denoiser.process(frame)
        return out.color

    rec709 = run((0.2126, 0.7152, 0.0722))
    acescg = run(ACESCG)
    leak_rec709 = float(rec709[1, :, w // 2 - 3: w // 2].mean())  # green on the red side
    leak_acescg = float(acescg[1, :, w // 2 - 3: w // 2].mean())
    # (ACEScg still leaks a little: in the first frames the spatial variance estimate sees
    # the step between the sides as noise, and the feedback keeps it in the history.)
    assert leak_rec709 > 0.1
    assert leak_acescg < 0.25 * leak_rec709
    # The default is Rec.709, bit for bit.
    assert run(Frame.__dataclass_fields__["luminance_weights"].default).tobytes() == (
        rec709.tobytes())


def test_state_carries_named_per_signal_history() -> None:
    params = resolve_params("paper")
    frames = [_lobes(i) for i in range(5)]
    denoiser = Denoiser(params)
    for f in frames[:3]:
        denoiser.process(f)
    state = denoiser.state()
    assert int(state["format_version"]) == STATE_FORMAT
    assert state["history_length"].shape == (3, 18, 28)
    assert state["history_mode"].dtype == np.uint16 and state["history_mode"].shape == (18, 28)
    tail = [denoiser.process(f).color for f in frames[3:]]
    resumed = Denoiser(params)
    resumed.load_state(state)
    assert resumed.signal_names == ("diffuse", "glossy", "transmission")
    for f, want in zip(frames[3:], tail, strict=True):
        assert resumed.process(f).color.tobytes() == want.tobytes()
    old = {k: v for k, v in state.items() if k not in ("format_version", "history_mode")}
    with pytest.raises(ValueError, match="format 1, this version reads format 2"):
        Denoiser(params).load_state(old)
    renamed = dict(state)
    renamed["history_length"] = state["history_length"][:2]
    with pytest.raises(ValueError, match="history_length: shape .* diffuse\\+glossy"):
        Denoiser(params).load_state(renamed)
    other = Denoiser(params)
    other.load_state(state)
    with pytest.raises(ValueError, match="signals changed"):
        other.process(static_sequence(1, 28, 18)[0])
