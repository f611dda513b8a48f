"""Jittered frames (``filters.jitter``) and the TAA the default preset gives them
(``taa_jittered``): a plane's inverse depth off the line of its pixel centres tells a
jittered frame, and only such a frame, not one whose header says centre-sampled, is
anti-aliased at its outlines."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import reference_svgf as ref

from svgf_cli.filters.denoiser import Denoiser
from svgf_cli.filters.jitter import MIN_TRIPLES, jittered_samples, plane_triples
from svgf_cli.filters.params import resolve_params
from svgf_cli.filters.taa import on_outline
from svgf_cli.io.exr import fix_signal_set, read_frame
from svgf_cli.io.layers import build_mapping

F32 = np.float32
ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "testdata"


def _plane(height: int, width: int, jitter: float, seed: int = 0) -> tuple[np.ndarray, ...]:
    """A slanted plane seen through each pixel's centre, or through a point up to
    ``jitter`` pixels from it: inverse depth affine in the sample's position."""
    rng = np.random.default_rng(seed)
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float64)
    xs += rng.uniform(-jitter, jitter, xs.shape)
    ys += rng.uniform(-jitter, jitter, ys.shape)
    depth = (1.0 / (0.2 + 0.004 * xs + 0.01 * ys)).astype(F32)
    normal = np.zeros((3, height, width), dtype=F32)
    normal[1] = 1.0
    return depth, normal, np.ones((height, width), dtype=np.int32)


def test_a_plane_through_pixel_centres_is_on_its_line() -> None:
    depth, normal, mesh = _plane(24, 32, 0.0)
    tested, jittered = plane_triples(depth, normal, mesh)
    assert tested == 6 * (30 + 32)  # rows 1, 5, ..., 21: their row and column triples
    assert jittered == 0 and not jittered_samples(depth, normal, mesh)


def test_a_plane_through_jittered_samples_is_off_its_line() -> None:
    depth, normal, mesh = _plane(24, 32, 0.5)
    tested, jittered = plane_triples(depth, normal, mesh)
    assert tested > 300 and jittered > 0.85 * tested
    assert jittered_samples(depth, normal, mesh)
    # A tenth of a pixel of jitter is still far off the line (the test's ratio is 0.1).
    assert jittered_samples(*_plane(24, 32, 0.1, seed=1))


def test_what_is_not_a_slanted_plane_is_not_tested() -> None:
    """A plane facing the camera (no slope), pixels of two objects, two normals and the
    background are no triples; too few triples are not enough to call a frame jittered."""
    depth, normal, mesh = _plane(24, 32, 0.5)
    assert plane_triples(np.full_like(depth, 3.0), normal, mesh) == (0, 0)
    checker = (np.indices(mesh.shape).sum(axis=0) % 2).astype(np.int32)
    assert plane_triples(depth, normal, checker)[0] == 0
    tilted = normal.copy()
    tilted[0][checker == 1] = 0.5
    assert plane_triples(depth, tilted, mesh)[0] == 0
    assert plane_triples(np.zeros_like(depth), normal, mesh) == (0, 0)
    small = tuple(a[..., :3, :12] for a in _plane(24, 32, 0.5))
    tested, jittered = plane_triples(*small)
    assert 0 < tested < MIN_TRIPLES and jittered > 0.5 * tested
    assert not jittered_samples(*small)


def _frames(folder: str, aovs: str, count: int = 3) -> list:
    mapping, _ = fix_signal_set(DATA / folder / "in.0001.exr", build_mapping(aovs))
    return [read_frame(DATA / folder / f"in.{f:04d}.exr", mapping).frame
            for f in range(1, count + 1)]


def _gbuffer(frame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    depth = np.where(np.isfinite(frame.depth) & (frame.depth < 1e9), frame.depth, 0.0)
    return (depth.astype(F32), np.ascontiguousarray(frame.normal, dtype=F32),
            frame.mesh_id)


@pytest.mark.parametrize(("folder", "aovs", "jittered"), [
    ("seq_jit", "svgf", True),  # svgf trace --jitter
    ("cycles/offset/roll", "cycles", True),  # Cycles with a sample offset
    ("seq", "svgf", False),  # svgf trace: pixel centres
    ("cycles/roll", "cycles", False),  # Cycles at 1 spp: its first sample's centre
    ("cycles/roll4", "cycles", False),  # at 4 spp the G-buffer is still sample 0's
    ("cycles/dof", "cycles", True),  # the lens moves the rays (its header says centre)
])
def test_the_bundled_frames_are_told_apart(folder: str, aovs: str, jittered: bool) -> None:
    frame = _frames(folder, aovs, 1)[0]
    tested, off = plane_triples(*_gbuffer(frame))
    assert tested > 500
    assert jittered_samples(*_gbuffer(frame)) == jittered
    # (roll4: 1 of 5894, a normal averaged over 4 samples where a crease is near)
    assert (off > 0.9 * tested) if jittered else (off < 0.001 * tested)


def test_plane_triples_match_the_float64_reference() -> None:
    for folder, aovs in (("seq_jit", "svgf"), ("cycles/roll", "cycles")):
        depth, normal, mesh = (a[..., 10:50, 20:90] for a in _gbuffer(_frames(folder, aovs,
                                                                               1)[0]))
        depth, normal, mesh = (np.ascontiguousarray(a) for a in (depth, normal, mesh))
        assert plane_triples(depth, normal, mesh) == ref.plane_triples(depth, normal, mesh)
        assert jittered_samples(depth, normal, mesh) == ref.jittered_samples(depth, normal,
                                                                             mesh)


def _outputs(params, frames) -> list[np.ndarray]:
    denoiser = Denoiser(params)
    return [denoiser.process(f).color.copy() for f in frames]


def test_the_default_anti_aliases_the_outlines_of_jittered_frames_only() -> None:
    """seq_jit: TAA's blend at the outlines, from the second frame on, nowhere else; its
    outlines change less from frame to frame. seq (pixel centres): no TAA, bit for bit."""
    params = resolve_params("default")
    frames = _frames("seq_jit", "svgf", 6)
    on, off = _outputs(params, frames), _outputs(params.replace(taa_jittered=False), frames)
    np.testing.assert_array_equal(on[0], off[0])
    # Without the noisy outlines' exchanges after it (which carry TAA's change a pixel on).
    alone = params.replace(noisy_outline_weight=0.0)
    on_alone = _outputs(alone, frames)
    off_alone = _outputs(alone.replace(taa_jittered=False), frames)
    for frame, a, b in zip(frames[1:], on_alone[1:], off_alone[1:], strict=True):
        depth = _gbuffer(frame)[0]
        outline = np.array([[depth[y, x] > 0 and on_outline(depth, y, x)
                             for x in range(depth.shape[1])] for y in range(depth.shape[0])])
        changed = np.any(a != b, axis=0)
        assert changed.any() and not changed[~outline].any()

    def flicker(outs: list[np.ndarray]) -> float:  # on the last frame's outlines
        return float(np.mean([np.abs(x - y)[:, outline].mean()
                              for x, y in zip(outs[2:], outs[1:], strict=False)]))

    assert flicker(on) < 0.85 * flicker(off)
    plain = _frames("seq", "svgf", 3)
    assert all(np.array_equal(a, b) for a, b in zip(
        _outputs(params, plain), _outputs(params.replace(taa_jittered=False), plain),
        strict=True))


def test_a_centre_sampled_header_wins_over_a_jittered_looking_g_buffer() -> None:
    """cycles/dof: the lens jitters the G-buffer, but Cycles says its sample went through
    the pixel centre: no TAA. Without the header's word the G-buffer decides."""
    params = resolve_params("default")
    frames = _frames("cycles/dof", "cycles", 3)
    assert all(f.centre_sampled for f in frames)
    on, off = _outputs(params, frames), _outputs(params.replace(taa_jittered=False), frames)
    assert all(np.array_equal(a, b) for a, b in zip(on, off, strict=True))
    unsaid = [dataclasses.replace(f, centre_sampled=False) for f in frames]
    assert not np.array_equal(_outputs(params, unsaid)[2],
                              _outputs(params.replace(taa_jittered=False), unsaid)[2])


@pytest.mark.parametrize("shape", [(1, 1), (2, 5), (3, 2), (5, 1)])
def test_tiny_frames_have_few_triples_and_are_not_jittered(shape: tuple[int, int]) -> None:
    depth, normal, mesh = _plane(*shape, 0.5)
    tested, jittered = plane_triples(depth, normal, mesh)
    assert 0 <= jittered <= tested <= 2 * shape[0] * shape[1]
    assert (tested, jittered) == ref.plane_triples(depth, normal, mesh)
    assert not jittered_samples(depth, normal, mesh)
