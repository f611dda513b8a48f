"""Scale invariance: denoising k * x gives k * denoise(x) (issue 10, item 5).

Every brightness-dependent constant of the filter is relative (the spatial variance's
luminance stop, the floor of the a-trous deviation), so a brighter or darker render of the
same scene is filtered the same way. Checked over several frames of a noisy, moving
sequence with emission, black (radiance-mode) pixels, background and a disocclusion, so
every stage (spatial variance, a-trous, reprojection, both modes) takes part.
"""

from __future__ import annotations

import functools

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from synthetic import make_frame, texture

from svgf_cli.filters.denoiser import Denoiser
from svgf_cli.filters.params import resolve_params
from svgf_cli.frame import Frame, Signal

F32 = np.float32
W, H, FRAMES = 30, 20, 5
HALF_EPSILON = 2.0**-11  # relative precision of a half-float output


def _sequence() -> list[Frame]:
    frames = []
    albedo = texture(W, H, seed=5)
    albedo[:, 12:16, 3:9] = 0.0  # black: filtered as radiance
    for i in range(FRAMES):
        depth = np.full((H, W), 6.0, F32)
        depth[:2] = 0.0  # background rows
        mesh = np.ones((H, W), np.int32)
        x0 = 4 + 3 * i  # a box moving right: disocclusions behind it every frame
        depth[6:11, x0:x0 + 5] = 3.0
        mesh[6:11, x0:x0 + 5] = 2
        motion = np.zeros((2, H, W), F32)
        motion[0] = -0.4
        motion[0, 6:11, x0:x0 + 5] = -3.0
        illumination = 0.5 + texture(W, H, seed=9, low=0.0, high=2.0)
        frames.append(make_frame(W, H, illumination=illumination, albedo=albedo, noise=0.6,
                                 noise_kind="exponential", seed=i, depth=depth, mesh_id=mesh,
                                 motion=motion, emission=(0.05, 0.0, 0.1)))
        frames[-1].signals[1].radiance[:, 12:16, 3:9] = 0.2  # a reflection on black paint
    return frames


def _scaled(frame: Frame, k: float) -> Frame:
    def s(plane: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(plane * F32(k), dtype=F32)

    return Frame(
        signals=[Signal(x.name, s(x.radiance), x.albedo) for x in frame.signals],
        albedo=frame.albedo, normal=frame.normal, depth=frame.depth, motion=frame.motion,
        mesh_id=frame.mesh_id, emission=None if frame.emission is None else s(frame.emission),
    )


def _run(frames: list[Frame], preset: str) -> list[np.ndarray]:
    denoiser = Denoiser(resolve_params(preset))
    return [denoiser.process(f).color.astype(np.float64) for f in frames]


@functools.cache
def _reference(preset: str) -> tuple[list[Frame], list[np.ndarray]]:
    frames = _sequence()
    return frames, _run(frames, preset)


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(exponent=st.floats(min_value=-3.0, max_value=3.0),
       preset=st.sampled_from(["paper", "falcor"]))
def test_scaling_the_input_scales_the_output(exponent: float, preset: str) -> None:
    k = 10.0**exponent
    frames, reference = _reference(preset)
    outputs = _run([_scaled(f, k) for f in frames], preset)
    for got, want in zip(outputs, reference, strict=True):
        expected = k * want
        # Within half-float precision of each pixel (plus a hair of the frame's level for
        # values near 0, where rounding in float32 sums dominates).
        tolerance = HALF_EPSILON * (np.abs(expected) + 1e-3 * np.abs(expected).mean())
        assert np.all(np.abs(got - expected) <= tolerance), (k, preset)
