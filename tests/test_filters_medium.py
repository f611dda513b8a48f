"""Medium pixels (issue 30): a pixel whose one sample scattered in fog has no surface in the
G-buffer; it takes the nearest surface's G-buffer (filters.medium, stage fill_medium) and is
filtered, not passed through."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from svgf_cli.filters.denoiser import Denoiser
from svgf_cli.filters.medium import (
    MEDIUM_SURFACE,
    NO_FILL,
    coverage,
    fill_sources,
    filled,
    medium_motion,
)
from svgf_cli.filters.params import PRESETS
from svgf_cli.frame import Frame, Signal
from svgf_cli.io.exr import read_frame
from svgf_cli.io.layers import build_mapping

ROOT = Path(__file__).resolve().parents[1]
F32 = np.float32


def reference_sources(depth: np.ndarray, medium: np.ndarray, radius: int) -> np.ndarray:
    """fill_sources in plain Python, float64."""
    height, width = depth.shape
    lit = (medium > 0).any(axis=0)
    out = np.full((height, width), NO_FILL, np.int64)
    for y in range(height):
        for x in range(width):
            if depth[y, x] > 0 or not lit[max(y - 1, 0):y + 2, max(x - 1, 0):x + 2].any():
                continue
            candidates = [((yy - y) ** 2 + (xx - x) ** 2, float(depth[yy, xx]), yy * width + xx)
                          for yy in range(max(y - radius, 0), min(y + radius + 1, height))
                          for xx in range(max(x - radius, 0), min(x + radius + 1, width))
                          if depth[yy, xx] > 0]
            out[y, x] = min(candidates)[2] if candidates else MEDIUM_SURFACE
    return out


@pytest.mark.parametrize("radius", [1, 2, 4])
def test_fill_sources_matches_the_reference(radius: int) -> None:
    rng = np.random.default_rng(radius)
    depth = np.where(rng.random((23, 31)) < 0.6, 0.0, rng.uniform(1, 5, (23, 31))).astype(F32)
    depth[:, :6] = 0.0  # a strip with no surface within reach of its left edge
    medium = np.where(rng.random((3, 23, 31)) < 0.3, rng.random((3, 23, 31)), 0.0).astype(F32)
    medium[:, 15:, 20:] = 0.0  # background far from the medium: not a medium pixel
    got = np.empty(depth.shape, np.int32)
    count = fill_sources(depth, medium, radius, got)
    want = reference_sources(depth, medium, radius)
    assert np.array_equal(got, want)
    assert count == int(np.count_nonzero(want != NO_FILL))
    assert (got == MEDIUM_SURFACE).any() and (got >= 0).any() and (got == NO_FILL).any()


def test_filled_copies_the_sources_and_leaves_the_input() -> None:
    plane = np.arange(2 * 3 * 4, dtype=F32).reshape(2, 3, 4)
    sources = np.full((3, 4), NO_FILL, np.int32)
    sources[0, 0] = 5  # (1, 1)
    sources[2, 3] = MEDIUM_SURFACE
    out = filled(plane, sources, 7.0)
    assert out[0, 0, 0] == plane[0, 1, 1] and out[1, 0, 0] == plane[1, 1, 1]
    assert out[0, 2, 3] == 7.0 and out[1, 2, 3] == 7.0
    assert np.array_equal(np.delete(out.reshape(2, -1), [0, 11], axis=1),
                          np.delete(plane.reshape(2, -1), [0, 11], axis=1))
    assert plane[0, 0, 0] == 0.0  # the input is not written


def test_fill_medium_fills_a_shared_colour_once_and_leaves_a_white_one() -> None:
    """Signals sharing one demodulation colour (Cycles' direct and indirect diffuse share
    DiffCol) share its filled copy; a constant colour (the medium's white) is not copied:
    filling it changes no value. The filter's output is bit for bit as with a copy each."""
    import dataclasses

    from svgf_cli.filters.context import FrameContext, StageBase

    taken: list[Frame] = []

    class Take(StageBase):
        name = "take"

        def run(self, ctx: FrameContext) -> bool:
            taken.append(ctx.frame)
            return False

    def frame_of(copies: bool) -> Frame:
        frame = fog_frame(np.random.default_rng(4), with_medium=True)
        diffuse, volume = frame.signals
        shared = diffuse.albedo
        second = shared.copy() if copies else shared
        halved = dataclasses.replace(diffuse, name="indirect", radiance=diffuse.radiance * 0.5,
                                     albedo=second)
        return dataclasses.replace(frame, signals=[diffuse, halved, volume])

    outputs = []
    for copies in (False, True):
        denoiser = Denoiser(PRESETS["default"])
        denoiser.pipeline.insert_after("fill_medium", Take())
        source = frame_of(copies)
        outputs.append(denoiser.process(source))
        diffuse, indirect, volume = taken[-1].signals
        assert (diffuse.albedo is indirect.albedo) is not copies
        assert diffuse.albedo is not source.signals[0].albedo  # filled: a copy
        assert np.array_equal(diffuse.albedo, filled(source.signals[0].albedo, _sources(source)))
        assert volume.albedo is source.signals[2].albedo  # white: left as it is
    assert np.array_equal(outputs[0].color.view(np.uint32), outputs[1].color.view(np.uint32))


def _sources(frame: Frame) -> np.ndarray:
    out = np.empty(frame.depth.shape, np.int32)
    fill_sources(frame.depth, frame.medium, PRESETS["default"].medium_fill_radius, out)
    return out


def fog_frame(rng: np.random.Generator, *, with_medium: bool, size: int = 48) -> Frame:
    """A lit floor (albedo 0.5, light 1) under fog on its left half: there, each pixel's one
    sample scattered in the fog (no surface; fog light, exponential noise, mean 0.4) with
    probability 0.6, else reached the floor (floor light, halved by the fog). The right half
    is clear floor; the top rows are sky (no surface, no light)."""
    h = w = size
    fog = np.zeros((h, w), bool)
    fog[8:, : w // 2] = True
    scattered = fog & (rng.random((h, w)) < 0.6)
    depth = np.full((h, w), 4.0, F32)
    depth[:8] = 0.0
    depth[scattered] = 0.0
    albedo = np.full((3, h, w), 0.5, F32)
    albedo[:, depth == 0] = 0.0
    floor = np.where(fog, 0.5, 1.0) * np.where(depth > 0, 1.0, 0.0)
    diffuse = (albedo * floor * rng.exponential(1.0, (h, w))).astype(F32)
    volume = np.where(scattered, 0.4 / 0.6 * rng.exponential(1.0, (h, w)), 0.0)
    volume = np.broadcast_to(volume, (3, h, w)).astype(F32).copy()
    normal = np.zeros((3, h, w), F32)
    normal[2] = 1.0
    normal[:, depth == 0] = 0.0
    mesh = np.where(depth > 0, 1, 0).astype(np.int32)
    return Frame(
        signals=[Signal("diffuse", diffuse, albedo.copy()),
                 Signal("volume", volume, np.ones((3, h, w), F32))],
        normal=normal, depth=depth, motion=np.zeros((2, h, w), F32), mesh_id=mesh,
        albedo=albedo, medium=volume if with_medium else None,
    )


def expected_fog_light() -> float:
    """Per channel inside the fog (fog_frame): the fog light's mean 0.4, plus the floor's
    light (1 x 0.5 through the fog, x albedo 0.5) on the 40 % of samples that reach it."""
    return 0.4 + 0.4 * 0.5 * 0.5


@pytest.mark.parametrize("radius", [0, 4])
def test_fog_is_filtered_where_its_samples_have_no_surface(radius: int) -> None:
    params = PRESETS["default"].replace(medium_fill_radius=radius, pixel_filter=0.0)
    denoiser = Denoiser(params)
    rng = np.random.default_rng(3)
    for _ in range(8):
        frame = fog_frame(rng, with_medium=True)
        out = denoiser.process(frame).color
    inside = out[:, 16:-4, 4:20]
    error = float(np.sqrt(np.mean((inside - expected_fog_light()) ** 2)))
    # Without the fill the scattered pixels pass through raw (exponential noise); with it
    # the fog region converges to its expectation.
    # Measured: 0.54 without, 0.050 with (of which 0.045 is a bias low that the default's
    # loose history clamp gives exponential noise, on clear floor too).
    if radius == 0:
        assert error > 0.3
    else:
        assert error < 0.1
        assert abs(float(inside.mean()) / expected_fog_light() - 1) < 0.15
    sky = out[:, :6, :]
    assert np.array_equal(sky, np.zeros_like(sky))  # no medium light near: background


@pytest.mark.parametrize(("setting", "stage"), [("medium_fill_radius", "fill_medium"),
                                              ("medium_coverage_radius", "medium_coverage")])
def test_frames_without_medium_light_are_unchanged(setting: str, stage: str) -> None:
    rng_a, rng_b = np.random.default_rng(5), np.random.default_rng(5)
    on = Denoiser(PRESETS["default"])
    off = Denoiser(PRESETS["default"].replace(**{setting: 0}))
    assert stage in on.stages and stage not in off.stages
    for _ in range(3):
        a = on.process(fog_frame(rng_a, with_medium=False)).color
        b = off.process(fog_frame(rng_b, with_medium=False)).color
        assert np.array_equal(a, b)


def test_the_reader_marks_the_medium_with_the_volume_lobe() -> None:
    mapping = build_mapping("cycles")
    fog = read_frame(ROOT / "testdata/cycles/production/in.0001.exr", mapping).frame
    volume = next(s for s in fog.signals if s.name == "volume")
    assert fog.medium is volume.radiance
    clear = read_frame(ROOT / "testdata/cycles/roll/in.0001.exr", mapping).frame
    assert clear.medium is None


def test_the_emission_of_medium_pixels_joins_the_medium_signal() -> None:
    from svgf_cli.filters.stages.fill_medium import emission_into_medium

    medium = np.ones((3, 2, 3), F32)
    emission = np.full((3, 2, 3), 2.0, F32)
    pixels = np.array([[True, False, False], [False, False, True]])
    light, rest = emission_into_medium(medium, emission, pixels)
    assert np.array_equal(light + rest, medium + emission)  # nothing lost or added
    assert np.all(light[:, pixels] == 3.0) and np.all(rest[:, pixels] == 0.0)
    assert np.all(light[:, ~pixels] == 1.0) and np.all(rest[:, ~pixels] == 2.0)
    assert np.all(medium == 1.0) and np.all(emission == 2.0)  # copies


def test_sky_seen_through_smoke_is_filtered_not_added_back_raw() -> None:
    """Smoke against the sky: the pixels whose sample passed through carry the sky as
    emission (Cycles' Env), those whose sample scattered carry medium light: the output
    is smooth where the input alternates, and adds up to the same total light."""
    h, w = 24, 32
    rng = np.random.default_rng(9)
    scattered = rng.random((h, w)) < 0.5
    depth = np.zeros((h, w), F32)  # no surface anywhere: medium surfaces
    volume = np.broadcast_to(np.where(scattered, 0.6, 0.0), (3, h, w)).astype(F32).copy()
    sky = np.broadcast_to(np.where(scattered, 0.0, 1.0), (3, h, w)).astype(F32).copy()
    frame = Frame(signals=[Signal("volume", volume, np.ones((3, h, w), F32))],
                  normal=np.zeros((3, h, w), F32), depth=depth,
                  motion=np.zeros((2, h, w), F32), mesh_id=np.full((h, w), -1, np.int32),
                  albedo=np.zeros((3, h, w), F32), emission=sky, medium=volume)
    params = PRESETS["default"].replace(pixel_filter=0.0)
    out = Denoiser(params).process(frame)
    inside = out.color[:, 4:-4, 4:-4]
    assert inside.std() < 0.25 * (volume + sky)[:, 4:-4, 4:-4].std()
    assert abs(float(inside.mean()) - 0.8) < 0.1  # 0.5 x 0.6 + 0.5 x 1.0
    # A pixel is a medium pixel when it or a neighbour has medium light: all but ~0.5^9.
    assert out.medium is not None and out.medium.mean() > 0.99
    assert out.emission is not None and not out.emission[:, out.medium].any()


def test_smoke_fixture_volume_error_is_a_tenth_of_the_input(tmp_path: Path) -> None:
    """Issue 30's target on the committed Cycles smoke shot (bench/volume_regions.py measures
    the same with OIDN beside it): inside the smoke (the reference's volume light over 30 %
    of the pixel's) svgf's mean per-pixel relMSE is at most 0.1x the input's. Measured
    2026-11-27: 0.0266 against 0.714 (0.037x); without medium pixels 0.428 (0.60x)."""
    import OpenEXR
    from test_cli_support import exit_code

    from svgf_cli.evaluate.metrics import per_pixel_relmse
    from svgf_cli.io.exr import read_rgb

    shot = ROOT / "testdata/cycles/smoke"
    out = tmp_path / "den"
    assert exit_code(["denoise", shot / "in.####.exr", "-o", out / "o.####.exr", "-q",
                      "--preset-aovs", "cycles", "--frames", "1-4"]) == 0
    mapping = build_mapping("cycles")
    errors = {"input": [], "svgf": []}
    for f in range(1, 5):
        with OpenEXR.File(str(shot / f"ref.{f:04d}.exr"), separate_channels=True) as exr:
            ch = {n: c.pixels.astype(np.float64) for n, c in exr.parts[0].channels.items()}
        ref = np.stack([ch[f"ViewLayer.Combined.{c}"] for c in "RGB"])
        volume = sum(np.stack([ch[f"ViewLayer.{p}.{c}"] for c in "RGB"])
                     for p in ("VolumeDir", "VolumeInd"))
        inside = volume.mean(axis=0) > 0.3 * np.maximum(ref.mean(axis=0), 1e-6)
        images = {"input": read_frame(shot / f"in.{f:04d}.exr", mapping).frame.total_radiance(),
                  "svgf": read_rgb(out / f"o.{f:04d}.exr", mapping)[0]}
        for name, image in images.items():
            per_pixel = per_pixel_relmse(image.astype(np.float64), ref)
            per_pixel = per_pixel.mean(axis=0) if per_pixel.ndim == 3 else per_pixel
            errors[name].append(float(per_pixel[inside].mean()))
    assert np.mean(errors["svgf"]) <= 0.1 * np.mean(errors["input"]), errors


def test_smoke_fixture_sky_seen_through_the_smoke_goes_back_to_env(tmp_path: Path) -> None:
    """The light layers of the committed smoke shot: on medium pixels the sky seen through
    the smoke (Cycles' ``Env``) is filtered with the volume signal, and its part goes back
    to ``Env``, not to ``VolumeDir`` (filters.composable.medium_emission). Measured
    2026-11-27 over the 8 frames (bench/light_layers.py): VolumeDir 0.06x its input's
    relMSE (trimmed), Env 0.50x; with the whole signal given to VolumeDir 0.78x and 0.88x."""
    import OpenEXR
    from test_cli_support import exit_code

    from svgf_cli.evaluate.metrics import relmse_trimmed

    shot = ROOT / "testdata/cycles/smoke"
    out = tmp_path / "den"
    assert exit_code(["denoise", shot / "in.####.exr", "-o", out / "o.####.exr", "-q",
                      "--preset-aovs", "cycles", "--frames", "1-4"]) == 0

    def layer(path: Path, name: str) -> np.ndarray:
        with OpenEXR.File(str(path), separate_channels=True) as exr:
            channels = {n: c for part in exr.parts for n, c in part.channels.items()}
            return np.stack([channels[f"ViewLayer.{name}.{c}"].pixels.astype(np.float64)
                             for c in "RGB"])

    for name, ratio in (("VolumeDir", 0.2), ("Env", 0.7)):
        errors = {"input": [], "svgf": []}
        for f in range(1, 5):
            ref = layer(shot / f"ref.{f:04d}.exr", name)
            errors["input"].append(relmse_trimmed(layer(shot / f"in.{f:04d}.exr", name), ref))
            errors["svgf"].append(relmse_trimmed(layer(out / f"o.{f:04d}.exr", name), ref))
        assert np.mean(errors["svgf"]) <= ratio * np.mean(errors["input"]), (name, errors)


@pytest.mark.parametrize("radius", [1, 2])
def test_coverage_matches_float64_reference(radius: int) -> None:
    """c(p): the share of the clipped (2 radius + 1)^2 window's pixels that are medium."""
    pixels = np.random.default_rng(radius).random((7, 9)) < 0.4
    got = coverage(pixels, radius)
    want = np.zeros(pixels.shape)
    for y, x in np.ndindex(*pixels.shape):
        window = pixels[max(y - radius, 0):y + radius + 1, max(x - radius, 0):x + radius + 1]
        want[y, x] = window.astype(np.float64).mean()
    assert got.dtype == F32
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-7)


def fog_patch_frame(rng: np.random.Generator, size: int = 48) -> Frame:
    """A lit wall (albedo 0.5, light 1) with a 16x16 patch of fog in front of its middle:
    there each pixel's sample scattered (fog light, exponential noise, mean 0.4) with
    probability 0.6, else reached the wall (its light halved by the fog)."""
    h = w = size
    fog = np.zeros((h, w), bool)
    fog[16:32, 16:32] = True
    scattered = fog & (rng.random((h, w)) < 0.6)
    depth = np.full((h, w), 4.0, F32)
    depth[scattered] = 0.0
    albedo = np.full((3, h, w), 0.5, F32)
    albedo[:, scattered] = 0.0
    wall = np.where(fog, 0.5, 1.0) * np.where(scattered, 0.0, 1.0)
    diffuse = (albedo * wall * rng.exponential(1.0, (h, w))).astype(F32)
    volume = np.where(scattered, 0.4 / 0.6 * rng.exponential(1.0, (h, w)), 0.0)
    volume = np.broadcast_to(volume, (3, h, w)).astype(F32).copy()
    normal = np.zeros((3, h, w), F32)
    normal[2] = 1.0
    normal[:, scattered] = 0.0
    return Frame(
        signals=[Signal("diffuse", diffuse, albedo.copy()),
                 Signal("volume", volume, np.ones((3, h, w), F32))],
        normal=normal, depth=depth, motion=np.zeros((2, h, w), F32),
        mesh_id=np.where(scattered, 0, 1).astype(np.int32), albedo=albedo, medium=volume,
    )


@pytest.mark.parametrize("seed", [3, 4, 5])
def test_the_medium_coverage_keeps_a_small_fogs_light_in_it(seed: int) -> None:
    """A fog patch over a wall that has no edge where the fog ends: filtered as radiance,
    its few bright samples among zeros lose to the zeros and its light spreads onto the
    wall, so the fog comes out dark (measured 0.84-0.89 of its expectation after 8
    frames; 0.80-0.84 before the a-trous stops compared blurred luminance) and the wall
    around it too (up to 0.035 below the far wall); demodulated by its coverage 0.90-0.91,
    and the wall beside it within 0.025 of the far wall (-0.022 to +0.008)."""
    fog_light, wall_light = 0.4 + 0.4 * 0.5 * 0.5, 0.5
    near = np.zeros((48, 48), bool)
    near[12:36, 12:36] = True
    near[16:32, 16:32] = False
    far = np.ones((48, 48), bool)
    far[14:34, 14:34] = False
    far[:8], far[-8:], far[:, :8], far[:, -8:] = False, False, False, False
    shares = {}
    for radius in (0, 1):
        # Without the history gain: in this static patch its wide windows see the fog's
        # few bright samples among zeros cross its significance on 2 of the 8 frames (a
        # heavy tail's false alarm), and the rescaled history brightens the radiance-filtered
        # fog (0.81 -> 0.89): the coverage's own effect is what is measured here.
        denoiser = Denoiser(PRESETS["default"].replace(pixel_filter=0.0, antilag_gain=False,
                                                       medium_coverage_radius=radius))
        assert ("medium_coverage" in denoiser.stages) == (radius > 0)
        rng = np.random.default_rng(seed)
        for _ in range(8):
            out = denoiser.process(fog_patch_frame(rng)).color
        shares[radius] = (float(out[:, 20:28, 20:28].mean()) / fog_light,
                          float(out[:, near].mean()) / wall_light,
                          float(out[:, far].mean()) / wall_light)
    (fog_off, near_off, far_off), (fog_on, near_on, far_on) = shares[0], shares[1]
    assert fog_on > 0.88 and fog_on > fog_off + 0.005
    assert far_on == pytest.approx(far_off, abs=0.002)  # the far wall: as it was
    assert abs(near_on - far_on) < 0.025
    assert abs(near_on - far_on) < abs(near_off - far_off) + 0.005


def test_the_coverage_radius_grows_with_the_image() -> None:
    """auto: 1 below 320 rows of the shorter side, else one pixel per 360, at least 2 (a
    3x3 coverage mottles a 640x360 fog; a 5x5 one is wider than a 128x72 fog's edge and
    lost video JOD at 384x216); an explicit radius is kept."""
    from svgf_cli.filters.params import medium_coverage_radius_for

    auto = PRESETS["default"]
    assert [medium_coverage_radius_for(auto, h, w) for h, w in
            ((72, 128), (144, 256), (216, 384), (319, 640), (360, 640), (640, 360),
             (540, 960), (1080, 1920), (1920, 1080), (2160, 3840))
            ] == [1, 1, 1, 1, 2, 2, 2, 3, 3, 6]
    assert medium_coverage_radius_for(auto.replace(medium_coverage_radius=2), 72, 128) == 2


def reference_medium_motion(light: np.ndarray, previous: np.ndarray, motion: np.ndarray,
                            pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """medium_motion in plain Python, float64: the motion chosen and, per pixel, the two
    candidates' errors' gap (for near ties, where float32 may choose the other)."""
    _, height, width = light.shape

    def mean(planes: np.ndarray, y: int, x: int) -> np.ndarray:
        window = planes[:, max(y - 1, 0):y + 2, max(x - 1, 0):x + 2].astype(np.float64)
        return window.reshape(3, -1).mean(axis=1)

    out = motion.astype(np.float64).copy()
    gap = np.full((height, width), np.inf)
    for y in range(height):
        for x in range(width):
            if not pixels[y, x]:
                continue
            now = mean(light, y, x)
            resting = np.abs(now - mean(previous, y, x)).sum()
            qx = int(np.floor(x + float(motion[0, y, x]) + 0.5))
            qy = int(np.floor(y + float(motion[1, y, x]) + 0.5))
            if 0 <= qx < width and 0 <= qy < height:
                moving = np.abs(now - mean(previous, qy, qx)).sum()
                gap[y, x] = abs(moving - resting)
                if moving < resting:
                    continue
            out[:, y, x] = 0.0
    return out, gap


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_medium_motion_matches_float64_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)
    height, width = 23, 31
    light = rng.random((3, height, width)).astype(F32) * 4
    previous = rng.random((3, height, width)).astype(F32) * 4
    motion = (rng.random((2, height, width)).astype(F32) - 0.5) * 12
    pixels = rng.random((height, width)) < 0.6
    got, still = medium_motion(light, previous, motion, pixels)
    want, gap = reference_medium_motion(light, previous, motion, pixels)
    clear = gap > 1e-4
    assert np.array_equal(got[:, clear], want[:, clear].astype(F32))
    assert np.array_equal(got[:, ~pixels], motion[:, ~pixels])  # other pixels keep theirs
    chosen_still = int((pixels & (want == 0).all(axis=0)).sum())
    assert abs(still - chosen_still) <= int((pixels & ~clear).sum())
    assert 0 < still < pixels.sum()
    motion[:, ::2] = 0.0  # pixels with no motion already are not counted
    _, fewer = medium_motion(light, previous, motion, pixels)
    assert fewer < still


def test_a_still_fog_in_front_of_a_moving_wall_takes_no_motion_and_a_moving_one_the_walls(
) -> None:
    """A fog whose light stays where it was while the surface behind it moves 5 pixels a
    frame (a camera move's parallax) reprojects with no motion; a fog whose light moved as
    the wall did keeps the wall's motion."""
    height, width = 20, 60
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float64)

    def fog(shift: float) -> np.ndarray:  # smooth light with structure along x
        pattern = 1.0 + 0.5 * np.sin((xs - shift) / 3.0) + 0.02 * ys
        return np.repeat(pattern[None], 3, axis=0).astype(F32)

    pixels = np.zeros((height, width), bool)
    pixels[3:17, 12:48] = True
    motion = np.zeros((2, height, width), F32)
    motion[0] = -5.0  # backward: the wall was 5 pixels to the left a frame ago
    still_fog, still = medium_motion(fog(0.0), fog(0.0), motion, pixels)
    assert (still_fog[:, pixels] == 0.0).all() and still == pixels.sum()
    moving_fog, still = medium_motion(fog(0.0), fog(-5.0), motion, pixels)
    assert (moving_fog[:, pixels] == motion[:, pixels]).all() and still == 0
