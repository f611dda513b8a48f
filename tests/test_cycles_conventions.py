"""Blender Cycles' multilayer EXR conventions, proved on the committed Cycles renders.

Read with the OpenEXR bindings directly (not through svgf's reader), so these facts hold for
the files as Blender wrote them. testdata/cycles/README.md describes the scenes; docs/cycles.md
lists the facts with their numbers.
"""

from __future__ import annotations

import json
from functools import cache
from pathlib import Path

import numpy as np
import OpenEXR
import pytest

CYCLES = Path(__file__).resolve().parent.parent / "testdata" / "cycles"
SCENES = ("roll", "metal")
FRAMES = range(1, 11)
LAYER = "ViewLayer"
BACKGROUND_DEPTH = 1e10
CLIP_START = 0.1  # Blender's default camera clip start, used by both scenes

# channel suffixes in the order a pass's components are stacked
COMPONENTS = "RGBAXYZW"

FLOAT_PASSES = {"Depth", "Normal", "Vector", "IndexOB", "Denoising Depth", "Denoising Normal"}
HALF_PASSES = {
    "Combined", "Emit", "Env", "Denoising Albedo",
    "DiffDir", "DiffInd", "DiffCol", "GlossDir", "GlossInd", "GlossCol",
    "TransDir", "TransInd", "TransCol",
}  # fmt: skip
LOBES = ("Diff", "Gloss", "Trans")


@cache
def read_input(scene: str, frame: int) -> dict[str, np.ndarray]:
    """Every pass of one input frame as float64 (H, W, C), keyed by pass name."""
    with OpenEXR.File(str(CYCLES / scene / f"in.{frame:04d}.exr"), separate_channels=True) as f:
        channels = {name: np.asarray(ch.pixels) for name, ch in f.channels().items()}
    grouped: dict[str, dict[str, np.ndarray]] = {}
    for name, pixels in channels.items():
        layer, pass_name, component = name.split(".")
        assert layer == LAYER
        grouped.setdefault(pass_name, {})[component] = pixels
    return {
        pass_name: np.stack(
            [parts[c] for c in sorted(parts, key=COMPONENTS.index)], axis=-1
        ).astype(np.float64)
        for pass_name, parts in grouped.items()
    }


@cache
def scene_info(scene: str) -> dict:
    return json.loads((CYCLES / scene / "scene.json").read_text())


def object_mask(scene: str, frame: int, name: str) -> np.ndarray:
    index = scene_info(scene)["pass_index"][name]
    return read_input(scene, frame)["IndexOB"][..., 0] == index


def bilinear(image: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sample `image` at continuous pixel positions (pixel centres at +0.5, y = row from top)."""
    height, width = image.shape[:2]
    x, y = x - 0.5, y - 0.5
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    inside = (x0 >= 0) & (y0 >= 0) & (x0 + 1 < width) & (y0 + 1 < height)
    x0, y0 = np.clip(x0, 0, width - 2), np.clip(y0, 0, height - 2)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    value = (
        image[y0, x0] * (1 - fx) * (1 - fy)
        + image[y0, x0 + 1] * fx * (1 - fy)
        + image[y0 + 1, x0] * (1 - fx) * fy
        + image[y0 + 1, x0 + 1] * fx * fy
    )
    return value, inside


def camera_rays(scene: str, frame: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per pixel centre: camera-space direction with z = -1 (Blender camera looks down -z),
    the camera-to-world rotation and the camera position (from scene.json)."""
    info = scene_info(scene)
    width, height = info["resolution"]
    record = info["per_frame"][str(frame)]
    to_world = np.array(record["camera_matrix_world"])
    half_width = np.tan(record["camera_angle_x"] / 2)  # sensor fit AUTO, landscape: fov is x
    rows, cols = np.mgrid[0:height, 0:width]
    x = ((cols + 0.5) / width * 2 - 1) * half_width
    y = (1 - (rows + 0.5) / height * 2) * half_width * height / width
    return np.stack([x, y, -np.ones_like(x)], axis=-1), to_world[:3, :3], to_world[:3, 3]


def reprojection_error(
    scene: str, pair: str, sign_x: int, sign_y: int, step: int, min_motion: float
) -> float:
    """Mean |DiffCol(t) - DiffCol(t+step) fetched at p + (sign_x*U, sign_y*V)|, (U, V) the
    Vector pass's XY or ZW (or zero), over pixels moving more than `min_motion` pixels."""
    errors = []
    for frame in FRAMES:
        if frame + step not in FRAMES:
            continue
        current = read_input(scene, frame)
        vector = current["Vector"]
        u, v = {"XY": (vector[..., 0], vector[..., 1]), "ZW": (vector[..., 2], vector[..., 3]),
                "zero": (0 * vector[..., 0], 0 * vector[..., 0])}[pair]  # fmt: skip
        height, width = u.shape
        rows, cols = np.mgrid[0:height, 0:width] + 0.5
        moving = np.hypot(vector[..., 0], vector[..., 1]) > min_motion
        fetched, inside = bilinear(
            read_input(scene, frame + step)["DiffCol"], cols + sign_x * u, rows + sign_y * v
        )
        errors.append(np.abs(fetched - current["DiffCol"])[inside & moving].mean())
    return float(np.mean(errors))


# --------------------------------------------------------------------------- files


@pytest.mark.parametrize("scene", SCENES)
def test_input_channels_and_pixel_types(scene):
    expected = {
        f"{LAYER}.{p}.{c}"
        for p, comps in {
            "Combined": "RGBA", "Depth": "Z", "Normal": "XYZ", "Vector": "XYZW", "IndexOB": "X",
            "Denoising Albedo": "RGB", "Denoising Normal": "XYZ", "Denoising Depth": "Z",
            **{p: "RGB" for p in HALF_PASSES - {"Combined", "Denoising Albedo"}},
        }.items()
        for c in comps
    }  # fmt: skip
    for frame in (FRAMES[0], FRAMES[-1]):
        path = CYCLES / scene / f"in.{frame:04d}.exr"
        with OpenEXR.File(str(path), separate_channels=True) as f:
            channels = f.channels()
            assert set(channels) == expected
            for name, channel in channels.items():
                pass_name = name.split(".")[1]
                want = np.float32 if pass_name in FLOAT_PASSES else np.float16
                assert channel.pixels.dtype == want, name
            assert f.header()["compression"] == OpenEXR.ZIP_COMPRESSION


@pytest.mark.parametrize("scene", SCENES)
def test_references_are_plain_float_rgba(scene):
    width, height = scene_info(scene)["resolution"]
    for frame in FRAMES:
        with OpenEXR.File(
            str(CYCLES / scene / f"ref.{frame:04d}.exr"), separate_channels=True
        ) as f:
            channels = f.channels()
            assert set(channels) == {"R", "G", "B", "A"}
            for channel in channels.values():
                assert channel.pixels.dtype == np.float32
                assert channel.pixels.shape == (height, width)
                assert np.isfinite(channel.pixels).all()
            assert (channels["A"].pixels == 1).all()


# --------------------------------------------------------------------------- Vector


def test_vector_xy_with_flipped_y_points_to_the_previous_frame():
    right = reprojection_error("roll", "XY", +1, -1, -1, min_motion=1.0)
    zero = reprojection_error("roll", "zero", 0, 0, -1, min_motion=1.0)
    wrong = [
        reprojection_error("roll", "XY", sx, sy, -1, min_motion=1.0)
        for sx, sy in ((+1, +1), (-1, +1), (-1, -1))
    ]
    # measured: 0.070 against 0.139 (zero motion) and 0.148-0.222 (other signs)
    assert right < 0.6 * zero
    assert right < 0.6 * min(wrong)


def test_vector_zw_points_to_the_next_frame_not_the_mirrored_xy():
    """ZW is `current - next` (y up), XY is `previous - current`: for uniform motion ZW ~ XY."""
    zw_next = reprojection_error("roll", "ZW", -1, +1, +1, min_motion=1.0)
    xy_mirrored = reprojection_error("roll", "XY", -1, +1, +1, min_motion=1.0)
    zero = reprojection_error("roll", "zero", 0, 0, +1, min_motion=1.0)
    zw_previous = reprojection_error("roll", "ZW", +1, -1, -1, min_motion=1.0)
    xy_previous = reprojection_error("roll", "XY", +1, -1, -1, min_motion=1.0)
    # measured: 0.071 (ZW) against 0.088 (-XY, exact only for uniform motion) and 0.139 (zero)
    assert zw_next < 0.6 * zero
    assert zw_next < 0.9 * xy_mirrored
    assert xy_previous < 0.9 * zw_previous  # ZW is the better guess for t+1, XY for t-1
    vectors = np.stack([read_input("roll", f)["Vector"] for f in FRAMES])
    same_sign = np.abs(vectors[..., :2] - vectors[..., 2:]).mean()
    opposite_sign = np.abs(vectors[..., :2] + vectors[..., 2:]).mean()
    assert same_sign < 0.25 * opposite_sign


@pytest.mark.parametrize("scene", SCENES)
def test_vector_is_zero_on_the_background_even_when_the_camera_moves(scene):
    for frame in FRAMES:
        passes = read_input(scene, frame)
        background = passes["IndexOB"][..., 0] == 0
        assert background.any()
        assert (passes["Vector"][background] == 0).all()
        assert np.abs(passes["Vector"][~background]).max() > 0.3


# --------------------------------------------------------------------------- depth


@pytest.mark.parametrize("scene", SCENES)
def test_depth_is_distance_along_the_view_axis(scene):
    for frame in (1, 10):
        directions, rotation, origin = camera_rays(scene, frame)
        world = directions @ rotation.T
        axial = -origin[2] / world[..., 2]  # z = 0 floor; camera-space z of the ray is -1
        ray_length = axial * np.linalg.norm(directions, axis=-1)
        floor = object_mask(scene, frame, "floor") & (axial > 0)
        depth = read_input(scene, frame)["Depth"][..., 0]
        to_axial = depth[floor] / axial[floor]
        to_ray = depth[floor] / ray_length[floor]
        assert abs(np.median(to_axial) - 1) < 1e-3
        assert np.mean(np.abs(to_axial - 1) < 0.01) > 0.95
        assert abs(np.median(to_ray) - 1) > 0.03  # the ray-length reading is off by 4-6 %


@pytest.mark.parametrize("scene", SCENES)
def test_one_sample_goes_through_the_pixel_centre_on_every_frame(scene):
    """At 1 spp the camera ray is the pixel centre's, whatever the (animated) seed."""
    for frame in FRAMES:
        directions, rotation, origin = camera_rays(scene, frame)
        axial = -origin[2] / (directions @ rotation.T)[..., 2]
        floor = object_mask(scene, frame, "floor") & (axial > 0)
        depth = read_input(scene, frame)["Depth"][..., 0]
        centred = np.abs(depth[floor] / axial[floor] - 1)
        rows = floor[1:] & floor[:-1]
        per_row = np.abs(axial[1:] / axial[:-1] - 1)[rows]
        # the floor's depth changes by 1.5-2 % a row: a 0.05 pixel offset would show as 0.07 %
        assert np.quantile(per_row, 0.05) > 0.01
        assert np.quantile(centred, 0.98) < 1e-4


@pytest.mark.parametrize("scene", SCENES)
def test_background_depth_is_finite_1e10_and_denoising_depth_0(scene):
    for frame in FRAMES:
        passes = read_input(scene, frame)
        background = passes["IndexOB"][..., 0] == 0
        depth = passes["Depth"][..., 0]
        assert np.isfinite(depth).all()
        assert (depth[background] == np.float32(BACKGROUND_DEPTH)).all()
        assert depth[~background].max() < 100
        assert (passes["Denoising Depth"][..., 0][background] == 0).all()


def test_denoising_depth_is_ray_distance_from_the_near_plane():
    """Denoising Depth = (Depth - clip_start) * |d|, d the camera ray with unit view-axis part,
    on rough surfaces; on near-specular ones it may continue to the reflected surface."""
    for frame in FRAMES:
        passes = read_input("roll", frame)
        directions, _, _ = camera_rays("roll", frame)
        stretch = np.linalg.norm(directions, axis=-1)
        rough = np.isin(passes["IndexOB"][..., 0], [1, 3])  # floor, diffuse box
        predicted = (passes["Depth"][..., 0] - CLIP_START) * stretch
        denoising_depth = passes["Denoising Depth"][..., 0]
        error = np.abs(denoising_depth - predicted)[rough]
        assert np.quantile(error, 0.99) < 1e-5 * predicted[rough].max()  # measured 3e-6
        assert np.abs(denoising_depth - passes["Depth"][..., 0])[rough].mean() > 0.05


# --------------------------------------------------------------------------- normals


@pytest.mark.parametrize("scene", SCENES)
def test_normal_is_world_space(scene):
    for frame in FRAMES:
        floor = object_mask(scene, frame, "floor")
        normal = read_input(scene, frame)["Normal"][floor]
        assert floor.sum() > 1000
        assert np.abs(normal - [0.0, 0.0, 1.0]).max() < 1e-6


def camera_space_floor_normal(scene: str, frame: int) -> np.ndarray:
    """World up in the camera's frame with x right, y up, z away from the camera."""
    _, rotation, _ = camera_rays(scene, frame)
    local = rotation.T @ np.array([0.0, 0.0, 1.0])  # Blender camera axes: looks down -z
    return local * [1.0, 1.0, -1.0]


def test_denoising_normal_is_camera_space_with_z_pointing_away_from_the_camera():
    seen = []
    for frame in FRAMES:
        floor = object_mask("roll", frame, "floor")
        normal = read_input("roll", frame)["Denoising Normal"][floor]
        expected = camera_space_floor_normal("roll", frame)
        assert np.abs(normal - expected).max() < 1e-4  # every floor pixel: rough floor
        assert expected[2] < 0  # facing the camera means negative z
        seen.append(normal.mean(axis=0))
    assert np.abs(seen[0] - seen[-1]).max() > 0.01  # it moves with the camera; Normal does not


def test_denoising_normal_follows_near_specular_reflections():
    """On the glossy (roughness 0.12) floor a third of the pixels carry the normal of the
    surface seen in the reflection, not the floor's."""
    for frame in FRAMES:
        floor = object_mask("metal", frame, "floor")
        normal = read_input("metal", frame)["Denoising Normal"][floor]
        off = np.abs(normal - camera_space_floor_normal("metal", frame)).max(axis=-1) > 1e-3
        assert 0.2 < off.mean() < 0.6


# --------------------------------------------------------------------------- light passes


def light_sum(passes: dict[str, np.ndarray], emit: bool = True, env: bool = True) -> np.ndarray:
    total = sum(
        (passes[f"{lobe}Dir"] + passes[f"{lobe}Ind"]) * passes[f"{lobe}Col"] for lobe in LOBES
    )
    return total + emit * passes["Emit"] + env * passes["Env"]


@pytest.mark.parametrize("scene", SCENES)
def test_combined_is_the_sum_of_lobes_times_colour_plus_emit_and_env(scene):
    worst = 0.0
    for frame in FRAMES:
        passes = read_input(scene, frame)
        combined = passes["Combined"][..., :3]
        error = np.abs(combined - light_sum(passes))
        # every term is stored as half: a few half ulps (2^-11 relative) per term
        worst = max(worst, (error / np.maximum(np.abs(combined), 1e-2)).max())
        emitters = passes["Emit"].max(axis=-1) > 1
        background = passes["IndexOB"][..., 0] == 0
        assert np.abs(combined - light_sum(passes, emit=False))[emitters].min() > 1
        assert np.abs(combined - light_sum(passes, env=False))[background].min() > 0.05
    assert worst < 3e-3  # measured 1.3e-3


@pytest.mark.parametrize("scene", SCENES)
def test_colour_passes_are_reflectances(scene):
    for frame in FRAMES:
        passes = read_input(scene, frame)
        for name in ("DiffCol", "GlossCol", "TransCol"):
            assert passes[name].min() >= 0
            assert passes[name].max() <= 1
        assert passes["TransCol"].max() == 0  # no transmissive material in these scenes


def test_denoising_albedo_is_not_a_reflectance_on_mirrors_and_emitters():
    ball_pixels = ball_hot = 0
    ball_max = 0.0
    for frame in FRAMES:
        passes = read_input("metal", frame)
        albedo = passes["Denoising Albedo"].max(axis=-1)
        ball = object_mask("metal", frame, "mirror_ball")
        strip = object_mask("metal", frame, "strip")
        background = passes["IndexOB"][..., 0] == 0
        ball_pixels += ball.sum()
        ball_hot += (albedo[ball] > 1).sum()
        ball_max = max(ball_max, albedo[ball].max())
        # an emitter's "albedo" is its emission; the background's is the world colour
        assert np.abs(passes["Denoising Albedo"] - passes["Emit"])[strip].max() < 0.05
        assert np.abs(passes["Denoising Albedo"] - passes["Env"])[background].max() == 0
    assert ball_max > 100  # measured 941
    assert 0.001 < ball_hot / ball_pixels < 0.05  # measured 0.7 % of the ball's pixels


# --------------------------------------------------------------------------- object index


@pytest.mark.parametrize("scene", SCENES)
def test_index_ob_holds_the_pass_indices_and_0_on_background(scene):
    indices = set(scene_info(scene)["pass_index"].values())
    for frame in FRAMES:
        passes = read_input(scene, frame)
        index = passes["IndexOB"][..., 0]
        assert set(np.unique(index)) == indices | {0}
        background = index == 0
        assert (background == (passes["Depth"][..., 0] == np.float32(BACKGROUND_DEPTH))).all()
        for name in ("Normal", "Denoising Normal", "DiffCol", "GlossCol", "Emit"):
            assert (passes[name][background] == 0).all(), name
        assert (passes["Combined"][..., :3][background] == passes["Env"][background]).all()
        assert (passes["Combined"][..., 3] == 1).all()


# --------------------------------------------------------------------------- scene facts


def read_reference(scene: str, frame: int) -> np.ndarray:
    path = CYCLES / scene / f"ref.{frame:04d}.exr"
    with OpenEXR.File(str(path), separate_channels=True) as f:
        channels = f.channels()
        return np.stack([channels[c].pixels for c in "RGB"], axis=-1).astype(np.float64)


def test_metal_point_light_switches_on_at_frame_6():
    info = scene_info("metal")
    first_on = info["point_light_on_from_frame"]
    assert first_on == 6
    for frame in FRAMES:
        energy = info["per_frame"][str(frame)]["lights"]["switched_point_light"]["energy"]
        assert energy == (400.0 if frame >= first_on else 0.0)
    means = np.array([read_reference("metal", frame).mean() for frame in FRAMES])
    steps = means[1:] / means[:-1]
    switch = first_on - FRAMES[0] - 1  # index of the step from frame 5 to frame 6
    assert steps[switch] > 1.3  # measured 1.50
    assert np.abs(np.delete(steps, switch) - 1).max() < 0.05  # measured at most 2.5 %
