"""The light groups' filter on 2x2 blocks (``filters.halfres``): the blocks' means, their
nearest surface, and the joint bilateral upsampling back, each against a float64 reference;
the layered filter on blocks still adds its groups up to the colour."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from synthetic import make_frame

from svgf_cli.filters import composable
from svgf_cli.filters.halfres import (
    DEPTH_TOLERANCE,
    FOREIGN_WEIGHT,
    block_means,
    halve_frame,
    upsample,
)
from svgf_cli.filters.params import resolve_params
from svgf_cli.frame import Frame, LightLayer, LightLayers


def _reference_means(planes: np.ndarray) -> np.ndarray:
    c, h, w = planes.shape
    out = np.zeros((c, (h + 1) // 2, (w + 1) // 2))
    for by in range(out.shape[1]):
        for bx in range(out.shape[2]):
            out[:, by, bx] = planes[:, 2 * by:2 * by + 2, 2 * bx:2 * bx + 2].astype(
                np.float64).mean(axis=(1, 2))
    return out


@pytest.mark.parametrize("shape", [(3, 8, 10), (2, 7, 9), (1, 1, 3)])
def test_block_means_match_a_float64_reference(shape: tuple[int, int, int]) -> None:
    planes = np.random.default_rng(1).random(shape, dtype=np.float32) * 4
    np.testing.assert_allclose(block_means(planes), _reference_means(planes), rtol=1e-6)


def _frame(height: int = 9, width: int = 11, seed: int = 0) -> Frame:
    rng = np.random.default_rng(seed)
    frame = make_frame(width, height, noise=0.3, seed=seed,
                       depth=rng.uniform(1.0, 5.0, (height, width)).astype(np.float32),
                       mesh_id=rng.integers(1, 4, (height, width)).astype(np.int32),
                       motion=rng.uniform(-2, 2, (2, height, width)).astype(np.float32))
    return dataclasses.replace(frame, samples_per_pixel=2)


def test_halve_frame_pools_light_and_takes_each_blocks_nearest_surface() -> None:
    frame = _frame()
    small = halve_frame(frame)
    h, w = frame.depth.shape
    assert small.depth.shape == ((h + 1) // 2, (w + 1) // 2)
    assert small.samples_per_pixel == 4 * frame.samples_per_pixel
    for signal, halved in zip(frame.signals, small.signals, strict=True):
        np.testing.assert_allclose(halved.radiance, _reference_means(signal.radiance),
                                   rtol=1e-5)
        np.testing.assert_allclose(halved.albedo, _reference_means(signal.albedo), rtol=1e-5)
    for by in range(small.depth.shape[0]):
        for bx in range(small.depth.shape[1]):
            block = frame.depth[2 * by:2 * by + 2, 2 * bx:2 * bx + 2]
            y, x = np.unravel_index(int(np.argmin(block)), block.shape)
            y, x = 2 * by + y, 2 * bx + x
            assert small.depth[by, bx] == frame.depth[y, x]
            assert small.mesh_id[by, bx] == frame.mesh_id[y, x]
            np.testing.assert_array_equal(small.normal[:, by, bx], frame.normal[:, y, x])
            np.testing.assert_array_equal(small.motion[:, by, bx], frame.motion[:, y, x] / 2)


def _reference_upsample(values: np.ndarray, small: Frame, full: Frame) -> np.ndarray:
    k, _, sh, sw = values.shape
    h, w = full.depth.shape
    out = np.zeros((k, 3, h, w))
    for y in range(h):
        fy = (y + 0.5) / 2 - 0.5
        y0 = min(max(int(np.floor(fy)), 0), sh - 1)
        y1, wy = min(y0 + 1, sh - 1), min(max(fy - y0, 0.0), 1.0)
        for x in range(w):
            fx = (x + 0.5) / 2 - 0.5
            x0 = min(max(int(np.floor(fx)), 0), sw - 1)
            x1, wx = min(x0 + 1, sw - 1), min(max(fx - x0, 0.0), 1.0)
            total, acc = 0.0, np.zeros((k, 3))
            for sy, vy in ((y0, 1 - wy), (y1, wy)):
                for sx, vx in ((x0, 1 - wx), (x1, wx)):
                    weight = vy * vx + 1e-6
                    z = float(full.depth[y, x])
                    if (small.mesh_id[sy, sx] != full.mesh_id[y, x]
                            or abs(float(small.depth[sy, sx]) - z) > DEPTH_TOLERANCE * z):
                        weight *= FOREIGN_WEIGHT
                    total += weight
                    acc += weight * values[:, :, sy, sx]
            out[:, :, y, x] = acc / total
    return out


def test_upsample_matches_a_float64_reference() -> None:
    full = _frame(10, 13, seed=4)
    small = halve_frame(full)
    values = np.random.default_rng(5).random((2, 3, *small.depth.shape), dtype=np.float32)
    np.testing.assert_allclose(upsample(values, small, full),
                               _reference_upsample(values, small, full), rtol=2e-5)


def test_upsample_keeps_each_surface_to_its_own_blocks() -> None:
    """Two objects side by side, the edge inside a block column: every pixel takes the
    value of the blocks that see its own object (within FOREIGN_WEIGHT), never a blend."""
    h, w = 8, 12
    ids = np.where(np.arange(w)[None, :] < 5, 1, 2).astype(np.int32).repeat(h, axis=0)
    depth = np.where(ids == 1, 2.0, 4.0).astype(np.float32)
    full = dataclasses.replace(make_frame(w, h), mesh_id=ids, depth=depth)
    small = halve_frame(full)
    values = np.where(small.mesh_id == 1, 1.0, 3.0).astype(np.float32)[None, None]
    values = np.repeat(values, 3, axis=1)
    up = upsample(values, small, full)[0, 0]
    expected = np.where(ids == 1, 1.0, 3.0)
    np.testing.assert_allclose(up, expected, atol=20 * FOREIGN_WEIGHT * 3)


def _layered_frame(height: int, width: int, seed: int) -> Frame:
    frame = make_frame(width, height, illumination=(0.8, 0.6, 0.4), noise=0.3, seed=seed)
    light = sum(s.radiance * s.albedo for s in frame.signals)
    rng = np.random.default_rng(seed)
    part = rng.uniform(0.2, 0.8, light.shape).astype(np.float32)
    groups = [LightLayer(("k.R", "k.G", "k.B"), light * part, light * part),
              LightLayer(("f.R", "f.G", "f.B"), light * (1 - part), light * (1 - part))]
    return dataclasses.replace(frame, light=LightLayers(groups=groups))


def test_layered_groups_on_blocks_add_up_to_the_colour(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(composable, "GROUP_BLOCKS_MIN_PIXELS", 0)
    denoiser = composable.LayeredDenoiser(resolve_params("default"))
    for seed in range(3):
        out = denoiser.process(_layered_frame(16, 22, seed))
        total = sum(np.stack([out.light[f"{g}.{c}"] for c in "RGB"]) for g in "kf")
        np.testing.assert_allclose(total, out.color, rtol=1e-3, atol=1e-6)
    history = denoiser.groups.resident.history
    assert history is not None and history["prev_depth"].shape == (8, 11)
    assert denoiser.layers.stage_seconds["group_blocks"] > 0.0  # -v prints the blocks' cost
