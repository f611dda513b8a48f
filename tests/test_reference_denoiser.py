"""The whole ``Denoiser`` against the float64 ``ReferenceDenoiser``, frame by frame.

Six frames of ``moving_scene`` (an object moving over a panning textured wall, a coplanar
sticker, background, black albedo, emission; 1-spp exponential noise; exact motion, depth,
normals and ids), for both presets, with every optional stage on, once with inexact
sub-pixel motion, and with the generalised signals: three signals with colours of their own
(a diffuse colour with a black stripe moving across the wall, so pixels change mode between
frames; a glossy colour above 1.05 on part of the object; a transmission colour that is
black on most pixels) and ACEScg luminance weights; the paper's two signals with the moving
stripe (both signals change mode together); and a frame with non-finite and beyond-limit
values in every plane. Each frame compares, per signal, the history length (whole counts
exactly: one off by a rounding error would cross the variance threshold), the modes, the
variance entering the a-trous, the filtered radiance; then the output colour, the
persistent history (colour, moments, modes) and the value-policy counts (exactly).

Tolerance: ``|denoiser - reference| <= 2e-4 (|reference| + max |reference|)`` per frame and
quantity. The kernels run in float32 (relative rounding 6e-8 per operation) and the a-trous
weights use ``fast_exp`` (relative error < 4e-6) and ``fast_log2`` (absolute error < 1e-6 on
``log2 cos``, so up to 128 ln2 1e-6 = 9e-5 relative on ``w_n`` at sigma_n = 128); through five
iterations and six frames of feedback the measured worst case over every case here is
9.1e-6 of the quantity's maximum (the paper case's first frame, where every pixel takes the
spatial variance; ``SVGF_REFERENCE_REPORT=1`` prints it per case). 2e-4 leaves a 20x margin
on that, and every filter bug planted by ``tests/mutants/plant.py`` still exceeds it.
"""

from __future__ import annotations

import dataclasses
import os
from typing import Any

import numpy as np
import pytest
import reference_svgf as ref
from moving_scene import ACESCG_LUMINANCE, plant_extremes, scene_frame, scene_sequence

from svgf_cli.filters.context import FrameContext, StageBase
from svgf_cli.filters.denoiser import Denoiser
from svgf_cli.filters.modulate import NO_HISTORY
from svgf_cli.filters.params import SVGFParams, resolve_params
from svgf_cli.frame import Frame

TOLERANCE = 2e-4
EXTRAS = {"firefly_clamp": 2.0, "history_clamp": 1.5, "taa": True}
# Inexact sub-pixel motion: bilinear weights round in float32 (history lengths are snapped to
# whole counts, so the variance threshold still sees the same h as the reference).
INEXACT_MOTION = {"wall_speed": 0.3, "object_velocity": (2.3, 0.6)}
THREE = {"layout": "three", "luminance_weights": ACESCG_LUMINANCE}
CASES: dict[str, tuple[SVGFParams, dict[str, Any], int | None]] = {
    # name: (params, scene options, frame that gets plant_extremes)
    "paper": (resolve_params("paper"), {}, None),
    "falcor": (resolve_params("falcor"), {"layout": "combined"}, None),
    "paper+extras": (resolve_params("paper", spatial_variance_blur_color=True, **EXTRAS), {},
                     None),
    "falcor+extras": (resolve_params("falcor", **EXTRAS), {"layout": "combined"}, None),
    "paper, inexact motion": (resolve_params("paper"), INEXACT_MOTION, None),
    "three signals, ACEScg": (resolve_params("paper"), THREE, None),
    "three signals, falcor+extras": (resolve_params("falcor", **EXTRAS), THREE, None),
    "paper, moving edge": (resolve_params("paper"), {"moving_edge": True}, None),
    "three signals, extreme frame": (resolve_params("paper"), THREE, 2),
    "paper, extreme frame": (resolve_params("paper", **EXTRAS), {}, 3),
    # anti-lag (the default preset) where the light drops at frame 3, and with every extra
    "default, light step": (resolve_params("default"), {"light_step": (3, 0.3)}, None),
    "three signals, default, light step": (resolve_params("default"),
                                           {**THREE, "light_step": (4, 0.4)}, None),
    # the light step left to anti-lag alone (no history gain)
    "default without the gain, light step": (resolve_params("default", antilag_gain=False),
                                             {"light_step": (3, 0.3)}, None),
    "default+extras, moving edge": (resolve_params("default", **EXTRAS),
                                    {"moving_edge": True}, None),
    # Cycles at 1 spp (the header says pixel centres): the pixel filter, with every extra
    "default+extras, centre-sampled": (resolve_params("default", **EXTRAS),
                                       {"centre_sampled": True}, None),
    # one combined colour: a mixed signal, at mixed_sigma_luminance
    "default, combined": (resolve_params("default"), {"layout": "combined"}, None),
    # feedback from the second iteration (with the colour blur), half of it where pixels
    # move; the wall stands still, the objects move
    "falcor, moving feedback share": (resolve_params("falcor", moving_feedback_share=0.5),
                                      {"layout": "combined", "wall_speed": 0.0}, None),
}
WORST: dict[str, float] = {}


def _close(got: np.ndarray, want: np.ndarray, what: str, scale: float | None = None) -> float:
    """Asserts the tolerance; returns the largest error relative to the scale."""
    want = np.asarray(want, dtype=np.float64)
    scale = float(np.max(np.abs(want))) if scale is None else scale
    np.testing.assert_allclose(got, want, rtol=TOLERANCE, atol=TOLERANCE * scale, err_msg=what)
    return float(np.max(np.abs(got - want))) / scale if scale > 0 else 0.0


def _mode_bits(radiance_mode: np.ndarray, has_history: np.ndarray | None = None) -> np.ndarray:
    """The reference's (S, H, W) modes as the Denoiser's uint16 mask (bit s: signal s is
    filtered as radiance; the top bit: no history)."""
    bits = sum((radiance_mode[s].astype(np.uint16) << s) for s in range(len(radiance_mode)))
    bits = np.asarray(bits, dtype=np.uint16)
    if has_history is not None:
        bits = np.where(has_history, bits, NO_HISTORY).astype(np.uint16)
    return bits


def compare_frame(got: Any, want: ref.ReferenceOutput, denoiser: Denoiser,
                  reference: ref.ReferenceDenoiser, names: tuple[str, ...],
                  where: str) -> float:
    """Every compared quantity of one frame; returns the worst relative error."""
    worst = 0.0
    for index, name in enumerate(names):
        length, want_length = got.layers[f"history_length.{name}"], want.history_length[index]
        # A history length off by a fraction could move a pixel across the variance
        # threshold: whole counts must be exact, mixed ones within float32 rounding.
        whole = want_length == np.round(want_length)
        np.testing.assert_array_equal(length[whole], want_length[whole],
                                      err_msg=f"{where}: {name} history length")
        worst = max(worst, _close(length, want_length, f"{where}: {name} history length"))
        np.testing.assert_array_equal(got.layers[f"radiance_mode.{name}"],
                                      want.radiance_mode[index],
                                      err_msg=f"{where}: {name} modes")
        rgb = np.stack([got.layers[f"{name}.{c}"] for c in "RGB"])
        worst = max(worst, _close(rgb, want.radiance[name], f"{where}: {name} radiance"))
    assert reference.history is not None
    moments_scale = float(np.max(reference.history.moments[:, 1]))
    variance = np.stack([got.layers[f"variance.{name}"] for name in names])
    worst = max(worst, _close(variance, want.variance, f"{where}: variance before the a-trous",
                              moments_scale))
    worst = max(worst, _close(got.color, want.color, f"{where}: output colour"))
    state = denoiser.state()
    worst = max(worst, _close(state["history_illumination"], reference.history.illumination,
                              f"{where}: colour history"))
    worst = max(worst, _close(state["history_moments"], reference.history.moments,
                              f"{where}: moments"))
    np.testing.assert_array_equal(
        state["history_mode"],
        _mode_bits(reference.history.radiance_mode, reference.history.has_history),
        err_msg=f"{where}: history modes")
    assert got.counts == want.counts, where
    return worst


def _frames(scene: dict[str, Any], extreme_frame: int | None) -> list[Frame]:
    options = dict(scene)
    centre_sampled = bool(options.pop("centre_sampled", False))
    frames = [dataclasses.replace(f, centre_sampled=centre_sampled)
              for f in scene_sequence(6, **options)]
    if extreme_frame is not None:
        plant_extremes(frames[extreme_frame])
    return frames


def _compare_sequence(case: str) -> list[ref.ReferenceOutput]:
    params, scene, extreme_frame = CASES[case]
    frames = _frames(scene, extreme_frame)
    denoiser = Denoiser(params, debug_layers=True)
    reference = ref.ReferenceDenoiser(params)
    outputs = []
    worst = 0.0
    for t, frame in enumerate(frames):
        got = denoiser.process(frame)
        want = reference.process(frame)
        outputs.append(want)
        worst = max(worst, compare_frame(got, want, denoiser, reference, frame.names,
                                         f"frame {t}"))
    WORST[case] = worst
    if os.environ.get("SVGF_REFERENCE_REPORT"):
        print(f"\n{case}: worst error {worst:.2e} of the quantity's maximum")
    return outputs


@pytest.mark.parametrize("case", list(CASES))
def test_denoiser_matches_the_float64_reference(case: str) -> None:
    outputs = _compare_sequence(case)
    # The sequence exercises what it should: cold pixels after frame 0 (disocclusions), long
    # history elsewhere, and every frame has both short- and long-history variance.
    lengths = np.stack([out.history_length for out in outputs[1:]])
    params, scene, extreme_frame = CASES[case]
    # A light step everywhere may leave no full history past it: the longest reaches the
    # step's frame at least.
    longest = scene["light_step"][0] if params.antilag and "light_step" in scene else 6
    assert np.sum(lengths == 1.0) >= 10 and lengths.max() >= longest
    if params.antilag and "light_step" in scene:
        # The light change is seen: at that frame the history gain rescales many histories
        # (the light scaled by one factor everywhere), or without it anti-lag shortens them,
        # while before it (no change but the moving object) it stays nearly silent.
        step = scene["light_step"][0]
        seen = "history_gain" if params.antilag_gain else "antilag"
        assert outputs[step].counts[seen] > 100
        assert outputs[step - 1].counts[seen] < outputs[step].counts[seen] // 4
        if params.antilag_gain:  # rescaled, the longest histories run through the step
            assert outputs[step].history_length.max() > step
    if params.spread_fireflies > 0 and params.glossy_spread_fireflies and scene.get(
            "layout") == "three":  # the glossy signal's fireflies are spread (in its 3x3)
        assert sum(out.counts.get("fireflies_spread.glossy", 0) for out in outputs) >= 2
    if extreme_frame is not None:
        counts = outputs[extreme_frame].counts
        assert counts["nonfinite"] >= 12 and counts["extreme"] == 5
        # The frames after it are clean: nothing planted survives in the history.
        assert all(out.counts["nonfinite"] == out.counts["extreme"] == 0
                   for out in outputs[extreme_frame + 1:])
    if scene.get("layout") == "three" or scene.get("moving_edge"):
        # Pixels change mode from frame to frame on the same surface point: the moving
        # stripe rejects their history (a signal's history length restarts at 1 there).
        changed = sum(int(np.sum(np.any(a.radiance_mode != b.radiance_mode, axis=0)))
                      for a, b in zip(outputs, outputs[1:], strict=False))
        assert changed >= 20


def test_three_signals_keep_their_own_history_and_modes() -> None:
    """Guards the three-signal scene itself: each signal has pixels in both modes, a colour
    above 1.05 filtered as radiance, and the signals' history lengths part where one
    signal's mode changed and the others' did not."""
    frames = scene_sequence(5, **THREE)
    reference = ref.ReferenceDenoiser(resolve_params("paper"))
    outputs = [reference.process(frame) for frame in frames]
    surface = frames[-1].depth > 0
    modes = outputs[-1].radiance_mode
    for index in range(3):
        assert modes[index][surface].any() and (~modes[index][surface]).any()
    assert outputs[-1].counts["implausible_albedo.glossy"] >= 8
    parted = sum(int(np.sum(np.ptp(out.history_length, axis=0) > 0)) for out in outputs[1:])
    assert parted >= 20
    assert frames[0].luminance_weights == ACESCG_LUMINANCE


class _Poisoned:
    """Mixin: the anti-lag hook writes NaN into one pixel's reprojected moments on frame 2
    (standing in for a defective stage), so the history guard must reset that pixel."""

    PIXEL = (9, 18)
    frame = 0

    def poison(self, moments: np.ndarray) -> None:
        self.frame += 1
        if self.frame == 2:
            moments[:, :, self.PIXEL[0], self.PIXEL[1]] = np.nan


class PoisonStage(_Poisoned, StageBase):
    """A stage of one's own after the reprojection (the paper preset has no history clamp
    nor anti-lag): poisons the reprojected moments where there is a history."""

    name = "poison"

    def run(self, ctx: FrameContext) -> bool:
        if not ctx.reprojected or ctx.temporal is None:
            return False
        self.poison(ctx.temporal.history_moments)
        return True


def poisoned_denoiser(params: SVGFParams, debug_layers: bool = False) -> Denoiser:
    denoiser = Denoiser(params, debug_layers=debug_layers)
    denoiser.pipeline.insert_after("reproject", PoisonStage())
    return denoiser


class PoisonedReference(_Poisoned, ref.ReferenceDenoiser):
    def before_accumulation(self, temporal: ref.TemporalState) -> None:
        super().before_accumulation(temporal)
        self.poison(temporal.history.moments)


def test_history_guard_resets_a_poisoned_pixel_like_the_reference() -> None:
    """A non-finite value that reaches the history is reset after the frame (counted), and
    the frames after it match the reference, which resets the same pixel. Temporal stages
    only (no spatial variance, no a-trous), so the NaN stays on its pixel on that frame: the
    kernels assume finite values (fast-math) and their result there is undefined."""
    params = resolve_params("paper", atrous_iterations=0, variance_history_threshold=1)
    frames = scene_sequence(5, **THREE)
    denoiser = poisoned_denoiser(params, debug_layers=True)
    reference = PoisonedReference(params)
    y, x = _Poisoned.PIXEL
    assert frames[2].depth[y, x] > 0
    for t, frame in enumerate(frames):
        got = denoiser.process(frame)
        want = reference.process(frame)
        if t == 2:
            assert got.counts["history_resets"] == want.counts["history_resets"] == 1
            state = denoiser.state()
            assert state["history_mode"][y, x] == NO_HISTORY
            assert np.all(state["history_length"][:, y, x] == 0)
            assert all(np.isfinite(state[k]).all() for k in (
                "history_illumination", "history_moments", "history_length"))
            continue
        compare_frame(got, want, denoiser, reference, frame.names, f"frame {t}")


def _scene_reprojections(frames: list[Frame], depth_tolerance: float = 10.0,
                         normal_tolerance: float = 16.0) -> list[ref.Reprojected]:
    """The reference reprojection between consecutive frames, with a random history."""
    rng = np.random.default_rng(0)
    results = []
    for previous, current in zip(frames, frames[1:], strict=False):
        shape = previous.depth.shape
        g_prev = ref.geometry(previous.depth, previous.normal)
        g_cur = ref.geometry(current.depth, current.normal)
        modes = np.zeros((1, *shape), bool)
        history = ref.History(rng.random((1, 3, *shape)), rng.random((1, 2, *shape)),
                              np.ones((1, *shape)), modes, np.ones(shape, bool), g_prev.depth,
                              g_prev.unit_normal, previous.mesh_id)
        results.append(ref.reproject(current.motion, g_cur, current.mesh_id, modes, history,
                                     depth_tolerance, 0.002, normal_tolerance))
    return results


def test_the_scene_takes_every_reprojection_branch() -> None:
    """Guards the scene itself: bilinear, 3x3 fallback and rejected pixels, and each
    consistency test (depth, normal, mesh id) rejecting taps on its own."""
    frames = scene_sequence(6)
    base = _scene_reprojections(frames)
    surface = [f.depth > 0 for f in frames[1:]]
    counts = {name: sum(int(np.sum((r.path[0] == value) & s)) for r, s in zip(base, surface,
                                                                             strict=True))
              for name, value in (("bilinear", ref.BILINEAR), ("fallback", ref.FALLBACK),
                                  ("rejected", ref.REJECTED))}
    assert counts["bilinear"] > 1500 and counts["fallback"] >= 30 and counts["rejected"] >= 5
    # Switching one test off changes which taps are used (near the object's depth step and
    # normal crease the history length stays the same, so compare the resampled colour).
    one_id = scene_sequence(6)
    for frame in one_id:
        frame.mesh_id[frame.mesh_id > 0] = 1
    variants = {
        "depth": _scene_reprojections(frames, depth_tolerance=1e9),
        "normal": _scene_reprojections(frames, normal_tolerance=1e9),
        "mesh id": _scene_reprojections(one_id),
    }
    for test, loose in variants.items():
        changed = sum(int(np.sum(np.abs(a.illumination - b.illumination).max(axis=(0, 1))
                                 > 1e-9)) for a, b in zip(base, loose, strict=True))
        assert changed >= 4, test


def test_atrous_step_schedule_is_powers_of_two() -> None:
    assert ref.atrous_steps(5) == [1, 2, 4, 8, 16]


def test_plant_extremes_counts_what_it_plants() -> None:
    for layout in ("split", "combined", "three"):
        frame = scene_frame(2, layout=layout)
        planted = plant_extremes(frame)
        clean = ref.apply_value_policy(frame)
        assert {k: clean.counts[k] for k in planted} == planted, layout
