"""The wavefront integrator and the G-buffer: what a frame's render and its A-SVGF gradient
samples (``svgf_trace.gradients``) both trace with; ``svgf_trace.render`` puts a frame together.

A frame is rendered as: build the world-space geometry for the frame (rigid object
transforms applied) and one Embree scene; intersect all primary rays once (through pixel
centres, shared by every sample); then, per batch of samples, bounce by bounce: shade every
active path (numba), trace all shadow rays (Embree OCCLUDED), trace all continuation rays
(Embree INTERSECT), compact. Embree calls are split across threads (embreex releases the GIL).

Seeds: the frame key is ``SeedSequence([seed, frame, stream])`` (stream 0 for the noisy
input, 1 for the reference, so the reference's samples are independent of the input's, 2
for the choice of gradient-sample pixels); each path's numbers come from hashing (frame
key, sample index, pixel, dimension).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import partial
from typing import NamedTuple

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from svgf_trace import bsdf, kernels
from svgf_trace.animation import Animation
from svgf_trace.camera import Camera, default_camera
from svgf_trace.scene import Scene

RR_DEPTH = 3
# Paths in flight per batch: bounds memory (about 200 bytes per path) for references.
MAX_PATHS_PER_BATCH = 1 << 20
# Below this many rays one Embree call beats splitting across threads.
MIN_RAYS_PER_THREAD = 16384

STREAM_INPUT = 0
STREAM_REFERENCE = 1
STREAM_GRADIENT = 2
STREAM_JITTER = 3


@dataclass
class TraceStats:
    """Counters for the benchmark: rays traced and wall time inside Embree calls."""

    rays: int = 0
    embree_seconds: float = 0.0
    build_seconds: float = 0.0


@dataclass
class EmbreeTracer:
    """One committed Embree scene of triangle soup; primID is the triangle index."""

    vertices: np.ndarray  # (T, 3, 3) float64 world space
    threads: int = 1
    stats: TraceStats = field(default_factory=TraceStats)

    def __post_init__(self) -> None:
        start = time.perf_counter()
        self._scene = rtcore_scene.EmbreeScene()
        flat = np.ascontiguousarray(self.vertices.reshape(-1, 3), dtype=np.float32)
        indices = np.arange(flat.shape[0], dtype=np.int32).reshape(-1, 3)
        self._mesh = TriangleMesh(self._scene, flat, indices)
        # The first query commits the scene; do it here, single-threaded, so concurrent
        # queries never race on the commit.
        self._scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32))
        self.stats.build_seconds += time.perf_counter() - start
        self._pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None

    def map_rows(self, n: int, work: Callable[[slice], object]) -> list:
        """Run ``work`` over row ranges covering ``range(n)``, on the pool when worthwhile."""
        chunks = self._chunks(n)
        if self._pool is None or len(chunks) == 1:
            return [work(c) for c in chunks]
        return list(self._pool.map(work, chunks))

    def _chunks(self, n: int) -> list[slice]:
        parts = min(self.threads, max(1, n // MIN_RAYS_PER_THREAD))
        bounds = np.linspace(0, n, parts + 1).astype(int)
        return [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]

    def intersect(
        self, origins: np.ndarray, directions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Closest hits: (primID (-1 = miss), u, v, t) for float32 ``(n, 3)`` rays."""
        n = origins.shape[0]
        start = time.perf_counter()
        chunks = self._chunks(n)

        def run(part: slice) -> dict[str, np.ndarray]:
            return self._scene.run(origins[part], directions[part], output=1)

        if self._pool is None or len(chunks) == 1:
            results = [run(c) for c in chunks]
        else:
            results = list(self._pool.map(run, chunks))
        self.stats.embree_seconds += time.perf_counter() - start
        self.stats.rays += n
        if len(results) == 1:
            r = results[0]
            return r["primID"], r["u"], r["v"], r["tfar"]
        return tuple(  # type: ignore[return-value]
            np.concatenate([r[k] for r in results]) for k in ("primID", "u", "v", "tfar")
        )

    def occluded(
        self, origins: np.ndarray, directions: np.ndarray, dists: np.ndarray
    ) -> np.ndarray:
        """True where something lies between the origin and ``dists`` along the ray."""
        n = origins.shape[0]
        if n == 0:
            return np.zeros(0, dtype=bool)
        start = time.perf_counter()
        chunks = self._chunks(n)

        def run(part: slice) -> np.ndarray:
            # embreex writes into the dists array it is given: hand it a private copy.
            tfar = np.array(dists[part], dtype=np.float32)
            return self._scene.run(origins[part], directions[part], dists=tfar, query="OCCLUDED")

        if self._pool is None or len(chunks) == 1:
            results = [run(c) for c in chunks]
        else:
            results = list(self._pool.map(run, chunks))
        self.stats.embree_seconds += time.perf_counter() - start
        self.stats.rays += n
        return np.concatenate(results) != -1


@dataclass
class MaterialArrays:
    """Per-material parameters as the kernels take them, plus the BSDF albedo tables."""

    kd: np.ndarray  # (M, 3)
    ke: np.ndarray  # (M, 3)
    gloss: np.ndarray  # (M,) int32: 1 = GGX specular lobe (bsdf module), 0 = Lambertian
    rough: np.ndarray  # (M,) perceptual roughness
    alpha: np.ndarray  # (M,) GGX alpha = max(roughness^2, MIN_ALPHA)
    metal: np.ndarray  # (M,)
    f0: np.ndarray  # (M,) dielectric reflectance at normal incidence
    tex_off: np.ndarray
    tex_w: np.ndarray
    tex_h: np.ndarray
    tex_data: np.ndarray
    tables: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]  # E1, E2, A1, A2


@dataclass
class FrameGeometry:
    """Everything the kernels need for one frame, in world space."""

    frame: int
    camera: Camera
    prev_camera: Camera
    tri_v: np.ndarray
    tri_prev_v: np.ndarray
    tri_ng: np.ndarray
    tri_ns: np.ndarray
    tri_has_ns: np.ndarray
    tri_uv: np.ndarray
    tri_mat: np.ndarray
    tri_obj: np.ndarray
    tri_ke: np.ndarray  # (T, 3) emission of each triangle this frame (Ke x emission_scale)
    materials: MaterialArrays
    light_tri: np.ndarray
    light_cdf: np.ndarray
    tri_light_pdf: np.ndarray
    eps: float
    tracer: EmbreeTracer

    @property
    def has_glossy(self) -> bool:
        return bool(np.any(self.materials.gloss[self.tri_mat] != 0))


def _object_pivots(scene: Scene) -> dict[str, np.ndarray]:
    pivots = {}
    for obj in scene.objects:
        pts = scene.positions[obj.start : obj.stop].reshape(-1, 3)
        pivots[obj.name] = (pts.min(axis=0) + pts.max(axis=0)) * 0.5
    return pivots


def world_vertices(scene: Scene, animation: Animation, frame: float) -> tuple[np.ndarray, list]:
    """World-space triangle vertices at ``frame`` and the per-object 4x4 matrices."""
    pivots = _object_pivots(scene)
    out = scene.positions.copy()
    matrices = []
    for obj in scene.objects:
        matrix = animation.object_matrix(obj.name, frame, pivots[obj.name])
        matrices.append(matrix)
        if not np.array_equal(matrix, np.eye(4)):
            block = scene.positions[obj.start : obj.stop]
            out[obj.start : obj.stop] = block @ matrix[:3, :3].T + matrix[:3, 3]
    return out, matrices


def triangle_emission(scene: Scene, animation: Animation, frame: float) -> np.ndarray:
    """(T, 3) emission of every triangle at ``frame``: its material's ``Ke`` times its
    object's ``emission_scale``."""
    ke = np.array([m.ke for m in scene.materials], dtype=np.float64).reshape(-1, 3)
    tri_ke = ke[scene.material]
    for obj in scene.objects:
        scale = animation.emission_scale(obj.name, frame)
        if not np.array_equal(scale, np.ones(3)):
            tri_ke[obj.start : obj.stop] = tri_ke[obj.start : obj.stop] * scale
    return tri_ke


def frame_camera(
    scene: Scene, animation: Animation, frame: float, width: int, height: int
) -> Camera:
    if animation.has_camera:
        return animation.camera(frame, width, height)
    lo, hi = scene.bounds()
    return default_camera(lo, hi, width, height)


_NO_TABLES = (np.zeros((2, 2)), np.zeros((2, 2)), np.zeros(2), np.zeros(2))


def pack_materials(scene: Scene) -> MaterialArrays:
    count = len(scene.materials)
    mats = scene.materials
    kd = np.array([m.kd for m in mats], dtype=np.float64).reshape(count, 3)
    ke = np.array([m.ke for m in mats], dtype=np.float64).reshape(count, 3)
    rough = np.array([m.roughness for m in mats], dtype=np.float64)
    off = np.full(count, -1, dtype=np.int64)
    tw = np.zeros(count, dtype=np.int64)
    th = np.zeros(count, dtype=np.int64)
    chunks = []
    cursor = 0
    for i, m in enumerate(mats):
        if m.texture is not None:
            off[i] = cursor
            th[i], tw[i] = m.texture.shape[:2]
            chunks.append(m.texture.reshape(-1))
            cursor += m.texture.size
    data = np.concatenate(chunks) if chunks else np.zeros(3, dtype=np.float32)
    return MaterialArrays(
        kd=kd,
        ke=ke,
        gloss=np.array([1 if m.glossy else 0 for m in mats], dtype=np.int32),
        rough=rough,
        alpha=np.maximum(rough * rough, bsdf.MIN_ALPHA),
        metal=np.array([m.metallic for m in mats], dtype=np.float64),
        f0=np.array([m.dielectric_f0 for m in mats], dtype=np.float64),
        tex_off=off,
        tex_w=tw,
        tex_h=th,
        tex_data=np.ascontiguousarray(data, dtype=np.float32),
        # The tables cost about a second to build: only scenes with a glossy material pay.
        tables=bsdf.albedo_tables() if any(m.glossy for m in mats) else _NO_TABLES,
    )


def prepare_frame(
    scene: Scene,
    animation: Animation,
    frame: int,
    width: int,
    height: int,
    threads: int = 1,
    stats: TraceStats | None = None,
) -> FrameGeometry:
    """World geometry, lights, cameras (this and the previous frame) and the Embree scene."""
    tri_v, matrices = world_vertices(scene, animation, frame)
    tri_prev_v, _ = world_vertices(scene, animation, frame - 1)
    camera = frame_camera(scene, animation, frame, width, height)
    prev_camera = frame_camera(scene, animation, frame - 1, width, height)

    cross = np.cross(tri_v[:, 1] - tri_v[:, 0], tri_v[:, 2] - tri_v[:, 0])
    double_area = np.linalg.norm(cross, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        tri_ng = np.where(double_area[:, None] > 0, cross / double_area[:, None], 0.0)
    area = double_area * 0.5

    # Shading normals: the inverse transpose of each object's linear part.
    tri_ns = scene.normals.copy()
    for obj, matrix in zip(scene.objects, matrices, strict=True):
        linear = matrix[:3, :3]
        if not np.array_equal(linear, np.eye(3)):
            normal_matrix = np.linalg.inv(linear).T
            tri_ns[obj.start : obj.stop] = scene.normals[obj.start : obj.stop] @ normal_matrix.T

    materials = pack_materials(scene)
    tri_ke = triangle_emission(scene, animation, frame)
    luminance = tri_ke @ np.array([0.2126, 0.7152, 0.0722])
    power = np.where(luminance > 0, area * luminance, 0.0)
    light_tri = np.flatnonzero(power > 0).astype(np.int32)
    tri_light_pdf = np.zeros(len(area))
    if len(light_tri):
        total = power[light_tri].sum()
        light_cdf = np.cumsum(power[light_tri]) / total
        light_cdf[-1] = 1.0
        # Area-measure pdf of a point on light triangle i: pmf_i / area_i.
        tri_light_pdf[light_tri] = (power[light_tri] / total) / area[light_tri]
    else:
        light_cdf = np.ones(0)

    extent = float(np.abs(tri_v).max()) if tri_v.size else 1.0
    eps = 1e-4 * max(extent, 1e-3)
    tracer = EmbreeTracer(tri_v, threads=threads, stats=stats or TraceStats())
    return FrameGeometry(
        frame=frame,
        camera=camera,
        prev_camera=prev_camera,
        tri_v=tri_v,
        tri_prev_v=tri_prev_v,
        tri_ng=np.ascontiguousarray(tri_ng),
        tri_ns=np.ascontiguousarray(tri_ns),
        tri_has_ns=scene.has_normals,
        tri_uv=scene.uvs,
        tri_mat=scene.material,
        tri_obj=scene.object_index,
        tri_ke=np.ascontiguousarray(tri_ke),
        materials=materials,
        light_tri=light_tri,
        light_cdf=light_cdf,
        tri_light_pdf=tri_light_pdf,
        eps=eps,
        tracer=tracer,
    )


@dataclass
class PrimaryHits:
    prim: np.ndarray
    u: np.ndarray
    v: np.ndarray
    t: np.ndarray
    origins: np.ndarray  # float32 (HW, 3)
    directions: np.ndarray  # float32 (HW, 3)


@dataclass
class PathStarts:
    """Where paths start: a primary hit per entry and the pixel whose random numbers the
    entry's paths use (path key = sample index x ``stride`` + ``pixel``)."""

    pixel: np.ndarray  # int64
    prim: np.ndarray  # int32, -1 = nothing hit (no path)
    u: np.ndarray
    v: np.ndarray
    t: np.ndarray
    directions: np.ndarray  # float32 (n, 3), the primary ray's direction
    stride: int

    @classmethod
    def from_hits(cls, hits: PrimaryHits) -> PathStarts:
        n = hits.prim.shape[0]
        return cls(np.arange(n, dtype=np.int64), hits.prim, hits.u, hits.v, hits.t,
                   hits.directions, n)  # fmt: skip


class Radiance(NamedTuple):
    """Radiance per path start (or per sample and start): ``direct``, ``indirect`` ``(..., n,
    3)`` and, when asked for, ``lobes`` ``(..., n, 4, 3)``: the diffuse-direct,
    diffuse-indirect, glossy-direct and glossy-indirect radiance (not divided by colour)."""

    direct: np.ndarray
    indirect: np.ndarray
    lobes: np.ndarray | None


def trace_primary(geo: FrameGeometry, jitter: np.ndarray | None = None) -> PrimaryHits:
    """The primary hits through every pixel centre, or through the ``jitter`` positions
    (``Camera.primary_rays``)."""
    dirs, eye = geo.camera.primary_rays(jitter)
    directions = np.ascontiguousarray(dirs, dtype=np.float32)
    origins = np.ascontiguousarray(np.broadcast_to(eye.astype(np.float32), directions.shape))
    prim, u, v, t = geo.tracer.intersect(origins, directions)
    return PrimaryHits(prim, u, v, t, origins, directions)


def gbuffer(
    geo: FrameGeometry, hits: PrimaryHits, *, lobe_colours: bool = False,
    next_frame: tuple[np.ndarray, Camera] | None = None,
) -> dict[str, np.ndarray]:  # fmt: skip
    """The noise-free primary-hit layers, each ``(H, W)`` or ``(H, W, k)`` float32.

    ``albedo`` is the total directional albedo ``DiffCol + GlossCol`` where a glossy
    material is seen (``Kd`` x texture on Lambertian ones). With ``lobe_colours`` also
    ``DiffCol`` and ``GlossCol``; with ``next_frame`` (the next frame's vertices and camera)
    also ``motion_next``.
    """
    cam = geo.camera
    mats = geo.materials
    n = hits.prim.shape[0]
    f32 = np.float32
    out_p = np.empty((n, 3), f32)
    out_n = np.empty((n, 3), f32)
    out_albedo = np.empty((n, 3), f32)
    out_emission = np.empty((n, 3), f32)
    out_z = np.empty(n, f32)
    out_id = np.empty(n, f32)
    out_motion = np.empty((n, 2), f32)
    eye = np.asarray(cam.position, float)
    forward = cam.forward
    ndc_now = cam.world_to_ndc()
    ndc_prev = geo.prev_camera.world_to_ndc()

    def work(r: slice) -> None:
        kernels.gbuffer_kernel(
            hits.prim[r], hits.u[r], hits.v[r], hits.directions[r], eye, forward,
            geo.tri_v, geo.tri_prev_v, geo.tri_ng, geo.tri_ns, geo.tri_has_ns, geo.tri_uv,
            geo.tri_mat, geo.tri_obj, geo.tri_ke, mats.kd,
            mats.tex_off, mats.tex_w, mats.tex_h, mats.tex_data,
            ndc_now, ndc_prev, cam.width, cam.height,
            out_p[r], out_n[r], out_albedo[r], out_emission[r], out_z[r], out_id[r], out_motion[r],
        )  # fmt: skip

    geo.tracer.map_rows(n, work)
    h, w = cam.height, cam.width

    def img(a: np.ndarray) -> np.ndarray:
        return a.reshape(h, w, -1)

    layers = {
        "P": img(out_p),
        "N": img(out_n),
        "albedo": img(out_albedo),
        "emission": img(out_emission),
        "Z": out_z.reshape(h, w),
        "id": out_id.reshape(h, w),
        "motion": img(out_motion),
    }
    if lobe_colours or geo.has_glossy:
        diff = np.empty((n, 3))
        gloss = np.empty((n, 3))
        geo.tracer.map_rows(n, lambda r: kernels.lobe_colours_kernel(
            hits.prim[r], hits.u[r], hits.v[r], hits.directions[r], geo.tri_ng, geo.tri_ns,
            geo.tri_has_ns, geo.tri_uv, geo.tri_mat, mats.kd, mats.gloss, mats.rough,
            mats.alpha, mats.metal, mats.f0, mats.tex_off, mats.tex_w, mats.tex_h,
            mats.tex_data, *mats.tables, diff[r], gloss[r],
        ))  # fmt: skip
        if geo.has_glossy:
            layers["albedo"] = img((diff + gloss).astype(f32))
        if lobe_colours:
            layers["DiffCol"] = img(diff.astype(f32))
            layers["GlossCol"] = img(gloss.astype(f32))
    if next_frame is not None:
        next_v, next_camera = next_frame
        motion_next = np.empty((n, 2), f32)
        ndc_next = next_camera.world_to_ndc()
        geo.tracer.map_rows(n, lambda r: kernels.reproject_kernel(
            hits.prim[r], hits.u[r], hits.v[r], geo.tri_v, next_v, ndc_now, ndc_next,
            cam.width, cam.height, motion_next[r],
        ))  # fmt: skip
        layers["motion_next"] = img(motion_next)
    return layers


def frame_key(seed: int, frame: int, stream: int) -> np.uint64:
    """The 64-bit key all of a frame's random numbers derive from."""
    state = np.random.SeedSequence([seed, frame, stream]).generate_state(2, dtype=np.uint64)
    return np.uint64(state[0])


def _as_starts(source: PrimaryHits | PathStarts) -> PathStarts:
    return PathStarts.from_hits(source) if isinstance(source, PrimaryHits) else source


def trace_samples(
    geo: FrameGeometry,
    source: PrimaryHits | PathStarts,
    spp: int,
    max_depth: int,
    key: np.uint64,
    *,
    lobes: bool = False,
    mis_mode: int = kernels.MIS_POWER,
) -> Radiance:
    """Mean radiance per path start over ``spp`` samples, float64 (``Radiance``).

    Samples are traced in batches of whole sample passes; the per-start sums are formed in
    sample order, so the result does not depend on the batch size.
    """
    starts = _as_starts(source)
    n = starts.prim.shape[0]
    sum_direct = np.zeros((n, 3))
    sum_indirect = np.zeros((n, 3))
    sum_lobes = np.zeros((n, 4, 3)) if lobes else None
    samples_per_batch = max(1, min(spp, MAX_PATHS_PER_BATCH // max(n, 1)))
    for first in range(0, spp, samples_per_batch):
        count = min(samples_per_batch, spp - first)
        batch = trace_batch(geo, starts, first, count, max_depth, key, lobes=lobes,
                            mis_mode=mis_mode)  # fmt: skip
        for s in range(count):
            sum_direct += batch.direct[s]
            sum_indirect += batch.indirect[s]
            if sum_lobes is not None and batch.lobes is not None:
                sum_lobes += batch.lobes[s]
    return Radiance(
        sum_direct / spp,
        sum_indirect / spp,
        None if sum_lobes is None else sum_lobes / spp,
    )


def _shade_rows(
    geo: FrameGeometry,
    depth: int,
    max_depth: int,
    key: np.uint64,
    mis_mode: int,
    lobes: bool,
    rows: tuple[np.ndarray, ...],
    accumulators: tuple[np.ndarray, ...],
    outs: tuple[np.ndarray, ...],
    r: slice,
) -> None:
    """shade_kernel over rows ``r`` of the path state (``rows``) and outputs (``outs``)."""
    mats = geo.materials
    kernels.shade_kernel(
        depth, max_depth, RR_DEPTH, key, geo.eps, mis_mode, lobes,
        *(a[r] for a in rows), *accumulators,
        geo.tri_v, geo.tri_ng, geo.tri_ns, geo.tri_has_ns, geo.tri_uv, geo.tri_mat, geo.tri_ke,
        mats.kd, mats.gloss, mats.rough, mats.alpha, mats.metal, mats.f0,
        mats.tex_off, mats.tex_w, mats.tex_h, mats.tex_data, *mats.tables,
        geo.light_tri, geo.light_cdf, geo.tri_light_pdf,
        *(a[r] for a in outs),
    )  # fmt: skip


def trace_batch(
    geo: FrameGeometry,
    source: PrimaryHits | PathStarts,
    first_sample: int,
    count: int,
    max_depth: int,
    key: np.uint64,
    *,
    lobes: bool = False,
    mis_mode: int = kernels.MIS_POWER,
) -> Radiance:
    """Samples ``first_sample .. first_sample + count - 1`` of every path start:
    ``Radiance`` with arrays ``(count, n, ...)``."""
    starts = _as_starts(source)
    n_starts = starts.prim.shape[0]
    n = n_starts * count
    acc_direct = np.zeros((n, 3))
    acc_indirect = np.zeros((n, 3))
    acc_lobes = np.zeros((n if lobes else 1, 4, 3))
    # Only rays that hit something start a path; background stays black.
    hit_starts = np.flatnonzero(starts.prim >= 0).astype(np.int64)
    samples = np.repeat(np.arange(count, dtype=np.int64), hit_starts.size)
    index = np.tile(hit_starts, count)
    path_id = samples * n_starts + index
    path_key = ((samples + first_sample) * starts.stride + starts.pixel[index]).astype(np.uint64)
    dirs = starts.directions[index]
    prim, bu, bv, tfar = starts.prim[index], starts.u[index], starts.v[index], starts.t[index]
    throughput = np.ones((path_id.size, 3))
    prev_pdf = np.zeros(path_id.size)
    lobe_frac = np.ones((path_id.size, 3))
    tracer = geo.tracer
    accumulators = (acc_direct, acc_indirect, acc_lobes)
    for depth in range(max_depth + 1):
        m = prim.shape[0]
        if m == 0:
            break
        shadow_org = np.empty((m, 3), np.float32)
        shadow_dir = np.empty((m, 3), np.float32)
        shadow_dist = np.empty(m, np.float32)
        shadow_value = np.empty((m, 3))
        shadow_frac = np.empty((m, 3))
        shadow_on = np.empty(m, np.bool_)
        next_org = np.empty((m, 3), np.float32)
        next_dir = np.empty((m, 3), np.float32)
        next_pdf = np.empty(m)
        next_frac = np.empty((m, 3))
        alive = np.empty(m, np.bool_)
        rows = (path_id, path_key, dirs, prim, bu, bv, tfar, throughput, prev_pdf, lobe_frac)
        outs = (shadow_org, shadow_dir, shadow_dist, shadow_value, shadow_frac, shadow_on,
                next_org, next_dir, next_pdf, next_frac, alive)  # fmt: skip
        tracer.map_rows(m, partial(_shade_rows, geo, depth, max_depth, key, mis_mode, lobes,
                                   rows, accumulators, outs))  # fmt: skip
        s_id, s_org, s_dir, s_dist, s_value, s_frac = kernels.compact_shadow_rays(
            shadow_on, path_id, shadow_org, shadow_dir, shadow_dist, shadow_value, shadow_frac
        )
        if s_id.size:
            blocked = tracer.occluded(s_org, s_dir, s_dist)
            kernels.add_shadow_kernel(
                depth, s_id, s_value, s_frac, ~blocked, acc_direct, acc_indirect, acc_lobes,
                lobes,
            )
        if depth == max_depth:
            break
        path_id, path_key, throughput, prev_pdf, lobe_frac, org, dirs = kernels.compact_paths(
            alive, path_id, path_key, throughput, next_pdf, next_frac, next_org, next_dir
        )
        if path_id.size == 0:
            break
        prim, bu, bv, tfar = tracer.intersect(org, dirs)
    return Radiance(
        acc_direct.reshape(count, n_starts, 3),
        acc_indirect.reshape(count, n_starts, 3),
        acc_lobes.reshape(count, n_starts, 4, 3) if lobes else None,
    )
