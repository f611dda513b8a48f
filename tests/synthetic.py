"""Small builders of synthetic :class:`Frame` objects for tests and benchmarks.

Everything is deterministic for a given ``seed``. A frame is described by its noise-free
*illumination* (what the filter should recover after demodulation), an albedo, optional
emission and a G-buffer; the noisy radiance signals are ``albedo * (illumination + noise)``
(the emission, when given, is the frame's own plane, added back after filtering). Helpers:

* :func:`make_frame` - one frame from scalars or arrays (size, noise, seed, split or
  combined, emission, background, motion, depth/normal/mesh-id planes);
* :func:`edge_geometry` - a vertical depth, normal or mesh-id edge (with optional background);
* :func:`texture` - a smooth deterministic colour texture (for albedo or illumination);
* :func:`static_sequence` - the same noise-free scene with fresh noise every frame;
* :func:`translating_sequence` - a textured plane scrolling by a constant sub-pixel velocity
  with exact backward motion vectors.

Noise: ``noise_kind="gaussian"`` adds the *same* N(0, noise^2) draw to the three channels
of a pixel (grey noise), so the luminance noise variance of the illumination is exactly
``noise**2`` (see :func:`luminance_noise_variance`); ``"exponential"`` multiplies the
illumination by an Exp(1) draw (mean-preserving, heavy-tailed: closer to 1-spp path tracing).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from svgf_cli.frame import Frame, Signal

F32 = np.float32
ArrayLike = float | Sequence[float] | np.ndarray


def _plane3(value: ArrayLike, height: int, width: int) -> np.ndarray:
    """Broadcast a scalar, an RGB triple or an array to a (3, H, W) float32 plane."""
    array = np.asarray(value, dtype=F32)
    if array.ndim == 1:
        array = array.reshape(3, 1, 1)
    # Always a fresh writable copy (a read-only plane would make numba compile twice).
    return np.array(np.broadcast_to(array, (3, height, width)), dtype=F32, order="C")


def _plane(value: float | np.ndarray, height: int, width: int, dtype: type = F32) -> np.ndarray:
    return np.array(np.broadcast_to(np.asarray(value, dtype=dtype), (height, width)), order="C")


def luminance_noise_variance(noise: float) -> float:
    """Luminance variance of the *illumination* noise added by ``noise_kind="gaussian"``."""
    return float(noise) ** 2


def texture(width: int, height: int, *, seed: int = 0, low: float = 0.2, high: float = 0.9,
            period: float = 9.0) -> np.ndarray:
    """A smooth (3, H, W) colour texture in [low, high], deterministic for ``seed``."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    channels = []
    for _ in range(3):
        fx, fy = rng.uniform(0.5, 1.5, size=2) * 2.0 * np.pi / period
        phase = rng.uniform(0.0, 2.0 * np.pi, size=2)
        wave = np.sin(fx * x + phase[0]) * np.cos(fy * y + phase[1])
        channels.append(low + (high - low) * 0.5 * (wave + 1.0))
    return np.ascontiguousarray(np.stack(channels), dtype=F32)


def edge_geometry(
    width: int,
    height: int,
    kind: str,
    *,
    column: int | None = None,
    depth: float = 5.0,
    background_rows: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Depth, normal and mesh-id planes with a vertical edge at ``column`` (default: middle).

    ``kind``: ``"depth"`` (right side twice as far), ``"normal"`` (right side faces +x
    instead of the camera), ``"mesh"`` (right side has id 2, same depth and normal) or
    ``"none"``. ``background_rows`` top rows are background (depth 0, id -1).
    """
    column = width // 2 if column is None else column
    z = np.full((height, width), depth, dtype=F32)
    normal = np.zeros((3, height, width), dtype=F32)
    normal[2] = 1.0
    mesh = np.ones((height, width), dtype=np.int32)
    if kind == "depth":
        z[:, column:] = 2.0 * depth
    elif kind == "normal":
        normal[2, :, column:] = 0.0
        normal[0, :, column:] = 1.0
    elif kind == "mesh":
        mesh[:, column:] = 2
    elif kind != "none":
        raise ValueError(f"unknown edge kind {kind!r}")
    if background_rows:
        z[:background_rows] = 0.0
        normal[:, :background_rows] = 0.0
        mesh[:background_rows] = -1
    return z, normal, mesh


def make_frame(
    width: int = 32,
    height: int = 24,
    *,
    illumination: ArrayLike = 1.0,
    indirect_illumination: ArrayLike | None = None,
    albedo: ArrayLike = 0.5,
    emission: ArrayLike | None = None,
    noise: float = 0.0,
    noise_kind: str = "gaussian",
    seed: int = 0,
    split: bool = True,
    depth: float | np.ndarray = 5.0,
    normal: np.ndarray | None = None,
    mesh_id: int | np.ndarray = 1,
    motion: tuple[float, float] | np.ndarray = (0.0, 0.0),
) -> Frame:
    """One synthetic frame.

    ``illumination`` is the noise-free demodulated direct illumination (or the combined one
    when ``split=False``); ``indirect_illumination`` defaults to half of it. Background is
    wherever ``depth <= 0`` (its normal is zeroed and its id set to -1). ``motion`` is a
    constant backward motion in pixels or a (2, H, W) array.
    """
    rng = np.random.default_rng(seed)
    z = _plane(depth, height, width)
    background = z <= 0.0
    if normal is None:
        normal = np.zeros((3, height, width), dtype=F32)
        normal[2] = 1.0
    normal = np.array(normal, dtype=F32, copy=True)
    normal[:, background] = 0.0
    mesh = np.array(_plane(mesh_id, height, width, np.int32), copy=True)
    mesh[background] = -1
    if isinstance(motion, np.ndarray):
        motion_plane = np.ascontiguousarray(motion, dtype=F32)
    else:
        motion_plane = np.empty((2, height, width), dtype=F32)
        motion_plane[0] = motion[0]
        motion_plane[1] = motion[1]
    albedo_plane = _plane3(albedo, height, width)
    emission_plane = None if emission is None else _plane3(emission, height, width)

    def noisy(clean: np.ndarray) -> np.ndarray:
        if noise_kind == "gaussian":
            draw = rng.standard_normal((height, width)).astype(F32) * F32(noise)
            return clean + draw[None]
        if noise_kind == "exponential":
            return clean * rng.exponential(1.0, (height, width)).astype(F32)[None]
        raise ValueError(f"unknown noise kind {noise_kind!r}")

    def radiance(clean_illumination: ArrayLike) -> np.ndarray:
        value = albedo_plane * noisy(_plane3(clean_illumination, height, width))
        return np.ascontiguousarray(value, dtype=F32)

    if split:
        indirect = (
            _plane3(illumination, height, width) * F32(0.5)
            if indirect_illumination is None
            else indirect_illumination
        )
        signals = [Signal("direct", radiance(illumination), albedo_plane),
                   Signal("indirect", radiance(indirect), albedo_plane)]
    else:
        signals = [Signal("color", radiance(illumination), albedo_plane)]
    frame = Frame(signals=signals, albedo=albedo_plane, normal=np.ascontiguousarray(normal),
                  depth=z, motion=motion_plane, mesh_id=mesh, emission=emission_plane)
    frame.validate()
    return frame


def static_sequence(num_frames: int, width: int = 24, height: int = 16, *, seed: int = 0,
                    **kwargs: object) -> list[Frame]:
    """``num_frames`` frames of one static scene, fresh noise each (seed, seed+1, ...)."""
    return [make_frame(width, height, seed=seed + i, **kwargs) for i in range(num_frames)]


def translating_sequence(
    num_frames: int,
    width: int = 40,
    height: int = 24,
    *,
    velocity: tuple[float, float] = (1.25, 0.5),
    noise: float = 0.0,
    seed: int = 0,
    split: bool = True,
    albedo: ArrayLike = 0.5,
    frequency: float = 1.0,
) -> list[Frame]:
    """A textured illumination scrolling right/down by ``velocity`` pixels per frame.

    The illumination at pixel (x, y) of frame i is an analytic function of
    ``(x - i*vx, y - i*vy)``, so it is exact at sub-pixel shifts; the backward motion is
    ``(-vx, -vy)`` everywhere. Depth 5, normal +z, one mesh. ``frequency`` scales the
    pattern's spatial frequencies (about 0.2-0.35 rad/pixel at 1; lower is smoother, which
    bilinear resampling reproduces more exactly).
    """
    vx, vy = velocity
    frames = []
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    for i in range(num_frames):
        u = (x - i * vx) * frequency
        v = (y - i * vy) * frequency
        pattern = np.stack([
            1.0 + 0.5 * np.sin(0.35 * u) * np.cos(0.21 * v),
            1.0 + 0.4 * np.cos(0.27 * u + 0.5),
            1.0 + 0.3 * np.sin(0.19 * v + 0.31 * u),
        ]).astype(F32)
        frames.append(make_frame(width, height, illumination=pattern, albedo=albedo,
                                 noise=noise, seed=seed + i, split=split,
                                 motion=(-vx, -vy)))
    return frames


def true_radiance(frame_illumination: ArrayLike, *, width: int, height: int,
                  albedo: ArrayLike = 0.5, split: bool = True,
                  emission: ArrayLike | None = None) -> np.ndarray:
    """Noise-free radiance that :func:`make_frame` would produce with ``noise=0``."""
    clean = make_frame(width, height, illumination=frame_illumination, albedo=albedo,
                       split=split, emission=emission)
    return clean.total_radiance()
