"""The value policy inside the Denoiser: non-finite and extreme inputs, the history guard."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic import make_frame, translating_sequence

import svgf_cli.filters.stages.accumulate as denoiser_module  # the accumulate stage
from svgf_cli.filters.denoiser import Denoiser
from svgf_cli.filters.params import resolve_params
from svgf_cli.filters.values import VALUE_LIMIT, count_geometry, reset_nonfinite_history
from svgf_cli.frame import count_warnings

F32 = np.float32


def test_one_extreme_value_does_not_blacken_the_rest_of_the_shot() -> None:
    """Issue 11: 1e20 in 40 pixels of one frame made every later frame 100% black."""
    frames = translating_sequence(10, 40, 24, velocity=(0.5, 0.0), noise=0.15, seed=3)
    clean = Denoiser(resolve_params("paper"))
    dirty = Denoiser(resolve_params("paper"))
    blown = [f for f in frames]
    hot = frames[3].signal("direct").radiance
    hot[:, 8:12, 10:20] = 1e20  # 40 pixels, every channel
    clean_frames = translating_sequence(10, 40, 24, velocity=(0.5, 0.0), noise=0.15, seed=3)
    for index, (a, b) in enumerate(zip(clean_frames, blown, strict=True)):
        want = clean.process(a)
        got = dirty.process(b)
        assert np.all(np.isfinite(got.color))
        if index == 3:
            assert got.counts["extreme"] == 120
            assert got.counts["extreme.radiance.direct"] == 120
            assert "120 input value(s) beyond +-1e15 replaced by 0" in got.warnings()[0]
        if index >= 5:
            # The bad frame counted as black there; later frames recover like any history.
            assert float(np.abs(got.color - want.color).mean()) < 0.01 * float(want.color.mean())
    assert got.counts["extreme"] == 0 and got.warnings() == []
    assert float(np.abs(got.color - want.color).max()) < 0.2 * float(want.color.max())


def test_non_finite_inputs_are_cleaned_and_counted_per_plane() -> None:
    h, w = 12, 16
    frames = [make_frame(w, h, noise=0.2, seed=i, emission=(0.1, 0.1, 0.1)) for i in range(4)]
    bad = frames[1]
    bad.signal("direct").radiance[0, 2, 3] = np.nan
    bad.signal("indirect").radiance[1, 4, 5] = -np.inf
    bad.albedo[2, 6, 6] = np.nan  # shared by both signals: counted for each
    assert bad.emission is not None
    bad.emission[0, 1, 1] = np.inf
    bad.emission[1, 1, 2] = 3e16
    bad.depth[7, 7] = np.nan
    bad.normal[:, 8, 8] = (np.inf, 0.0, 1.0)
    bad.motion[0, 9, 9] = np.nan
    denoiser = Denoiser(resolve_params("paper"), debug_layers=True)
    outputs = [denoiser.process(f) for f in frames]
    counts = outputs[1].counts
    assert counts["nonfinite.radiance.direct"] == 1
    assert counts["nonfinite.radiance.indirect"] == 1
    assert counts["nonfinite.albedo.direct"] == counts["nonfinite.albedo.indirect"] == 1
    assert counts["nonfinite.emission"] == 1 and counts["extreme.emission"] == 1
    assert counts["nonfinite.depth"] == counts["nonfinite.normal"] == 1
    assert counts["nonfinite.motion"] == 1
    assert counts["nonfinite"] == 8 and counts["extreme"] == 1
    for out in outputs:
        assert np.all(np.isfinite(out.color))
        for layer in out.layers.values():
            assert np.all(np.isfinite(layer))
    # The NaN depth is background that frame (its radiance passes through, cleaned) and
    # the NaN motion means no history there.
    assert outputs[1].layers["history_length.direct"][7, 7] == 0.0
    assert outputs[1].layers["history_length.direct"][9, 9] == 1.0
    assert outputs[2].counts["nonfinite"] == 0
    # The caller's planes are never modified.
    assert np.isnan(bad.depth[7, 7]) and np.isnan(bad.signal("direct").radiance[0, 2, 3])


def test_a_stage_that_produces_a_nan_resets_only_that_history(monkeypatch) -> None:
    frames = translating_sequence(5, 24, 16, velocity=(0.0, 0.0), noise=0.1, seed=1)
    real = denoiser_module.accumulate_in_place

    def poisoned(illumination, accumulated, *args):  # noqa: ANN001, ANN202
        real(illumination, accumulated, *args)
        if poisoned.armed:
            accumulated[1, :, 5, 7] = np.nan  # signal "indirect", one pixel
            poisoned.armed = False

    poisoned.armed = False
    monkeypatch.setattr(denoiser_module, "accumulate_in_place", poisoned)
    params = resolve_params("paper", feedback_iteration=-1)  # the accumulation is the history
    denoiser = Denoiser(params, debug_layers=True)
    denoiser.process(frames[0])
    denoiser.process(frames[1])
    poisoned.armed = True
    out = denoiser.process(frames[2])
    assert out.counts["history_resets"] == 1  # one pixel, both signals
    assert "1 pixel history(ies) reset" in " ".join(out.warnings())
    state = denoiser.state()
    assert all(np.all(np.isfinite(state[k])) for k in
               ("history_illumination", "history_moments", "history_length"))
    assert np.all(state["history_length"][:, 5, 7] == 0.0)
    assert state["history_mode"][5, 7] == 1 << 15 and state["history_length"][0, 5, 8] > 0.0
    later = denoiser.process(frames[3])
    assert np.all(np.isfinite(later.color)) and later.counts["history_resets"] == 0
    # The reset pixel itself is never resampled (its mode matches nothing): the paper's 3x3
    # fallback rebuilds it from its neighbours' history, not from zeros.
    assert later.layers["history_length.indirect"][5, 7] == 4.0
    indirect = later.layers["indirect.G"]
    assert abs(indirect[5, 7] / indirect[4:7, 6:9].mean() - 1.0) < 0.1


def test_reset_nonfinite_history_and_geometry_counts() -> None:
    illumination = np.ones((2, 3, 4, 5), F32)
    moments = np.ones((2, 2, 4, 5), F32)
    length = np.full((2, 4, 5), 3.0, F32)
    mode = np.ones((4, 5), np.uint16)
    assert reset_nonfinite_history(illumination, moments, length, mode) == 0
    moments[0, 1, 2, 2] = np.inf
    length[1, 3, 4] = np.nan
    assert reset_nonfinite_history(illumination, moments, length, mode) == 2
    assert np.all(length[:, 2, 2] == 0.0) and np.all(length[:, 3, 4] == 0.0)
    assert length[1, 2, 3] == 3.0
    assert mode[2, 2] == mode[3, 4] == 1 << 15 and mode.sum() == 2 * (1 << 15) + 18
    assert np.all(illumination[0, :, 2, 2] == 0.0) and np.all(moments[0, :, 2, 2] == 0.0)
    depth = np.ones((4, 5), F32)
    normal = np.ones((3, 4, 5), F32)
    motion = np.zeros((2, 4, 5), F32)
    depth[0, 0] = np.inf
    depth[1, 1] = 2e15
    normal[1, 3, 3] = -np.nan
    motion[1, 2, 0] = 1e30
    assert count_geometry(depth, normal, motion) == {
        "depth": (1, 1), "normal": (1, 0), "motion": (0, 1)
    }
    assert F32(1e15) == VALUE_LIMIT


def test_count_warnings_name_the_problem() -> None:
    assert count_warnings({"nonfinite": 0, "extreme": 0, "history_resets": 0,
                           "radiance_mode.direct": 400}) == []
    lines = count_warnings({"nonfinite": 3, "nonfinite.depth": 1, "nonfinite.radiance.direct": 2,
                            "extreme": 0, "clamped.direct": 4, "history_resets": 0})
    assert lines == [
        "3 non-finite input value(s) cleaned (depth 1, radiance.direct 2)",
        "signal direct: 4 demodulated value(s) clamped to +-1e15",
    ]


@pytest.mark.parametrize("scale", [1e-3, 1e3])
def test_extreme_but_legal_values_stay_within_float32(scale: float) -> None:
    """Values just under the limit over a tiny albedo: every intermediate stays finite."""
    h, w = 10, 12
    albedo = np.full((3, h, w), 1e-3, F32)
    frames = [make_frame(w, h, illumination=9e14 * scale / 1e3, albedo=albedo, noise=0.0,
                         seed=i) for i in range(3)]
    for f in frames:
        for s in f.signals:
            s.radiance[:, ::2, ::3] *= F32(1000.0)  # up to ~9e14 * scale, checkerboarded
    denoiser = Denoiser(resolve_params("falcor"), debug_layers=True)
    for f in frames:
        out = denoiser.process(f)
        assert np.all(np.isfinite(out.color))
        assert all(np.all(np.isfinite(v)) for v in out.layers.values())
    assert out.counts["history_resets"] == 0
