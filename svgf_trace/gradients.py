"""A-SVGF temporal gradient samples (Schied, Peters and Dachsbacher, HPG 2018).

For frame ``f`` against frame ``f - 1`` of the animation timeline:

1. In every 3x3 stratum of frame ``f - 1`` one pixel is picked by hashing (seed, ``f - 1``,
   stratum) (``kernels.stratum_pixels``; border strata are clipped to the image).
2. Its primary hit in frame ``f - 1`` (triangle and barycentrics) is the surface sample.
   The same point on the object in frame ``f`` is the same barycentrics on the triangle's
   frame-``f`` vertices (object transforms are affine).
3. The sample survives if that point lies in front of camera ``f``, projects inside the
   image, and is visible from camera ``f``: a ray from the eye towards it hits the same
   triangle (or, for coplanar neighbours, the same object within 2e-4 of the distance).
4. It is shaded twice with frame ``f - 1``'s random numbers for its pixel and every sample:
   in frame ``f - 1`` (exactly the path that frame's render traced: ``prev``) and on frame
   ``f``'s geometry, lights and emission from the moved point (``curr``). The view
   direction of the re-shaded ray is frame ``f - 1``'s primary direction plus the change in
   the direction from the eye to the point, so it is the same ray when nothing moved and the
   two shadings then agree bit for bit; any difference is a change of the scene, not noise.
5. The sample is written at the frame-``f`` pixel containing the projected point,
   ``(floor(x), floor(y))``; when several land on one pixel, the one from the first stratum
   (row-major order) is kept.

Layers (float32, ``(H, W)``; 0 where ``gradient.mask`` is 0): ``gradient.mask`` (1 where a
sample sits), and the Rec. 709 luminance of the sample's ``prev`` and ``curr`` radiance per
signal: ``direct`` and ``indirect`` (as in the frame's ``direct``/``indirect`` layers) and,
with lobe passes, ``diffuse`` and ``glossy`` (a lobe's radiance, Col x (Dir + Ind)). ``prev``
is the frame ``f - 1`` pixel's value as traced (mean of its ``spp`` samples, before any
half rounding).
"""

from __future__ import annotations

import numpy as np

from svgf_trace import kernels
from svgf_trace.animation import Animation
from svgf_trace.scene import Scene
from svgf_trace.tracing import (
    STREAM_GRADIENT,
    STREAM_INPUT,
    FrameGeometry,
    PathStarts,
    Radiance,
    TraceStats,
    frame_key,
    prepare_frame,
    trace_samples,
)

STRATUM = 3
# Relative distance within which a hit on another triangle of the same object counts as
# the sample itself (coplanar neighbours, e.g. the two triangles of a quad).
SAME_SURFACE_TOLERANCE = 2e-4
REC709 = np.array([0.2126, 0.7152, 0.0722])


def surface_points(tri_v: np.ndarray, prim: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """World points ``(n, 3)`` float64 at Embree barycentrics (clamped as the kernels do)."""
    b1 = np.clip(u.astype(np.float64), 0.0, 1.0)
    b2 = np.clip(v.astype(np.float64), 0.0, 1.0)
    total = b1 + b2
    over = total > 1.0
    b1 = np.where(over, b1 / np.where(over, total, 1.0), b1)
    b2 = np.where(over, b2 / np.where(over, total, 1.0), b2)
    b0 = 1.0 - b1 - b2
    tri = tri_v[prim]
    return b0[:, None] * tri[:, 0] + b1[:, None] * tri[:, 1] + b2[:, None] * tri[:, 2]


def _unit(vectors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    length = np.sqrt(np.einsum("ij,ij->i", vectors, vectors))
    return vectors / length[:, None], length


def _signals(radiance: Radiance) -> dict[str, np.ndarray]:
    """Luminance per signal name of each start's mean radiance, float32."""
    out = {
        "direct": radiance.direct @ REC709,
        "indirect": radiance.indirect @ REC709,
    }
    if radiance.lobes is not None:
        out["diffuse"] = (radiance.lobes[:, 0] + radiance.lobes[:, 1]) @ REC709
        out["glossy"] = (radiance.lobes[:, 2] + radiance.lobes[:, 3]) @ REC709
    return {name: value.astype(np.float32) for name, value in out.items()}


class GradientSamples:
    """The surviving samples of one frame pair, in stratum order (for tests and layers)."""

    def __init__(self, source_pixel: np.ndarray, target_pixel: np.ndarray,
                 position: np.ndarray, prev: dict[str, np.ndarray],
                 curr: dict[str, np.ndarray]) -> None:  # fmt: skip
        self.source_pixel = source_pixel  # linear pixel index in frame f - 1
        self.target_pixel = target_pixel  # linear pixel index in frame f
        self.position = position  # (n, 2) continuous pixel position in frame f
        self.prev = prev
        self.curr = curr


def gradient_samples(
    scene: Scene,
    animation: Animation,
    geo: FrameGeometry,
    *,
    spp: int,
    max_depth: int,
    seed: int,
    lobes: bool = False,
    threads: int = 1,
    stats: TraceStats | None = None,
) -> GradientSamples:
    """Steps 1-4 of the module docstring for frame ``geo.frame``, before collisions."""
    cam = geo.camera
    width, height = cam.width, cam.height
    frame = geo.frame
    prev_key = frame_key(seed, frame - 1, STREAM_INPUT)
    choice_key = frame_key(seed, frame - 1, STREAM_GRADIENT)
    source = kernels.stratum_pixels(choice_key, width, height, STRATUM)

    prev_geo = prepare_frame(scene, animation, frame - 1, width, height, threads=threads,
                             stats=stats)  # fmt: skip
    try:
        all_dirs, prev_eye = prev_geo.camera.primary_rays()
        prev_dirs = np.ascontiguousarray(all_dirs[source], dtype=np.float32)
        origins = np.ascontiguousarray(
            np.broadcast_to(prev_eye.astype(np.float32), prev_dirs.shape)
        )
        prim, u, v, t = prev_geo.tracer.intersect(origins, prev_dirs)
        hit = prim >= 0
        source, prim, u, v, t, prev_dirs = (a[hit] for a in (source, prim, u, v, t, prev_dirs))
        prev_points = surface_points(prev_geo.tri_v, prim, u, v)

        # The same surface points in frame f, and whether camera f sees them.
        points = surface_points(geo.tri_v, prim, u, v)
        eye = np.asarray(cam.position, dtype=np.float64)
        to_eye_dir, dist = _unit(points - eye)
        position = cam.project(points)
        inside = (
            (cam.view_depth(points) > 0.0)
            & (position[:, 0] >= 0.0)
            & (position[:, 0] < width)
            & (position[:, 1] >= 0.0)
            & (position[:, 1] < height)
        )
        ray_dirs = np.ascontiguousarray(to_eye_dir, dtype=np.float32)
        ray_orgs = np.ascontiguousarray(np.broadcast_to(eye.astype(np.float32), ray_dirs.shape))
        seen, _, _, seen_t = geo.tracer.intersect(ray_orgs, ray_dirs)
        same_object = (seen >= 0) & (geo.tri_obj[np.maximum(seen, 0)] == geo.tri_obj[prim])
        close = np.abs(seen_t.astype(np.float64) - dist) <= SAME_SURFACE_TOLERANCE * dist
        visible = (seen == prim) | (same_object & close)
        keep = inside & visible
        source, prim, u, v, t, prev_dirs, prev_points, points, dist, position = (
            a[keep]
            for a in (source, prim, u, v, t, prev_dirs, prev_points, points, dist, position)
        )
        stride = width * height
        prev = trace_samples(prev_geo, PathStarts(source, prim, u, v, t, prev_dirs, stride),
                             spp, max_depth, prev_key, lobes=lobes)  # fmt: skip
    finally:
        prev_geo.tracer.close()

    # Re-shade in frame f with frame f - 1's numbers: the previous primary direction, moved
    # by the change of the eye-to-point direction (zero when nothing moved).
    prev_unit, _ = _unit(prev_points - prev_eye)
    now_unit, _ = _unit(points - eye)
    curr_dirs = np.ascontiguousarray(prev_dirs.astype(np.float64) + (now_unit - prev_unit),
                                     dtype=np.float32)  # fmt: skip
    curr = trace_samples(
        geo, PathStarts(source, prim, u, v, dist.astype(np.float32), curr_dirs, stride),
        spp, max_depth, prev_key, lobes=lobes,
    )  # fmt: skip
    target = (np.floor(position[:, 1]).astype(np.int64) * width
              + np.floor(position[:, 0]).astype(np.int64))  # fmt: skip
    return GradientSamples(source, target, position, _signals(prev), _signals(curr))


def gradient_layers(
    scene: Scene,
    animation: Animation,
    geo: FrameGeometry,
    *,
    spp: int,
    max_depth: int,
    seed: int,
    lobes: bool = False,
    threads: int = 1,
    stats: TraceStats | None = None,
) -> dict[str, np.ndarray]:
    """The ``gradient.*`` layers of frame ``geo.frame`` (module docstring), ``(H, W)``."""
    samples = gradient_samples(scene, animation, geo, spp=spp, max_depth=max_depth, seed=seed,
                               lobes=lobes, threads=threads, stats=stats)  # fmt: skip
    width, height = geo.camera.width, geo.camera.height
    # Collisions: the first sample (stratum order) to land on a pixel keeps it.
    pixels, first = np.unique(samples.target_pixel, return_index=True)
    layers = {"mask": np.zeros(width * height, np.float32)}
    layers["mask"][pixels] = 1.0
    for name in samples.prev:
        for when, values in (("prev", samples.prev[name]), ("curr", samples.curr[name])):
            plane = np.zeros(width * height, np.float32)
            plane[pixels] = values[first]
            layers[f"{name}.{when}"] = plane
    return {name: plane.reshape(height, width) for name, plane in layers.items()}
