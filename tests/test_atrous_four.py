"""Four signals (the Cycles lobe set) in the a-trous, and signals that are exactly 0 (issue 32).

Four signals run as the stage groups them (2 + 2); each signal's own arithmetic is the same
in every loop body, so every other grouping (3 + 1, one at a time) must give the same bits
(a four-signal loop body, when there is one, joins the comparison as one more grouping), all
within the float64 reference's tolerance. A signal whose colour and variance are +0
everywhere is not filtered at all: its output is +0 (the sums of eqs. 1-2 over finite
weights), and the whole denoiser gives the same bits as when it is filtered.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
import reference_svgf as ref
from moving_scene import scene_sequence

from svgf_cli.filters.atrous import atrous_iteration, luminance_stop_guides, zero_signals
from svgf_cli.filters.denoiser import Denoiser
from svgf_cli.filters.fastmath import REC709
from svgf_cli.filters.params import resolve_params
from svgf_cli.filters.stages import atrous as stage
from svgf_cli.frame import Frame, Signal

F32 = np.float32
SIGMAS = (4.0, 1.0, 2.5, 4.0)


def _scene(height: int, width: int, seed: int) -> dict[str, np.ndarray]:
    """Four signals over a sloped surface with a depth step, a normal crease, background
    columns, a row end and a hole; radiance-mode pixels in signals 0, 2 and 3."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    depth = 4.0 + 0.05 * x + 0.02 * y
    depth[:, width // 2:] += 1.5
    normal = np.zeros((3, height, width))
    normal[2] = -1.0
    normal[0, height // 2:] = 0.6
    normal /= np.linalg.norm(normal, axis=0)
    background = np.zeros((height, width), dtype=bool)
    background[:, :2] = True
    background[0] = True
    background[1, width - 2:] = True
    background[height - 2, width // 3] = True
    depth[background] = 0.0
    normal[:, background] = 0.0
    illumination = rng.gamma(1.5, 0.7, (4, 3, height, width))
    illumination[3] *= 20.0  # a bright signal next to dim ones
    variance = rng.gamma(1.0, 0.3, (4, height, width))
    variance[:, 3:7, 2:6] = 0.0
    mode = np.zeros((height, width), dtype=np.uint16)
    mode[2:6, 3:7] |= 1
    mode |= ((rng.uniform(size=(height, width)) < 0.15) << 2).astype(np.uint16)
    mode |= ((rng.uniform(size=(height, width)) < 0.3) << 3).astype(np.uint16)
    return {
        "illumination": illumination.astype(F32), "variance": variance.astype(F32),
        "mode": mode, "depth": depth.astype(F32),
        "ddx": np.gradient(depth, axis=1).astype(F32),
        "ddy": np.gradient(depth, axis=0).astype(F32), "normal": normal.astype(F32),
    }


def _filter(scene: dict[str, np.ndarray], part: slice, step: int, propagate: bool,
            out_c: np.ndarray, out_v: np.ndarray, luminance: np.ndarray,
            inverse_scale: np.ndarray) -> None:
    """Guides and one a-trous iteration of the signals ``part`` (one kernel call each)."""
    luminance_stop_guides(
        scene["illumination"][part], scene["variance"][part], scene["mode"], part.start,
        scene["depth"], SIGMAS[part], REC709, luminance[part], inverse_scale[part])
    atrous_iteration(
        scene["illumination"][part], scene["variance"][part], luminance[part],
        inverse_scale[part], scene["depth"], scene["ddx"], scene["ddy"], scene["normal"],
        step, 1.0, 128.0, propagate, out_c[part], out_v[part])


@pytest.mark.parametrize(("step", "width", "propagate"),
                         [(1, 23, True), (2, 9, True), (4, 21, False), (8, 300, True)])
def test_four_signals_give_the_same_bits_in_every_grouping(step: int, width: int,
                                                            propagate: bool) -> None:
    """Bit for bit: the stage's grouping of 4 = 3 + 1 = each alone (guides included)."""
    height = 13
    scene = _scene(height, width, seed=step + width)
    together_c = np.full_like(scene["illumination"], np.nan)
    together_v = np.full_like(scene["variance"], np.nan)
    luminance = np.empty_like(scene["variance"])
    inverse_scale = np.empty_like(luminance)
    for part in stage.signal_groups(4):
        _filter(scene, part, step, propagate, together_c, together_v, luminance,
                inverse_scale)
    for parts in ((slice(0, 3), slice(3, 4)), tuple(slice(s, s + 1) for s in range(4))):
        apart_c = np.full_like(together_c, np.nan)
        apart_v = np.full_like(together_v, np.nan)
        apart_luminance = np.empty_like(luminance)
        apart_inverse = np.empty_like(luminance)
        for part in parts:
            _filter(scene, part, step, propagate, apart_c, apart_v, apart_luminance,
                    apart_inverse)
        np.testing.assert_array_equal(apart_luminance, luminance)
        np.testing.assert_array_equal(apart_inverse, inverse_scale)
        np.testing.assert_array_equal(together_c, apart_c)
        np.testing.assert_array_equal(together_v, apart_v)
    assert np.isnan(together_v).all() != propagate
    # And the paper's equations in float64 (the tolerance of test_filters_atrous).
    want_c, want_v = ref.atrous_iteration(
        scene["illumination"], scene["variance"], np.abs(luminance), luminance < 0,
        inverse_scale, scene["depth"], scene["ddx"], scene["ddy"], scene["normal"], step,
        1.0, 128.0)
    np.testing.assert_allclose(together_c, want_c, rtol=2e-4, atol=1e-6)
    if propagate:
        np.testing.assert_allclose(together_v, want_v, rtol=4e-4, atol=1e-7)


def test_signal_groups_and_the_span_of_signals_that_are_not_zero() -> None:
    sizes = {n: [g.stop - g.start for g in stage.signal_groups(n)] for n in range(1, 8)}
    assert sizes == {1: [1], 2: [2], 3: [3], 4: [2, 2], 5: [3, 2], 6: [3, 3], 7: [3, 2, 2]}
    # Zero signals at either end are skipped; one between others is filtered with them
    # (a group split in two would cost more).
    assert stage.filtered_span([False] * 4) == slice(0, 4)
    assert stage.filtered_span([True, False, False, True]) == slice(1, 3)
    assert stage.filtered_span([False, True, False, True]) == slice(0, 3)
    span = stage.filtered_span([True, True])
    assert span.stop - span.start == 0


def test_zero_signals_are_every_bit_zero() -> None:
    illumination = np.zeros((4, 3, 5, 7), dtype=F32)
    variance = np.zeros((4, 5, 7), dtype=F32)
    illumination[0, 2, 4, 6] = 1e-30  # the very last value of signal 0
    variance[1, 4, 6] = 1e-30  # only the variance of signal 1
    illumination[2, 1, 3, 2] = -0.0  # -0.0 is not +0: its output's sign would differ
    assert zero_signals(illumination, variance).tolist() == [False, False, False, True]


def _four_signal_frames(count: int, fourth: Callable[[Frame], np.ndarray],
                        position: int = 3) -> list[Frame]:
    """The moving scene's three lobes and a fourth signal ``fourth(frame)`` (a volume:
    demodulated by white) at index ``position``."""
    frames = scene_sequence(count, layout="three", width=40, height=28)
    for frame in frames:
        albedo = np.ones_like(frame.signals[0].albedo)
        frame.signals.insert(position, Signal("volume", fourth(frame), albedo, mixed=True))
    return frames


def _outputs(frames: list[Frame]) -> list[np.ndarray]:
    denoiser = Denoiser(resolve_params("default"))
    outputs = [denoiser.process(frame).color.copy() for frame in frames]
    return outputs + [np.asarray(v) for v in denoiser.state().values()
                      if isinstance(v, np.ndarray)]


@pytest.mark.parametrize("position", [3, 0, 1])
def test_a_zero_signal_is_skipped_with_the_same_output(monkeypatch: pytest.MonkeyPatch,
                                                       position: int) -> None:
    """Skipped at either end (3, 0), filtered with the others between them (1): the same
    bits as when the signal is filtered like any other."""
    frames = _four_signal_frames(4, lambda f: np.zeros_like(f.signals[0].radiance), position)
    found: list[list[bool]] = []

    def spy(illumination: np.ndarray, variance: np.ndarray) -> np.ndarray:
        zero = zero_signals(illumination, variance)
        found.append(zero.tolist())
        return zero

    monkeypatch.setattr(stage, "zero_signals", spy)
    skipped = _outputs(frames)
    assert found and all(z == [s == position for s in range(4)] for z in found)
    monkeypatch.setattr(stage, "zero_signals", lambda c, v: np.zeros(c.shape[0], dtype=bool))
    filtered = _outputs(frames)
    for a, b in zip(skipped, filtered, strict=True):
        np.testing.assert_array_equal(a, b)
