"""Render the Blender Cycles fixtures under testdata/cycles (run by `make cycles-fixtures`).

Runs in its own virtual environment with Blender as a Python module (`bpy` 4.5 LTS):

    .venv-blender/bin/python testdata/cycles/render.py [--scene roll metal] [--what all]

Every scene is built in code from the factory-empty file (no .blend is stored), animated with
keyframes (so Cycles can evaluate the neighbouring frames for the Vector pass), and rendered on
the CPU with fixed seeds. For every frame it writes

    <scene>/in.####.exr   1 spp, multilayer EXR, every pass a Blender user enables for denoising
    <scene>/ref.####.exr  the same frame at --ref-spp samples, plain single-layer float R,G,B,A

and once per scene <scene>/scene.json: the camera (world matrix, field of view) and the moving
objects' and lights' state per frame, so tests can compute what a pixel should see.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import bpy

HERE = Path(__file__).resolve().parent

RESOLUTION = (128, 72)
FRAMES = (1, 10)
INPUT_SEED = 17  # Cycles seed of the 1 spp inputs (animated: hashed with the frame number)
REF_SEED = 4711  # a different seed for the references, so no reference sample equals an input's
REF_SPP = 1024

# pass_index of each object: the IndexOB pass holds these values (0 = background / no object)
PASS_INDEX = {
    "roll": {"floor": 1, "ball": 2, "box": 3, "bust": 4, "panel": 5},
    "metal": {"floor": 1, "mirror_ball": 2, "strip": 3, "cube": 4, "pillar": 5},
    "production": {"floor": 1, "glass": 2, "wires": 3, "box": 4, "fog": 5},
    "dof": {"floor": 1, "ball": 2, "box": 3, "bust": 4, "panel": 5},
    "smoke": {"floor": 1, "smoke": 2, "sphere": 3, "box": 4},
}

# Light groups of the production scene (View Layer -> Light Groups): every light and the world
# is in one, so the groups add up to Combined.
# The dof and smoke shots carry the same three group names (and so the same passes).
LIGHT_GROUPS = {
    "production": ("key", "fill", "env"),
    "dof": ("key", "fill", "env"),
    "smoke": ("key", "fill", "env"),
}
# Frames per scene (the production-like shots are shorter: they are the biggest files per frame).
SCENE_FRAMES = {"production": (1, 8), "dof": (1, 8), "smoke": (1, 8)}
# Depth of field of the dof shot: f-number at the roll camera's 35 mm lens (aperture diameter
# 35 mm / 0.03 = 1.17 m), focused on the ball. Circles of confusion at 128x72: the emissive
# panel behind the objects about 7 px, the floor at the bottom edge 6-7 px, box and bust 3-5 px,
# the far floor up to about 20 px; the ball's centre is in focus.
DOF_FSTOP = 0.03
# Peak density (1/m) of the smoke shot's medium where the noise is over its threshold.
SMOKE_DENSITY = 8.0


# --------------------------------------------------------------------------- building blocks


def reset_scene() -> bpy.types.Scene:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return bpy.context.scene


def principled(
    name: str,
    base: tuple[float, float, float] = (0.8, 0.8, 0.8),
    roughness: float = 0.5,
    metallic: float = 0.0,
    checker: tuple[tuple[float, float, float], tuple[float, float, float], float] | None = None,
    checker_coords: str = "UV",
    emission: tuple[float, float, float] | None = None,
    emission_strength: float = 0.0,
) -> bpy.types.Material:
    """A Principled BSDF material; optionally a procedural checker as base colour and emission."""
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    bsdf = nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*base, 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["Metallic"].default_value = metallic
    if checker is not None:
        colour_a, colour_b, scale = checker
        coords = nodes.new("ShaderNodeTexCoord")
        tex = nodes.new("ShaderNodeTexChecker")
        tex.inputs["Color1"].default_value = (*colour_a, 1.0)
        tex.inputs["Color2"].default_value = (*colour_b, 1.0)
        tex.inputs["Scale"].default_value = scale
        links.new(coords.outputs[checker_coords], tex.inputs["Vector"])
        links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    if emission is not None:
        bsdf.inputs["Emission Color"].default_value = (*emission, 1.0)
        bsdf.inputs["Emission Strength"].default_value = emission_strength
    return mat


def attach(obj: bpy.types.Object, mat: bpy.types.Material, name: str, pass_index: int) -> None:
    obj.name = name
    obj.data.materials.append(mat)
    obj.pass_index = pass_index


def smooth(obj: bpy.types.Object) -> None:
    for poly in obj.data.polygons:
        poly.use_smooth = True


def add_plane(size: float, location, rotation=(0.0, 0.0, 0.0)) -> bpy.types.Object:
    bpy.ops.mesh.primitive_plane_add(size=size, location=location, rotation=rotation)
    return bpy.context.active_object


def add_sphere(radius: float, location) -> bpy.types.Object:
    bpy.ops.mesh.primitive_uv_sphere_add(
        radius=radius, location=location, segments=64, ring_count=32
    )
    obj = bpy.context.active_object
    smooth(obj)
    return obj


def gradient_world(scene, horizon, zenith, strength: float) -> None:
    """A world whose colour blends from `horizon` (and below) to `zenith` with view elevation."""
    world = bpy.data.worlds.new("World")
    scene.world = world
    world.use_nodes = True
    nodes, links = world.node_tree.nodes, world.node_tree.links
    background = nodes["Background"]
    background.inputs["Strength"].default_value = strength
    coords = nodes.new("ShaderNodeTexCoord")
    split = nodes.new("ShaderNodeSeparateXYZ")
    ramp = nodes.new("ShaderNodeValToRGB")
    ramp.color_ramp.elements[0].position = 0.0  # world "Generated" z = view direction z
    ramp.color_ramp.elements[0].color = (*horizon, 1.0)
    ramp.color_ramp.elements[1].position = 0.12
    ramp.color_ramp.elements[1].color = (*zenith, 1.0)
    links.new(coords.outputs["Generated"], split.inputs["Vector"])
    links.new(split.outputs["Z"], ramp.inputs["Fac"])
    links.new(ramp.outputs["Color"], background.inputs["Color"])


def add_camera(
    scene, target_name: str, lens_mm: float
) -> tuple[bpy.types.Object, bpy.types.Object]:
    bpy.ops.object.empty_add(location=(0.0, 0.0, 0.0))
    target = bpy.context.active_object
    target.name = target_name
    bpy.ops.object.camera_add()
    camera = bpy.context.active_object
    camera.name = "Camera"
    camera.data.lens = lens_mm
    camera.data.sensor_fit = "AUTO"
    track = camera.constraints.new("TRACK_TO")
    track.target = target
    track.track_axis = "TRACK_NEGATIVE_Z"
    track.up_axis = "UP_Y"
    scene.camera = camera
    return camera, target


def key_location(obj, frame: int, location) -> None:
    obj.location = location
    obj.keyframe_insert("location", frame=frame)


def hold_keys(data) -> None:
    """Make every keyframe of `data` (an object or object data) a step: CONSTANT interpolation.

    Keys are inserted with Blender's default (Bezier, auto-clamped handles); the preference for
    new keys is not honoured by the Python module, so the curves are changed after insertion."""
    for curve in data.animation_data.action.fcurves:
        for key in curve.keyframe_points:
            key.interpolation = "CONSTANT"


# --------------------------------------------------------------------------- scenes


def build_roll(scene) -> dict:
    """Camera move; a textured ball rolling across a checker floor; glossy and diffuse objects."""
    index = PASS_INDEX["roll"]
    gradient_world(scene, horizon=(0.55, 0.5, 0.45), zenith=(0.15, 0.3, 0.75), strength=0.6)

    floor = add_plane(30.0, (0.0, 0.0, 0.0))
    attach(
        floor,
        principled("floor", roughness=0.9, checker=((0.75, 0.75, 0.72), (0.08, 0.1, 0.12), 24.0)),
        "floor",
        index["floor"],
    )

    radius = 0.55
    ball = add_sphere(radius, (0.0, 0.0, radius))
    attach(
        ball,
        principled(
            "ball_rough_glossy",
            roughness=0.3,
            checker=((0.8, 0.15, 0.05), (0.9, 0.85, 0.7), 2.0),
            checker_coords="Object",
        ),
        "ball",
        index["ball"],
    )

    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(1.6, 1.4, 0.5), rotation=(0, 0, 0.5))
    attach(
        bpy.context.active_object,
        principled("box_diffuse", base=(0.2, 0.45, 0.7), roughness=1.0),
        "box",
        index["box"],
    )

    bpy.ops.mesh.primitive_monkey_add(size=1.1, location=(-1.7, 1.5, 0.75), rotation=(0, 0, -0.4))
    bust = bpy.context.active_object
    bpy.ops.object.modifier_add(type="SUBSURF")
    bust.modifiers[-1].levels = 1
    bust.modifiers[-1].render_levels = 2
    smooth(bust)
    attach(
        bust,
        principled("bust_mid_glossy", base=(0.9, 0.6, 0.25), roughness=0.25, metallic=1.0),
        "bust",
        index["bust"],
    )

    panel = add_plane(1.4, (0.4, 3.2, 1.0), rotation=(math.radians(90), 0.0, 0.0))
    panel.scale = (1.6, 0.6, 1.0)
    attach(
        panel,
        principled(
            "panel_emitter",
            base=(0.0, 0.0, 0.0),
            roughness=0.5,
            emission=(1.0, 0.75, 0.45),
            emission_strength=6.0,
        ),
        "panel",
        index["panel"],
    )

    bpy.ops.object.light_add(type="AREA", location=(-2.0, -1.5, 4.5))
    key_light = bpy.context.active_object
    key_light.name = "key_light"
    key_light.data.energy = 900.0
    key_light.data.size = 2.0
    key_light.rotation_euler = (math.radians(25), math.radians(-20), 0.0)

    camera, target = add_camera(scene, "camera_target", lens_mm=35.0)

    first, last = FRAMES
    # Ball: at rest at `first`, rolls +x, at rest again at `last` (Bezier ease in/out, so its
    # speed differs from frame to frame: the backward and forward motion vectors are not mirror
    # images). Rolling without slipping: rotation about +y = distance / radius.
    x0, x1 = -1.4, 1.3
    for frame, x in ((first, x0), (last, x1)):
        key_location(ball, frame, (x, 0.2, radius))
        ball.rotation_euler = (0.0, (x - x0) / radius, 0.0)
        ball.keyframe_insert("rotation_euler", frame=frame)
    # Camera: a dolly to the right and down while its target drifts; keys outside the frame
    # range, so it moves on every rendered frame, at changing speed.
    key_location(camera, first - 6, (-3.6, -6.2, 2.9))
    key_location(camera, last + 6, (2.2, -5.4, 2.2))
    key_location(target, first - 6, (-0.6, 0.8, 0.9))
    key_location(target, last + 6, (0.5, 0.9, 0.8))
    return {"ball_radius": radius, "ball_x": [x0, x1]}


def build_metal(scene) -> dict:
    """A mirror-like metal ball reflecting a moving area light, a point light switching on."""
    index = PASS_INDEX["metal"]
    gradient_world(scene, horizon=(0.12, 0.12, 0.14), zenith=(0.05, 0.08, 0.2), strength=1.0)

    floor = add_plane(30.0, (0.0, 0.0, 0.0))
    attach(
        floor,
        principled(
            "floor_glossy",
            roughness=0.12,
            checker=((0.7, 0.7, 0.7), (0.05, 0.05, 0.06), 24.0),
        ),
        "floor",
        index["floor"],
    )

    radius = 0.8
    mirror = add_sphere(radius, (0.0, 0.4, radius))
    attach(
        mirror,
        principled("mirror_metal", base=(0.95, 0.93, 0.9), roughness=0.08, metallic=1.0),
        "mirror_ball",
        index["mirror_ball"],
    )

    strip = add_plane(1.0, (-1.6, 3.0, 1.4), rotation=(math.radians(90), 0.0, math.radians(20)))
    strip.scale = (1.8, 0.25, 1.0)
    attach(
        strip,
        principled(
            "strip_emitter",
            base=(0.0, 0.0, 0.0),
            emission=(0.6, 0.8, 1.0),
            emission_strength=8.0,
        ),
        "strip",
        index["strip"],
    )

    bpy.ops.mesh.primitive_cube_add(size=0.7, location=(1.6, 0.9, 0.35), rotation=(0, 0, 0.7))
    attach(
        bpy.context.active_object,
        principled("cube_diffuse", base=(0.75, 0.2, 0.15), roughness=1.0),
        "cube",
        index["cube"],
    )

    bpy.ops.mesh.primitive_cylinder_add(radius=0.3, depth=1.6, location=(-1.5, 1.2, 0.8))
    pillar = bpy.context.active_object
    smooth(pillar)
    attach(
        pillar,
        principled("pillar_rough_glossy", base=(0.3, 0.7, 0.35), roughness=0.35),
        "pillar",
        index["pillar"],
    )

    first, last = FRAMES
    half = (first + last + 1) // 2  # first frame with the point light on

    bpy.ops.object.light_add(type="AREA", location=(2.5, -1.0, 3.0))
    area = bpy.context.active_object
    area.name = "moving_area_light"
    area.data.energy = 400.0
    area.data.size = 0.8
    area.data.color = (1.0, 0.9, 0.75)
    track = area.constraints.new("TRACK_TO")
    track.target = mirror
    track.track_axis = "TRACK_NEGATIVE_Z"
    track.up_axis = "UP_Y"
    key_location(area, first - 3, (2.8, -1.6, 2.6))
    key_location(area, (first + last) // 2, (0.6, -2.4, 3.4))
    key_location(area, last + 3, (-2.4, -1.4, 2.8))

    bpy.ops.object.light_add(type="POINT", location=(-0.9, -0.9, 2.2))
    point = bpy.context.active_object
    point.name = "switched_point_light"
    point.data.shadow_soft_size = 0.1
    point.data.color = (0.6, 0.75, 1.0)
    point.data.energy = 0.0
    point.data.keyframe_insert("energy", frame=first - 1)
    point.data.energy = 400.0
    point.data.keyframe_insert("energy", frame=half)
    hold_keys(point.data)

    camera, target = add_camera(scene, "camera_target", lens_mm=40.0)
    target.location = (0.0, 0.6, 0.6)
    key_location(camera, first - 6, (-1.2, -5.8, 2.3))
    key_location(camera, last + 6, (0.9, -5.5, 2.0))
    return {"mirror_ball_radius": radius, "point_light_on_from_frame": half}


def glass_material(name: str) -> bpy.types.Material:
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.95, 0.97, 1.0, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.02
    bsdf.inputs["Transmission Weight"].default_value = 1.0
    bsdf.inputs["IOR"].default_value = 1.45
    return mat


def fog_material(name: str, density: float) -> bpy.types.Material:
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.remove(nodes["Principled BSDF"])
    volume = nodes.new("ShaderNodeVolumePrincipled")
    volume.inputs["Density"].default_value = density
    volume.inputs["Color"].default_value = (0.9, 0.9, 0.95, 1.0)
    links.new(volume.outputs["Volume"], nodes["Material Output"].inputs["Volume"])
    return mat


def build_production(scene) -> dict:
    """A production-like shot: three light groups (key, fill switching on, env), glass, a fog
    volume box, thin metal wires, Cryptomatte, a camera move."""
    index = PASS_INDEX["production"]
    add_light_groups(scene, "production")
    gradient_world(scene, horizon=(0.5, 0.5, 0.55), zenith=(0.1, 0.2, 0.5), strength=0.5)
    scene.world.lightgroup = "env"

    floor = add_plane(30.0, (0.0, 0.0, 0.0))
    attach(
        floor,
        principled("floor", roughness=0.6, checker=((0.7, 0.7, 0.68), (0.1, 0.1, 0.12), 20.0)),
        "floor",
        index["floor"],
    )
    glass = add_sphere(0.6, (-0.6, 0.3, 0.6))
    attach(glass, glass_material("glass"), "glass", index["glass"])

    bpy.ops.mesh.primitive_cube_add(size=0.8, location=(1.3, 0.9, 0.4), rotation=(0, 0, 0.6))
    attach(
        bpy.context.active_object,
        principled("box_diffuse", base=(0.7, 0.35, 0.15), roughness=1.0),
        "box",
        index["box"],
    )
    wire_mat = principled("wire_metal", base=(0.9, 0.9, 0.92), roughness=0.2, metallic=1.0)
    for i in range(4):  # thin vertical wires, 1.5 cm thick: under a pixel wide
        bpy.ops.mesh.primitive_cylinder_add(
            radius=0.0075, depth=2.4, location=(0.2 + 0.35 * i, -0.4, 1.2), vertices=8
        )
        attach(bpy.context.active_object, wire_mat, f"wire_{i}", index["wires"])
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(-1.7, 1.0, 0.8))
    fog = bpy.context.active_object
    fog.scale = (0.8, 0.8, 0.8)
    attach(fog, fog_material("fog", density=1.5), "fog", index["fog"])

    first, last = SCENE_FRAMES["production"]
    bpy.ops.object.light_add(type="AREA", location=(-2.2, -1.8, 4.0))
    key = bpy.context.active_object
    key.name = "key_light"
    key.data.energy = 700.0
    key.data.size = 1.5
    key.rotation_euler = (math.radians(30), math.radians(-25), 0.0)
    key.lightgroup = "key"

    bpy.ops.object.light_add(type="POINT", location=(2.2, -1.2, 1.8))
    fill = bpy.context.active_object
    fill.name = "fill_light"
    fill.data.shadow_soft_size = 0.15
    fill.data.color = (0.55, 0.7, 1.0)
    fill.lightgroup = "fill"
    on_from = (first + last + 1) // 2  # the fill switches on mid-shot: a per-group change
    fill.data.energy = 0.0
    fill.data.keyframe_insert("energy", frame=first - 1)
    fill.data.energy = 250.0
    fill.data.keyframe_insert("energy", frame=on_from)
    hold_keys(fill.data)

    camera, target = add_camera(scene, "camera_target", lens_mm=32.0)
    target.location = (-0.2, 0.6, 0.7)
    key_location(camera, first - 5, (-2.0, -6.0, 2.4))
    key_location(camera, last + 5, (1.2, -5.6, 2.1))
    return {"light_groups": list(LIGHT_GROUPS["production"]), "fill_on_from_frame": on_from}


def add_light_groups(scene, name: str) -> None:
    layer = scene.view_layers[0]
    for group in LIGHT_GROUPS[name]:
        layer.lightgroups.add(name=group)


def build_dof(scene) -> dict:
    """The roll shot (same objects, ball and camera animation) through a wide-open lens focused
    on the ball: the background, the box and the bust and the near floor are out of focus.
    Light groups (key: the area light, fill: the emissive panel, env: the world) and the
    production shot's passes."""
    extra = build_roll(scene)
    add_light_groups(scene, "dof")
    bpy.data.objects["key_light"].lightgroup = "key"
    bpy.data.objects["panel"].lightgroup = "fill"
    scene.world.lightgroup = "env"
    dof = scene.camera.data.dof
    dof.use_dof = True
    dof.focus_object = bpy.data.objects["ball"]
    dof.aperture_fstop = DOF_FSTOP
    return {
        **extra,
        "light_groups": list(LIGHT_GROUPS["dof"]),
        "dof": {
            "focus_object": "ball",
            "aperture_fstop": DOF_FSTOP,
            "aperture_diameter_m": scene.camera.data.lens * 1e-3 / DOF_FSTOP,
            "aperture_blades": 0,
        },
    }


def smoke_material(name: str, density: float) -> bpy.types.Material:
    """A patchy, smoke-like medium for a 2 m cube (object coordinates -1..1): a Principled
    Volume whose density is a thresholded Noise Texture (object space), faded to zero towards
    a sphere of radius 1 so the cube's faces do not show."""
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.remove(nodes["Principled BSDF"])
    coords = nodes.new("ShaderNodeTexCoord")
    noise = nodes.new("ShaderNodeTexNoise")
    noise.inputs["Scale"].default_value = 2.2
    noise.inputs["Detail"].default_value = 4.0
    noise.inputs["Roughness"].default_value = 0.55
    links.new(coords.outputs["Object"], noise.inputs["Vector"])
    patches = nodes.new("ShaderNodeMapRange")  # noise 0.45 .. 0.68 -> 0 .. 1, clamped
    patches.inputs["From Min"].default_value = 0.45
    patches.inputs["From Max"].default_value = 0.68
    links.new(noise.outputs["Fac"], patches.inputs["Value"])
    sphere = nodes.new("ShaderNodeTexGradient")  # 1 - |p|, 0 outside the unit sphere
    sphere.gradient_type = "SPHERICAL"
    links.new(coords.outputs["Object"], sphere.inputs["Vector"])
    fade = nodes.new("ShaderNodeMapRange")  # full density inside radius 0.65
    fade.inputs["From Min"].default_value = 0.0
    fade.inputs["From Max"].default_value = 0.35
    links.new(sphere.outputs["Fac"], fade.inputs["Value"])
    product = nodes.new("ShaderNodeMath")
    product.operation = "MULTIPLY"
    links.new(patches.outputs["Result"], product.inputs[0])
    links.new(fade.outputs["Result"], product.inputs[1])
    scaled = nodes.new("ShaderNodeMath")
    scaled.operation = "MULTIPLY"
    scaled.inputs[1].default_value = density
    links.new(product.outputs["Value"], scaled.inputs[0])
    volume = nodes.new("ShaderNodeVolumePrincipled")
    volume.inputs["Color"].default_value = (0.85, 0.85, 0.88, 1.0)
    links.new(scaled.outputs["Value"], volume.inputs["Density"])
    links.new(volume.outputs["Volume"], nodes["Material Output"].inputs["Volume"])
    return mat


def build_smoke(scene) -> dict:
    """A heterogeneous smoke cloud (noise-driven density) standing on a checker floor, its
    lower part in front of the floor and a diffuse sphere, its upper part against the sky; a
    sun (key), a bluish area fill and the world (env) in three light groups; slow camera move."""
    index = PASS_INDEX["smoke"]
    add_light_groups(scene, "smoke")
    gradient_world(scene, horizon=(0.6, 0.62, 0.65), zenith=(0.2, 0.35, 0.7), strength=0.6)
    scene.world.lightgroup = "env"

    floor = add_plane(30.0, (0.0, 0.0, 0.0))
    attach(
        floor,
        principled("floor", roughness=0.8, checker=((0.7, 0.7, 0.68), (0.12, 0.12, 0.14), 20.0)),
        "floor",
        index["floor"],
    )
    bpy.ops.mesh.primitive_cube_add(size=2.0, location=(0.0, 0.6, 1.15))
    cloud = bpy.context.active_object
    cloud.scale = (1.6, 1.1, 1.15)
    attach(cloud, smoke_material("smoke", density=SMOKE_DENSITY), "smoke", index["smoke"])

    sphere = add_sphere(0.6, (1.3, 2.2, 0.6))  # partly hidden behind the smoke
    attach(
        sphere,
        principled("sphere_diffuse", base=(0.8, 0.4, 0.12), roughness=1.0),
        "sphere",
        index["sphere"],
    )
    bpy.ops.mesh.primitive_cube_add(size=0.8, location=(-2.3, 1.0, 0.4), rotation=(0, 0, 0.5))
    attach(
        bpy.context.active_object,
        principled("box_diffuse", base=(0.25, 0.5, 0.75), roughness=1.0),
        "box",
        index["box"],
    )

    bpy.ops.object.light_add(type="SUN", location=(0.0, 0.0, 6.0))
    sun = bpy.context.active_object
    sun.name = "sun"
    sun.data.energy = 3.5
    sun.data.angle = math.radians(3.0)
    sun.data.color = (1.0, 0.95, 0.85)
    sun.rotation_euler = (math.radians(50), 0.0, math.radians(-140))  # from behind right
    sun.lightgroup = "key"

    bpy.ops.object.light_add(type="AREA", location=(-3.0, -3.0, 2.5))
    fill = bpy.context.active_object
    fill.name = "fill_light"
    fill.data.energy = 200.0
    fill.data.size = 1.5
    fill.data.color = (0.6, 0.72, 1.0)
    track = fill.constraints.new("TRACK_TO")
    track.target = cloud
    track.track_axis = "TRACK_NEGATIVE_Z"
    track.up_axis = "UP_Y"
    fill.lightgroup = "fill"

    first, last = SCENE_FRAMES["smoke"]
    camera, target = add_camera(scene, "camera_target", lens_mm=35.0)
    target.location = (0.1, 0.6, 1.2)
    key_location(camera, first - 5, (-1.8, -5.8, 1.0))
    key_location(camera, last + 5, (1.0, -5.5, 1.2))
    return {"light_groups": list(LIGHT_GROUPS["smoke"]), "smoke_density": SMOKE_DENSITY}


SCENES = {
    "roll": build_roll,
    "metal": build_metal,
    "production": build_production,
    "dof": build_dof,
    "smoke": build_smoke,
}


# --------------------------------------------------------------------------- render settings


def common_settings(
    scene, resolution: tuple[int, int], frames: tuple[int, int] = FRAMES
) -> None:
    render = scene.render
    render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    render.resolution_x, render.resolution_y = resolution
    render.resolution_percentage = 100
    render.fps = 24
    scene.frame_start, scene.frame_end = frames
    render.use_motion_blur = False  # the Vector pass is only written without motion blur
    render.use_compositing = False
    render.use_sequencer = False
    render.threads_mode = "FIXED"
    render.threads = 2
    scene.cycles.use_denoising = False
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.use_animated_seed = True
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    # Header metadata that changes from run to run (wall-clock date, render time, host).
    render.use_stamp_date = False
    render.use_stamp_render_time = False
    render.use_stamp_memory = False
    render.use_stamp_hostname = False


def input_settings(
    scene, codec: str, depth: str, seed: int = INPUT_SEED, sample_offset: int = 0,
    spp: int = 1,
) -> None:
    scene.cycles.seed = seed
    # Cycles traces sample 0 through the pixel centre (the filter is only sampled from sample
    # 1 on), so default 1-spp frames are point samples that no history anti-aliases; a
    # subset of one sample starting at 1 or later is one jittered sample of the pixel filter.
    # ``spp`` > 1: that many samples from sample 0 (the pixel filter's footprint averaged).
    scene.cycles.samples = spp + sample_offset
    scene.cycles.use_sample_subset = sample_offset > 0
    scene.cycles.sample_offset = sample_offset
    scene.cycles.sample_subset_length = spp
    layer = scene.view_layers[0]
    for name in (
        "combined", "z", "normal", "vector", "object_index", "emit", "environment",
        "diffuse_direct", "diffuse_indirect", "diffuse_color",
        "glossy_direct", "glossy_indirect", "glossy_color",
        "transmission_direct", "transmission_indirect", "transmission_color",
    ):  # fmt: skip
        setattr(layer, f"use_pass_{name}", True)
    layer.cycles.denoising_store_passes = True  # Denoising Albedo / Normal / Depth
    if len(layer.lightgroups):  # the production shot: volumes and Cryptomatte too
        layer.cycles.use_pass_volume_direct = True
        layer.cycles.use_pass_volume_indirect = True
        layer.use_pass_cryptomatte_object = True
    image = scene.render.image_settings
    image.file_format = "OPEN_EXR_MULTILAYER"
    image.color_depth = depth
    image.exr_codec = codec


def reference_settings(scene, spp: int) -> None:
    scene.cycles.samples = spp
    scene.cycles.seed = REF_SEED
    layer = scene.view_layers[0]
    for prop in dir(layer):
        if prop.startswith("use_pass_") and prop != "use_pass_combined":
            setattr(layer, prop, False)
    layer.cycles.denoising_store_passes = False
    image = scene.render.image_settings
    image.color_mode = "RGBA"
    image.exr_codec = "ZIP"
    if len(layer.lightgroups):
        # The production shot's references carry the same light groups and light passes (so
        # each layer is scored against its own reference), multilayer, half (size).
        for name in (
            "emit", "environment", "diffuse_direct", "diffuse_indirect", "diffuse_color",
            "glossy_direct", "glossy_indirect", "glossy_color",
            "transmission_direct", "transmission_indirect", "transmission_color",
        ):  # fmt: skip
            setattr(layer, f"use_pass_{name}", True)
        layer.use_pass_cryptomatte_object = False
        layer.cycles.use_pass_volume_direct = True
        layer.cycles.use_pass_volume_indirect = True
        image.file_format = "OPEN_EXR_MULTILAYER"
        image.color_depth = "16"
        return
    image.file_format = "OPEN_EXR"
    image.color_depth = "32"


def frame_record(scene, moving: list[str]) -> dict:
    camera = scene.camera
    record = {
        "camera_matrix_world": [list(row) for row in camera.matrix_world],
        "camera_angle_x": camera.data.angle_x,
        "objects": {
            name: {
                "location": list(bpy.data.objects[name].matrix_world.translation),
                "rotation_euler": list(bpy.data.objects[name].matrix_world.to_euler()),
            }
            for name in moving
        },
        "lights": {
            light.name: {
                "energy": light.data.energy,
                "location": list(light.matrix_world.translation),
            }
            for light in scene.objects
            if light.type == "LIGHT"
        },
    }
    if camera.data.dof.use_dof:  # the dof shot: focus distance along the view axis
        record["focus_distance"] = -(
            camera.matrix_world.inverted() @ camera.data.dof.focus_object.matrix_world.translation
        ).z
    return record


def render_frame(scene, path: Path) -> float:
    scene.render.filepath = str(path)
    start = time.process_time()
    wall = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    wall = time.perf_counter() - wall
    cpu = time.process_time() - start
    print(f"  {path.name}: {wall:.1f} s wall, {cpu:.1f} s cpu", flush=True)
    return wall


def run(args) -> None:
    for name in args.scene:
        out = args.out / name
        out.mkdir(parents=True, exist_ok=True)
        scene = reset_scene()
        extra = SCENES[name](scene)
        scene_frames = SCENE_FRAMES.get(name, FRAMES)
        common_settings(scene, tuple(args.resolution), scene_frames)
        frames = range(args.frames[0], args.frames[1] + 1)
        if args.frames == list(FRAMES):
            frames = range(scene_frames[0], scene_frames[1] + 1)
        moving = {"roll": ["ball", "Camera", "camera_target"],
                  "metal": ["Camera", "moving_area_light"],
                  "production": ["Camera"],
                  "dof": ["ball", "Camera", "camera_target"],
                  "smoke": ["Camera"]}[name]  # fmt: skip
        info = {
            "scene": name,
            "blender": bpy.app.version_string,
            "resolution": list(args.resolution),
            "frames": list(scene_frames),
            "input_seed": args.input_seed,
            "input_sample_offset": args.sample_offset,
            "reference_seed": REF_SEED,
            "reference_spp": args.ref_spp,
            "pass_index": PASS_INDEX[name],
            **extra,
            "per_frame": {},
        }
        for frame in range(scene_frames[0], scene_frames[1] + 1):
            scene.frame_set(frame)
            info["per_frame"][str(frame)] = frame_record(scene, moving)
        if args.what in ("scene", "inputs", "all"):
            (out / "scene.json").write_text(json.dumps(info, indent=1) + "\n")
        if args.what in ("inputs", "all"):
            input_settings(scene, args.codec, args.depth, args.input_seed, args.sample_offset,
                           args.input_spp)
            for frame in frames:
                scene.frame_set(frame)
                render_frame(scene, out / f"{args.prefix}in.{frame:04d}.exr")
        if args.what in ("refs", "all"):
            reference_settings(scene, args.ref_spp)
            for frame in frames:
                scene.frame_set(frame)
                render_frame(scene, out / f"{args.prefix}ref.{frame:04d}.exr")
        if args.what == "preview":
            scene.cycles.samples = args.ref_spp
            scene.render.image_settings.file_format = "PNG"
            for frame in frames:
                scene.frame_set(frame)
                render_frame(scene, out / f"preview.{frame:04d}.png")


def main(argv: list[str]) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", nargs="+", choices=sorted(SCENES), default=["roll", "metal"],
                        help="scenes to render (production: light groups, glass, fog, "
                        "Cryptomatte; dof: roll with depth of field; smoke: a heterogeneous "
                        "volume; these three are rendered only when named)")
    parser.add_argument(
        "--what", choices=["all", "inputs", "refs", "scene", "preview"], default="all"
    )
    parser.add_argument(
        "--frames", type=int, nargs=2, default=list(FRAMES), metavar=("FIRST", "LAST")
    )
    parser.add_argument("--ref-spp", type=int, default=REF_SPP)
    parser.add_argument(
        "--resolution", type=int, nargs=2, default=list(RESOLUTION), metavar=("W", "H")
    )
    parser.add_argument("--codec", default="ZIP", help="EXR codec of the inputs (lossless only)")
    parser.add_argument("--depth", default="16", choices=["16", "32"], help="inputs' half/float")
    parser.add_argument("--out", type=Path, default=HERE)
    parser.add_argument("--prefix", default="", help="file name prefix (for experiments)")
    parser.add_argument("--input-seed", type=int, default=INPUT_SEED,
                        help="Cycles seed of the inputs: another noise realisation of the same "
                        "frames (bench/bias_variance.py)")
    parser.add_argument("--sample-offset", type=int, default=0,
                        help="Cycles sample offset of the inputs: 0 (Blender's default) traces "
                        "the one sample through the pixel centre, 1 or more jitters it over the "
                        "pixel filter")
    parser.add_argument("--input-spp", type=int, default=1,
                        help="samples per pixel of the inputs (the committed fixtures: 1)")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    run(args)
    print(f"done in {time.perf_counter() - start:.0f} s", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
