"""A tiny moving scene with exact motion, depth, normals and ids, for comparing the
``Denoiser`` with the float64 reference frame by frame.

Three layers over a two-row background strip (depth 0, id -1, a constant sky radiance):

* a **wall** (id 1): a tilted plane (depth ``6 + 0.04 u + 0.03 y``) panning right by 0.5 px
  per frame (backward motion ``(-0.5, 0)``: every wall pixel has a half-pixel bilinear
  footprint, and the left column's footprint leaves the image), with a smooth albedo
  texture, a black-albedo patch (filtered as radiance, not demodulated), a patch whose
  green albedo is 0 (floored, still demodulated) and a dark patch (0.05: demodulated
  unless the signal's guide-albedo floor is above it);
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

Signal layouts (``layout``):

* ``"split"``: the paper's direct + indirect, both demodulated by the albedo, emission
  inside direct (``Frame.direct_indirect``);
* ``"combined"``: one colour with the emission inside (``Frame.combined``);
* ``"three"``: three signals with colours of their own, emission separate, like a
  renderer's lobe passes: **diffuse** (the albedo, plus a black stripe on the wall whose
  edges move across the wall, so pixels change mode from frame to frame), **glossy** (a
  specular colour that exceeds a reflectance, up to 1.3, on part of the object: filtered as
  radiance there) and **transmission** (a colour only on the sticker and the object's left
  part, black elsewhere, with a little radiance of its own there). The G-buffer albedo is
  no reflectance (8, like Cycles' Denoising Albedo where a specular path reached a light)
  on a patch of the copper, where the default preset filters the glossy signal as
  radiance (``glossy_emitter_radiance``).

``moving_edge`` adds the moving black stripe to the albedo of the other layouts too.
:func:`plant_extremes` puts non-finite and beyond-limit values into one frame.
"""

from __future__ import annotations

import numpy as np

from svgf_cli.frame import REC709_LUMINANCE, Frame, Signal

F32 = np.float32
WIDTH, HEIGHT = 24, 16
SKY = np.array([0.2, 0.3, 0.5])
WALL_NORMAL = np.array([0.1, -0.05, 1.0]) / np.linalg.norm([0.1, -0.05, 1.0])
GRAZING_NORMAL = np.array([0.95, 0.0, 0.312]) / np.linalg.norm([0.95, 0.0, 0.312])
EMISSION = np.array([2.0, 1.6, 1.0])
ACESCG_LUMINANCE = (0.2722, 0.6741, 0.0537)  # AP1 primaries, D60 (ACES TB-2014-004)
# The moving black stripe (wall coordinates): columns [13 + 1.5 t, 17 + 1.5 t) of rows 2-10,
# i.e. 2 px per frame on screen; its left edge turns pixels from black to coloured, its
# right edge coloured to black.
STRIPE = (13.0, 17.0, 1.5, 2.0, 10.0)


def _stripe(u: np.ndarray, v: np.ndarray, t: int) -> np.ndarray:
    left, right, speed, top, bottom = STRIPE
    return (u >= left + speed * t) & (u < right + speed * t) & (v >= top) & (v < bottom)


def _wall_albedo(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    albedo = np.stack([
        0.45 + 0.3 * np.sin(0.7 * u) * np.cos(0.5 * v),
        0.5 + 0.25 * np.cos(0.45 * u + 0.3),
        0.4 + 0.3 * np.sin(0.3 * v + 0.55 * u),
    ])
    albedo[:, (u >= 3) & (u < 7) & (v >= 12) & (v < 15)] = 0.0  # black: not demodulated
    green_black = (u >= 9) & (u < 12) & (v >= 3) & (v < 5)
    albedo[1, green_black] = 0.0  # one channel below eps: floored, still demodulated
    # Dark but a reflectance: demodulated, except under a guide-albedo floor above 0.05.
    albedo[:, (u >= 14) & (u < 17) & (v >= 3) & (v < 6)] = 0.05
    return albedo


def scene_frame(t: int, *, seed: int = 0, layout: str = "split", noise: bool = True,
                width: int = WIDTH, height: int = HEIGHT, wall_speed: float = 0.5,
                object_velocity: tuple[float, float] = (2.5, 1.0), moving_edge: bool = False,
                luminance_weights: tuple[float, float, float] = REC709_LUMINANCE,
                light_step: tuple[int, float] | None = None,
                motion_next: bool = False) -> Frame:
    """Frame ``t`` (0, 1, ...) of the scene. ``noise=False`` gives the noise-free frame.

    ``light_step`` ``(frame, factor)``: from that frame on every light (not the emitters
    or the sky) is scaled by ``factor``, a lighting change no geometric test sees.

    ``layout`` is ``"split"``, ``"combined"`` or ``"three"`` (see the module docstring).
    ``wall_speed`` (px per frame, rightwards) and ``object_velocity`` change the motion;
    other than the defaults they give inexact bilinear weights (see the module docstring).
    ``motion_next`` also gives the frame its exact motion to the next frame (every layer
    moves at a constant velocity: the negated backward motion; 0 on background).
    """
    if layout not in ("split", "combined", "three"):
        raise ValueError(f"unknown layout {layout!r}")
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float64)
    cx, cy = xs + 0.5, ys + 0.5  # pixel centres
    depth = np.zeros((height, width))
    normal = np.zeros((3, height, width))
    mesh = np.full((height, width), -1, dtype=np.int32)
    motion = np.zeros((2, height, width))
    forward_motion = np.zeros((2, height, width))
    albedo = np.zeros((3, height, width))
    direct = np.zeros((3, height, width))  # noise-free illumination, later radiance
    indirect = np.zeros((3, height, width))
    emission = np.zeros((3, height, width))
    black = np.zeros((height, width), dtype=bool)
    # The lobes of the "three" layout: their colours and noise-free illumination.
    glossy_colour = np.zeros((3, height, width))
    glossy_light = np.zeros((height, width))
    transmission_colour = np.zeros((3, height, width))
    transmission_light = np.zeros((height, width))

    def paint(mask: np.ndarray, z: np.ndarray, n: np.ndarray, ident: int, mv: tuple,
              alb: np.ndarray, light_direct: np.ndarray, light_indirect: np.ndarray,
              glossy: tuple[np.ndarray, np.ndarray],
              transmission: tuple[np.ndarray, np.ndarray]) -> None:
        depth[mask] = z[mask]
        normal[:, mask] = (n[:, mask] if n.ndim == 3 else n[:, None])
        mesh[mask] = ident
        motion[0, mask], motion[1, mask] = mv
        forward_motion[0, mask], forward_motion[1, mask] = -mv[0], -mv[1]
        albedo[:, mask] = alb[:, mask]
        direct[:, mask] = light_direct[mask]
        indirect[:, mask] = light_indirect[mask]
        emission[:, mask] = 0.0
        glossy_colour[:, mask] = glossy[0][:, mask]
        glossy_light[mask] = glossy[1][mask]
        transmission_colour[:, mask] = transmission[0][:, mask]
        transmission_light[mask] = transmission[1][mask]

    def constant(rgb: tuple[float, float, float]) -> np.ndarray:
        return np.broadcast_to(np.array(rgb)[:, None, None], (3, height, width))

    def flat(value: float) -> np.ndarray:
        return np.full((height, width), value)

    # Wall: world coordinate u = cx - wall_speed t (panning right).
    u = cx - wall_speed * t
    wall = cy >= 2.0
    wall_depth = 6.0 + 0.04 * u + 0.03 * cy
    wall_albedo = _wall_albedo(u, cy)
    if moving_edge or layout == "three":
        wall_albedo[:, _stripe(u, cy, t)] = 0.0
    wall_glossy = (0.06 + 0.3 * (0.5 + 0.5 * np.sin(0.25 * u)))[None] * np.array(
        [1.0, 0.95, 0.9])[:, None, None]
    paint(wall, wall_depth, WALL_NORMAL, 1, (-wall_speed, 0.0), wall_albedo,
          1.2 + 0.6 * np.sin(0.35 * u + 0.25 * cy), 0.35 + 0.1 * np.cos(0.2 * u),
          (wall_glossy, 0.8 + 0.4 * np.cos(0.3 * u + 0.2 * cy)), (constant((0, 0, 0)), flat(0)))
    black[wall] = np.all(albedo[:, wall] == 0.0, axis=0)

    # Sticker: coplanar with the wall, sliding left 1 px per frame (s = cx + t is fixed).
    s = cx + t
    sticker = (s >= 16.0) & (s < 20.0) & (cy >= 11.0) & (cy < 14.0)
    paint(sticker, wall_depth, WALL_NORMAL, 3, (1.0, 0.0), constant((0.2, 0.6, 0.8)),
          flat(1.0), flat(0.5), (constant((0.5, 0.5, 0.5)), flat(0.6)),
          (constant((0.7, 0.85, 0.95)), flat(0.6)))
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
    # Copper, brighter than a reflectance (up to 1.3, like Cycles' glossy colour on a
    # polished metal) on the right part: the glossy signal is filtered as radiance there.
    copper = np.array([0.95, 0.64, 0.54])[:, None, None] * np.where(a >= 6.5, 1.35, 1.0)[None]
    clear = np.where((a < 4.5)[None], constant((0.8, 0.9, 1.0)), 0.0)
    paint(body, object_depth, object_normal, 2, (-vx, -vy), object_albedo,
          np.where(grazing, 0.8, 2.0), flat(0.3), (copper, np.where(grazing, 1.5, 0.7)),
          (clear, flat(0.4)))
    black[body] = False
    lamp = body & (a >= 3.0) & (a < 5.0) & (b >= 4.0) & (b < 6.0)
    emission[:, lamp] = EMISSION[:, None]

    if light_step is not None and t >= light_step[0]:
        for light in (direct, indirect, glossy_light, transmission_light):
            light *= light_step[1]
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

    geometry = dict(albedo=f32(albedo), normal=f32(normal), depth=f32(depth),
                    motion=f32(motion), mesh_id=mesh, emission=f32(emission),
                    luminance_weights=luminance_weights)
    if layout == "split":
        frame = Frame.direct_indirect(f32(direct_radiance), f32(indirect_radiance), **geometry)
    elif layout == "combined":
        frame = Frame.combined(f32(direct_radiance + indirect_radiance), **geometry)
    else:
        lobes = (rng.exponential(1.0, (2, height, width)) if noise
                 else np.ones((2, height, width)))
        glossy_radiance = glossy_colour * glossy_light * lobes[0]
        # Where the transmission colour is black a little light still arrives (filtered
        # as radiance there).
        clear_black = np.all(transmission_colour == 0.0, axis=0) & ~sky
        transmission_radiance = np.where(clear_black[None], 0.05,
                                         transmission_colour * transmission_light) * lobes[1]
        transmission_radiance[:, sky] = 0.0
        # A light reflected by the copper: the G-buffer albedo holds its emission there.
        reflected_light = body & (a >= 7.0) & (a < 8.5) & (b >= 4.0) & (b < 6.5)
        geometry["albedo"] = f32(np.where(reflected_light[None], 8.0, albedo))
        frame = Frame(signals=[
            Signal("diffuse", f32(direct_radiance - emission + indirect_radiance), f32(albedo)),
            Signal("glossy", f32(glossy_radiance), f32(glossy_colour), glossy=True),
            Signal("transmission", f32(transmission_radiance), f32(transmission_colour),
                   glossy=True),
        ], **geometry)
    if motion_next:
        frame.motion_next = f32(forward_motion)
    frame.validate()
    return frame


def plant_extremes(frame: Frame) -> dict[str, int]:
    """In place: non-finite and beyond-limit values in every plane the value policy covers
    (radiance of the first and last signal, a demodulation colour, emission, depth, normal,
    motion) and one implausibly bright demodulation colour. Returns the non-finite and
    extreme (finite, beyond 1e15) counts planted, as ``DenoisedFrame.counts`` totals them
    (albedo planes shared by several signals count once per signal)."""
    first, last = frame.signals[0], frame.signals[-1]
    first.radiance[0, 14, 20] = np.nan
    first.radiance[1, 15, 21] = np.inf
    first.radiance[2, 12, 22] = 2e15
    first.radiance[0, 13, 1] = -3e16
    last.radiance[1, 9, 3] = -np.inf
    shared = sum(s.albedo is frame.signals[-1].albedo for s in frame.signals)
    frame.signals[-1].albedo[2, 11, 14] = np.inf
    first.albedo[:, 4, 16] = 50.0  # finite: not a reflectance, so radiance mode
    assert frame.emission is not None
    frame.emission[:, 7, 10] = np.nan
    frame.emission[1, 0, 5] = 1e20
    frame.depth[13, 5] = np.nan
    frame.depth[14, 6] = 1e20
    frame.depth[15, 7] = -np.inf
    frame.normal[0, 12, 8] = np.nan
    frame.normal[2, 12, 9] = 1e20
    frame.motion[0, 13, 10] = np.nan
    frame.motion[1, 13, 11] = np.inf
    # radiance 3, emission 3, depth 2, normal 1, motion 2, the albedo once per signal;
    # radiance 2, emission, depth and normal 1 each.
    return {"nonfinite": 3 + 3 + 2 + 1 + 2 + shared, "extreme": 2 + 1 + 1 + 1}


def scene_sequence(num_frames: int, **kwargs: object) -> list[Frame]:
    """Frames 0 .. num_frames - 1 of :func:`scene_frame`."""
    return [scene_frame(t, **kwargs) for t in range(num_frames)]
