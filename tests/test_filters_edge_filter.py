"""The pixel filter across outlines (``filters.edge_filter``, stage ``edge_filter``)."""

from __future__ import annotations

import numpy as np
import pytest
import reference_svgf as ref
from synthetic import make_frame

from svgf_cli.filters.denoiser import Denoiser
from svgf_cli.filters.edge_filter import edge_filter, edge_filter_weight
from svgf_cli.filters.params import AUTO_PIXEL_FILTER, PRESETS
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
    edge_filter(colour, mesh, depth, F32(weight), out)
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
    edge_filter(colour, mesh, depth, F32(0.25), out)
    np.testing.assert_allclose(out.sum(axis=(1, 2)), colour.sum(axis=(1, 2)), rtol=1e-5)


def test_auto_is_for_centre_sampled_frames_only() -> None:
    assert edge_filter_weight(AUTO_PIXEL_FILTER, True) == 0.05
    assert edge_filter_weight(AUTO_PIXEL_FILTER, False) == 0.0
    assert edge_filter_weight(0.1, False) == 0.1
    assert "edge_filter" in stage_names(PRESETS["default"])
    assert "edge_filter" not in stage_names(PRESETS["paper"])


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
