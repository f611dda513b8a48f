"""One frame: its G-buffer layers, noisy radiance, optional A-SVGF gradient samples and its
reference, put together from the wavefront integrator in ``svgf_trace.tracing`` (see there
for how a frame is traced and seeded) and ``svgf_trace.gradients``.

The integrator's functions and types are re-exported here, the names this module has always
offered; its tuning constants (``MAX_PATHS_PER_BATCH``, ``MIN_RAYS_PER_THREAD``,
``RR_DEPTH``) live in ``svgf_trace.tracing`` only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from svgf_trace.animation import Animation
from svgf_trace.camera import Camera
from svgf_trace.gradients import gradient_layers
from svgf_trace.scene import Scene
from svgf_trace.tracing import (
    STREAM_GRADIENT,
    STREAM_INPUT,
    STREAM_JITTER,
    STREAM_REFERENCE,
    EmbreeTracer,
    FrameGeometry,
    MaterialArrays,
    PathStarts,
    PrimaryHits,
    Radiance,
    TraceStats,
    frame_camera,
    frame_key,
    gbuffer,
    pack_materials,
    prepare_frame,
    trace_batch,
    trace_primary,
    trace_samples,
    triangle_emission,
    world_vertices,
)

__all__ = [
    "STREAM_GRADIENT",
    "STREAM_INPUT",
    "STREAM_JITTER",
    "STREAM_REFERENCE",
    "EmbreeTracer",
    "FrameGeometry",
    "FrameResult",
    "MaterialArrays",
    "PathStarts",
    "PrimaryHits",
    "Radiance",
    "TraceStats",
    "frame_camera",
    "frame_key",
    "gbuffer",
    "pack_materials",
    "prepare_frame",
    "render_frame",
    "trace_batch",
    "trace_primary",
    "trace_samples",
    "triangle_emission",
    "world_vertices",
]


@dataclass
class FrameResult:
    """Everything written for one frame."""

    layers: dict[str, np.ndarray]  # G-buffer (H, W[, k]) float32
    direct: np.ndarray  # (H, W, 3) float32
    indirect: np.ndarray
    camera: Camera
    prev_camera: Camera
    lobes: np.ndarray | None = None  # (H, W, 4, 3) float32 lobe radiance (Radiance.lobes)
    gradient: dict[str, np.ndarray] | None = None  # (H, W) float32 planes, gradients module


def render_frame(
    scene: Scene,
    animation: Animation,
    frame: int,
    width: int,
    height: int,
    spp: int,
    max_depth: int,
    seed: int,
    *,
    reference_spp: int = 0,
    threads: int = 1,
    stats: TraceStats | None = None,
    lobes: bool = False,
    motion_next: bool = False,
    gradient_samples: bool = False,
    reference_supersample: int = 1,
    jitter: bool = False,
) -> tuple[FrameResult, FrameResult | None]:
    """Render one frame (and its reference when ``reference_spp`` > 0).

    ``jitter``: the input's primary ray (and so its G-buffer and its samples) goes through a
    uniformly random position in each pixel, a new one every frame (:func:`pixel_jitter`),
    as Mitsuba's and most renderers' one-sample frames do, instead of the pixel centre; the
    reference then wants ``reference_supersample`` > 1 (its hits are the input's otherwise).

    ``reference_supersample`` k > 1: the reference averages a k x k grid of positions in
    each pixel (a box pixel filter; ``reference_spp / k^2`` samples each, at least 1)
    instead of the pixel centre the input samples, as a production renderer's converged
    frame averages its pixel filter's footprint.

    ``lobes``: also the per-lobe light passes and colours; ``motion_next``: the motion to
    frame + 1; ``gradient_samples``: A-SVGF temporal gradient samples against frame - 1
    (``svgf_trace.gradients``).
    """
    geo = prepare_frame(scene, animation, frame, width, height, threads=threads, stats=stats)
    try:
        hits = trace_primary(geo, pixel_jitter(seed, frame, width, height) if jitter else None)
        next_frame = None
        if motion_next:
            next_v, _ = world_vertices(scene, animation, frame + 1)
            next_frame = (next_v, frame_camera(scene, animation, frame + 1, width, height))
        layers = gbuffer(geo, hits, lobe_colours=lobes, next_frame=next_frame)
        key = frame_key(seed, frame, STREAM_INPUT)
        radiance = trace_samples(geo, hits, spp, max_depth, key, lobes=lobes)
        gradient = None
        if gradient_samples:
            gradient = gradient_layers(
                scene, animation, geo, spp=spp, max_depth=max_depth, seed=seed, lobes=lobes,
                threads=threads, stats=stats,
            )  # fmt: skip
        result = FrameResult(
            layers=layers,
            direct=radiance.direct.reshape(height, width, 3).astype(np.float32),
            indirect=radiance.indirect.reshape(height, width, 3).astype(np.float32),
            camera=geo.camera,
            prev_camera=geo.prev_camera,
            lobes=None
            if radiance.lobes is None
            else radiance.lobes.reshape(height, width, 4, 3).astype(np.float32),
            gradient=gradient,
        )
        reference = None
        if reference_spp > 0:
            direct, indirect = _reference(scene, animation, frame, geo, hits, reference_spp,
                                          max_depth, seed, reference_supersample, threads,
                                          stats)
            reference = FrameResult(
                layers={}, direct=direct, indirect=indirect, camera=geo.camera,
                prev_camera=geo.prev_camera,
            )
    finally:
        geo.tracer.close()
    return result, reference


def pixel_jitter(seed: int, frame: int, width: int, height: int) -> np.ndarray:
    """The input's sample position in each pixel of ``frame``, (H, W, 2) float64 in [0, 1)
    from the pixel's top-left corner (x, y): uniform (a box pixel filter), from the frame's
    own random stream."""
    return np.random.default_rng(int(frame_key(seed, frame, STREAM_JITTER))).random(
        (height, width, 2))


def _reference(
    scene: Scene, animation: Animation, frame: int, geo: FrameGeometry, hits: PrimaryHits,
    spp: int, max_depth: int, seed: int, supersample: int, threads: int,
    stats: TraceStats | None,
) -> tuple[np.ndarray, np.ndarray]:
    """The reference's direct and indirect radiance, (H, W, 3) float32: ``spp`` samples from
    the input's pixel-centre hits, or with ``supersample`` k > 1 the mean over a k x k grid
    of sub-pixel positions (the frame traced at k times the resolution, ``ceil(spp / k^2)``
    samples each, box-filtered down)."""
    height, width = geo.camera.height, geo.camera.width
    key = frame_key(seed, frame, STREAM_REFERENCE)
    if supersample <= 1:
        ref = trace_samples(geo, hits, spp, max_depth, key)
        return (ref.direct.reshape(height, width, 3).astype(np.float32),
                ref.indirect.reshape(height, width, 3).astype(np.float32))
    k = supersample
    fine = prepare_frame(scene, animation, frame, width * k, height * k, threads=threads,
                         stats=stats)
    try:
        ref = trace_samples(fine, trace_primary(fine), -(-spp // (k * k)), max_depth, key)
    finally:
        fine.tracer.close()

    def box(plane: np.ndarray) -> np.ndarray:
        return plane.reshape(height, k, width, k, 3).mean(axis=(1, 3)).astype(np.float32)

    return box(ref.direct), box(ref.indirect)
