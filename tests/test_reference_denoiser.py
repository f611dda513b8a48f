"""The whole ``Denoiser`` against the float64 ``ReferenceDenoiser``, frame by frame.

Six frames of ``moving_scene`` (an object moving over a panning textured wall, a coplanar
sticker, background, black albedo, emission; 1-spp exponential noise; exact motion, depth,
normals and ids), for both presets, with every optional stage on, and once with inexact
sub-pixel motion. Each frame compares the history length (whole counts exactly: one off by
a rounding error would cross the variance threshold), the variance entering the a-trous,
each signal's filtered radiance, the output colour and the persistent history (colour,
moments).

Tolerance: ``|denoiser - reference| <= 2e-4 (|reference| + max |reference|)`` per frame and
quantity. The kernels run in float32 (relative rounding 6e-8 per operation) and the a-trous
weights use ``fast_exp`` (relative error < 4e-6) and ``fast_log2`` (absolute error < 1e-6 on
``log2 cos``, so up to 128 ln2 1e-6 = 9e-5 relative on ``w_n`` at sigma_n = 128); through five
iterations and six frames of feedback the measured worst case is 1.2e-5 relative to the
image maximum. 2e-4 leaves a 15x margin on that and still sits 50x below the smallest
effect of the planted bugs in ``tests/mutants/plant.py``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
import reference_svgf as ref
from moving_scene import scene_sequence

from svgf_cli.filters.denoiser import Denoiser
from svgf_cli.filters.params import SVGFParams, resolve_params

TOLERANCE = 2e-4
EXTRAS = {"firefly_clamp": 2.0, "history_clamp": 1.5, "taa": True}
# Inexact sub-pixel motion: bilinear weights round in float32 (history lengths are snapped to
# whole counts, so the variance threshold still sees the same h as the reference).
INEXACT_MOTION = {"wall_speed": 0.3, "object_velocity": (2.3, 0.6)}
CASES = {
    # name: (params, split direct/indirect or one combined signal, scene options)
    "paper": (resolve_params("paper"), True, {}),
    "falcor": (resolve_params("falcor"), False, {}),
    "paper+extras": (resolve_params("paper", spatial_variance_blur_color=True, **EXTRAS), True,
                     {}),
    "falcor+extras": (resolve_params("falcor", **EXTRAS), False, {}),
    "paper, inexact motion": (resolve_params("paper"), True, INEXACT_MOTION),
}


def _close(got: np.ndarray, want: np.ndarray, what: str, scale: float | None = None) -> None:
    want = np.asarray(want, dtype=np.float64)
    scale = float(np.max(np.abs(want))) if scale is None else scale
    np.testing.assert_allclose(got, want, rtol=TOLERANCE, atol=TOLERANCE * scale, err_msg=what)


def _compare_sequence(params: SVGFParams, split: bool,
                      scene: dict[str, Any]) -> list[ref.ReferenceOutput]:
    frames = scene_sequence(6, split=split, **scene)
    denoiser = Denoiser(params, debug_layers=True)
    reference = ref.ReferenceDenoiser(params)
    outputs = []
    for t, frame in enumerate(frames):
        got = denoiser.process(frame)
        want = reference.process(frame)
        outputs.append(want)
        names = [name for name, _ in frame.signals()]
        where = f"frame {t}"
        # A history length off by a fraction could move a pixel across the variance
        # threshold: whole counts must be exact, mixed ones within float32 rounding.
        whole = want.history_length == np.round(want.history_length)
        np.testing.assert_array_equal(got.layers["history_length"][whole],
                                      want.history_length[whole],
                                      err_msg=f"{where}: history length")
        _close(got.layers["history_length"], want.history_length, f"{where}: history length")
        assert reference.history is not None
        moments_scale = float(np.max(reference.history.moments[:, 1]))
        variance = np.stack([got.layers[f"variance.{name}"] for name in names])
        _close(variance, want.variance, f"{where}: variance before the a-trous", moments_scale)
        for name in names:
            rgb = np.stack([got.layers[f"{name}.{c}"] for c in "RGB"])
            _close(rgb, want.radiance[name], f"{where}: {name} radiance")
        _close(got.color, want.color, f"{where}: output colour")
        state = denoiser.state()
        _close(state["history_illumination"], reference.history.illumination,
               f"{where}: colour history")
        _close(state["history_moments"], reference.history.moments, f"{where}: moments")
    return outputs


@pytest.mark.parametrize("case", list(CASES))
def test_denoiser_matches_the_float64_reference(case: str) -> None:
    params, split, scene = CASES[case]
    outputs = _compare_sequence(params, split, scene)
    # The sequence exercises what it should: cold pixels after frame 0 (disocclusions), long
    # history elsewhere, and every frame has both short- and long-history variance.
    lengths = np.stack([out.history_length for out in outputs[1:]])
    assert np.sum(lengths == 1.0) >= 10 and lengths.max() == 6.0


def _scene_reprojections(frames: list, depth_tolerance: float = 10.0,
                         normal_tolerance: float = 16.0) -> list[ref.Reprojected]:
    """The reference reprojection between consecutive frames, with a random history."""
    rng = np.random.default_rng(0)
    results = []
    for previous, current in zip(frames, frames[1:], strict=False):
        shape = previous.depth.shape
        g_prev = ref.geometry(previous.depth, previous.normal, previous.albedo, 1e-3)
        g_cur = ref.geometry(current.depth, current.normal, current.albedo, 1e-3)
        history = ref.History(rng.random((1, 3, *shape)), rng.random((1, 2, *shape)),
                              np.ones(shape), g_prev.depth, g_prev.unit_normal,
                              previous.mesh_id)
        results.append(ref.reproject(current.motion, g_cur, current.mesh_id, history,
                                     depth_tolerance, 0.002, normal_tolerance))
    return results


def test_the_scene_takes_every_reprojection_branch() -> None:
    """Guards the scene itself: bilinear, 3x3 fallback and rejected pixels, and each
    consistency test (depth, normal, mesh id) rejecting taps on its own."""
    frames = scene_sequence(6)
    base = _scene_reprojections(frames)
    surface = [f.depth > 0 for f in frames[1:]]
    counts = {name: sum(int(np.sum((r.path == value) & s)) for r, s in zip(base, surface,
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
