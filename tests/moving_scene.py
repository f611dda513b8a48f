"""A tiny moving scene with exact motion, depth, normals and ids, for comparing the
``Denoiser`` with the float64 reference frame by frame.

Three layers over a two-row background strip (depth 0, id -1, a constant sky radiance):

* a **wall** (id 1): a tilted plane (depth ``6 + 0.04 u + 0.03 y``) panning right by 0.5 px
  per frame (backward motion ``(-0.5, 0)``: every wall pixel has a half-pixel bilinear
  footprint, and the left column's footprint leaves the image), with a smooth albedo
  texture, a black-albedo patch (filtered as radiance, not demodulated) and a patch whose
  green albedo is 0 (floored, still demodulated);
* a **sticker** (id 3): coplanar with the wall (same depth and normal), sliding left by
  1 px per frame: where it uncovers the wall only the mesh-id test tells them apart;
* an **object** (id 2) at depth 3 moving by (2.5, 1) px per frame in front of both, with a
  0.5 depth step inside the object (same id: only the depth test), a normal crease from a
  camera-facing left part to a grazing right part (only the normal test), and an emissive
  patch. (Both edges run across the horizontal motion, whose half-pixel footprint straddles
  them; the vertical motion is a whole pixel, so its second row of taps has weight 0.)

Every layer is an analytic function of its own coordinates, so the motion vectors are exact
and the pixel at ``(x + motion.x, y + motion.y)`` of frame ``t - 1`` shows the same surface
point. Motion fractions are 0 or 1/2, so bilinear weights (and history lengths resampled
with them) are exact in float32 and the float32 kernels and the float64 reference take
the same branch at every history-length threshold.

Noise is 1-spp-like: every signal is its noise-free value times an Exp(1) draw per pixel.
"""

from __future__ import annotations

import numpy as np

from svgf_cli.frame import Frame

F32 = np.float32
WIDTH, HEIGHT = 24, 16
SKY = np.array([0.2, 0.3, 0.5])
WALL_NORMAL = np.array([0.1, -0.05, 1.0]) / np.linalg.norm([0.1, -0.05, 1.0])
GRAZING_NORMAL = np.array([0.95, 0.0, 0.312]) / np.linalg.norm([0.95, 0.0, 0.312])
EMISSION = np.array([2.0, 1.6, 1.0])


def _wall_albedo(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    albedo = np.stack([
        0.45 + 0.3 * np.sin(0.7 * u) * np.cos(0.5 * v),
        0.5 + 0.25 * np.cos(0.45 * u + 0.3),
        0.4 + 0.3 * np.sin(0.3 * v + 0.55 * u),
    ])
    albedo[:, (u >= 3) & (u < 7) & (v >= 12) & (v < 15)] = 0.0  # black: not demodulated
    green_black = (u >= 9) & (u < 12) & (v >= 3) & (v < 5)
    albedo[1, green_black] = 0.0  # one channel below eps: floored, still demodulated
    return albedo


def scene_frame(t: int, *, seed: int = 0, split: bool = True, noise: bool = True,
                width: int = WIDTH, height: int = HEIGHT, wall_speed: float = 0.5,
                object_velocity: tuple[float, float] = (2.5, 1.0)) -> Frame:
    """Frame ``t`` (0, 1, ...) of the scene. ``noise=False`` gives the noise-free frame.

    ``wall_speed`` (px per frame, rightwards) and ``object_velocity`` change the motion;
    other than the defaults they give inexact bilinear weights (see the module docstring).
    """
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float64)
    cx, cy = xs + 0.5, ys + 0.5  # pixel centres
    depth = np.zeros((height, width))
    normal = np.zeros((3, height, width))
    mesh = np.full((height, width), -1, dtype=np.int32)
    motion = np.zeros((2, height, width))
    albedo = np.zeros((3, height, width))
    direct = np.zeros((3, height, width))  # noise-free illumination, later radiance
    indirect = np.zeros((3, height, width))
    emission = np.zeros((3, height, width))
    black = np.zeros((height, width), dtype=bool)

    def paint(mask: np.ndarray, z: np.ndarray, n: np.ndarray, ident: int, mv: tuple,
              alb: np.ndarray, light_direct: np.ndarray, light_indirect: np.ndarray) -> None:
        depth[mask] = z[mask]
        normal[:, mask] = (n[:, mask] if n.ndim == 3 else n[:, None])
        mesh[mask] = ident
        motion[0, mask], motion[1, mask] = mv
        albedo[:, mask] = alb[:, mask]
        direct[:, mask] = light_direct[mask]
        indirect[:, mask] = light_indirect[mask]
        emission[:, mask] = 0.0

    # Wall: world coordinate u = cx - wall_speed t (panning right).
    u = cx - wall_speed * t
    wall = cy >= 2.0
    wall_depth = 6.0 + 0.04 * u + 0.03 * cy
    paint(wall, wall_depth, WALL_NORMAL, 1, (-wall_speed, 0.0), _wall_albedo(u, cy),
          1.2 + 0.6 * np.sin(0.35 * u + 0.25 * cy), 0.35 + 0.1 * np.cos(0.2 * u))
    black[wall] = np.all(albedo[:, wall] == 0.0, axis=0)

    # Sticker: coplanar with the wall, sliding left 1 px per frame (s = cx + t is fixed).
    s = cx + t
    sticker = (s >= 16.0) & (s < 20.0) & (cy >= 11.0) & (cy < 14.0)
    paint(sticker, wall_depth, WALL_NORMAL, 3, (1.0, 0.0),
          np.broadcast_to(np.array([0.2, 0.6, 0.8])[:, None, None], (3, height, width)),
          np.full((height, width), 1.0), np.full((height, width), 0.5))
    black[sticker] = False

    # Object: own coordinates (a, b) = (cx - vx t, cy - vy t), in front of everything.
    vx, vy = object_velocity
    a, b = cx - vx * t, cy - vy * t
    body = (a >= 2.0) & (a < 9.0) & (b >= 3.0) & (b < 9.0)
    object_depth = np.where(a < 5.5, 3.0, 3.5) + 0.02 * b  # a depth step inside one mesh
    grazing = a >= 3.5  # a crease across the direction of motion, like the depth step
    object_normal = np.where(grazing[None], GRAZING_NORMAL[:, None, None],
                             np.array([0.0, 0.0, 1.0])[:, None, None])
    stripes = 0.75 + 0.25 * np.sin(1.3 * a)
    object_albedo = np.array([0.7, 0.5, 0.3])[:, None, None] * stripes[None]
    paint(body, object_depth, object_normal, 2, (-vx, -vy), object_albedo,
          np.where(grazing, 0.8, 2.0), np.full((height, width), 0.3))
    black[body] = False
    lamp = body & (a >= 3.0) & (a < 5.0) & (b >= 4.0) & (b < 6.0)
    emission[:, lamp] = EMISSION[:, None]

    rng = np.random.default_rng(1000 * seed + t)
    draws = rng.exponential(1.0, (2, height, width)) if noise else np.ones((2, height, width))
    # Black-albedo pixels carry radiance of their own (a dark metal reflecting something).
    direct_radiance = np.where(black[None], 0.4, albedo * direct) * draws[0] + emission
    indirect_radiance = np.where(black[None], 0.1, albedo * indirect) * draws[1]
    sky = ~(depth > 0.0)
    direct_radiance[:, sky] = SKY[:, None]
    indirect_radiance[:, sky] = 0.0

    def f32(array: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(array, dtype=F32)

    frame = Frame(albedo=f32(albedo), normal=f32(normal), depth=f32(depth), motion=f32(motion),
                  mesh_id=mesh, emission=f32(emission))
    if split:
        frame.direct = f32(direct_radiance)
        frame.indirect = f32(indirect_radiance)
    else:
        frame.color = f32(direct_radiance + indirect_radiance)
    frame.validate()
    return frame


def scene_sequence(num_frames: int, **kwargs: object) -> list[Frame]:
    """Frames 0 .. num_frames - 1 of :func:`scene_frame`."""
    return [scene_frame(t, **kwargs) for t in range(num_frames)]
