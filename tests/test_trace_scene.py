"""svgf trace: OBJ/MTL loading at full precision, textures, animation files, clear errors."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from svgf_cli.errors import InputError
from svgf_trace import render
from svgf_trace.animation import Animation, CameraKey, load_animation
from svgf_trace.render import gbuffer, prepare_frame, trace_primary, world_vertices
from svgf_trace.scene import load_obj

TESTDATA = Path(__file__).resolve().parent.parent / "testdata"


def write_image(path: Path, pixels: np.ndarray, fmt: str) -> None:
    h, w, c = pixels.shape
    out = oiio.ImageOutput.create(str(path))
    assert out is not None
    assert out.open(str(path), oiio.ImageSpec(w, h, c, fmt))
    assert out.write_image(np.ascontiguousarray(pixels))
    assert out.close()


def test_cornell_box_loads_objects_and_exact_materials() -> None:
    scene = load_obj(TESTDATA / "cornell.obj")
    names = [o.name for o in scene.objects]
    assert names == [
        "floor", "ceiling", "back_wall", "left_wall", "right_wall", "light",
        "short_block", "tall_block",
    ]  # fmt: skip
    assert scene.triangle_count == 38
    by_name = {m.name: m for m in scene.materials}
    # Full precision, not 8-bit colour: 0.725 would come back as 185/255 = 0.7255 otherwise.
    assert by_name["white"].kd.tolist() == [0.725, 0.71, 0.68]
    assert by_name["green"].kd.tolist() == [0.14, 0.45, 0.091]
    assert by_name["light"].ke.tolist() == [17.0, 12.0, 4.0]
    assert not by_name["white"].emissive
    # The light is wound to face down (it emits on that side only).
    light = scene.object_by_name("light")
    assert light is not None
    tris = scene.positions[light.start : light.stop]
    normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    assert np.all(normals[:, 1] < 0) and np.allclose(normals[:, [0, 2]], 0)
    lo, hi = scene.bounds()
    assert np.allclose(lo, [0, 0, 0]) and np.allclose(hi, [556.0, 548.8, 559.2])


def test_obj_polygons_negative_indices_groups_and_normals(tmp_path: Path) -> None:
    (tmp_path / "m.mtl").write_text("newmtl a\nKd 0.1 0.2 0.3\nnewmtl b\nKd 0.5 0.5 0.5\n")
    (tmp_path / "s.obj").write_text(
        "mtllib m.mtl\n"
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 1.5 0\n"
        "vn 0 0 1\nvn 0 0.6 0.8\n"
        "o first\nusemtl a\n"
        "f 1//1 2//1 3//2 4//2 5//1\n"  # a pentagon: 3 fan triangles
        "g second\nusemtl b\n"
        "f -5 -4 -3\n"  # negative indices: vertices 1 2 3
        "o first\n"
        "f 1 3 4\n"  # resumes object "first"
    )
    scene = load_obj(tmp_path / "s.obj")
    assert [o.name for o in scene.objects] == ["first", "second"]
    first, second = scene.objects
    assert first.stop - first.start == 4 and second.stop - second.start == 1
    # Fan triangulation keeps the corner order (and so the winding).
    assert scene.positions[0].tolist() == [[0, 0, 0], [1, 0, 0], [1, 1, 0]]
    assert scene.positions[2].tolist() == [[0, 0, 0], [0, 1, 0], [0.5, 1.5, 0]]
    assert scene.has_normals[:3].all() and not scene.has_normals[3]
    assert scene.normals[0, 2].tolist() == [0.0, 0.6, 0.8]
    assert second.start == 4 and scene.material[4] == 1
    assert scene.materials[scene.material[0]].kd.tolist() == [0.1, 0.2, 0.3]


def _textured_quad(tmp_path: Path, texture_name: str) -> Path:
    (tmp_path / "t.mtl").write_text(f"newmtl tex\nKd 1 0.5 0.25\nmap_Kd {texture_name}\n")
    (tmp_path / "t.obj").write_text(
        "mtllib t.mtl\no quad\nusemtl tex\n"
        "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n"
        "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
        "f 1/1 2/2 3/3 4/4\n"
    )
    return tmp_path / "t.obj"


def test_albedo_is_kd_times_bilinear_texture(tmp_path: Path) -> None:
    # A float (linear) 2x2 texture on a quad that exactly fills a square view.
    texels = np.array([[[1, 0, 0], [0, 1, 0]], [[0, 0, 1], [1, 1, 1]]], dtype=np.float32)
    write_image(tmp_path / "tex.exr", texels, "float")
    scene = load_obj(_textured_quad(tmp_path, "tex.exr"))
    size = 8
    distance = 3.0
    fov = math.degrees(2 * math.atan(1.0 / distance))
    anim = Animation([CameraKey(0, np.array([0, 0, distance]), np.zeros(3),
                                np.array([0.0, 1, 0]), fov)])  # fmt: skip
    geo = prepare_frame(scene, anim, 0, size, size)
    layers = gbuffer(geo, trace_primary(geo))
    geo.tracer.close()
    # Expected: u = (x + 0.5) / size, v = 1 - (y + 0.5) / size; texel row 0 is the top.
    coords = (np.arange(size) + 0.5) / size * 2 - 0.5  # texel space, wrap-around
    expected = np.zeros((size, size, 3))
    for yi, ty in enumerate(coords):
        for xi, tx in enumerate(coords):
            x0, y0 = math.floor(tx), math.floor(ty)
            fx, fy = tx - x0, ty - y0
            value = np.zeros(3)
            for dy, wy in ((0, 1 - fy), (1, fy)):
                for dx, wx in ((0, 1 - fx), (1, fx)):
                    value += wx * wy * texels[(y0 + dy) % 2, (x0 + dx) % 2]
            expected[yi, xi] = value * [1, 0.5, 0.25]
    np.testing.assert_allclose(layers["albedo"], expected, atol=1e-5)


def test_eight_bit_texture_is_decoded_from_srgb(tmp_path: Path) -> None:
    write_image(tmp_path / "grey.png", np.full((2, 2, 3), 188, dtype=np.uint8), "uint8")
    scene = load_obj(_textured_quad(tmp_path, "grey.png"))
    texture = scene.materials[0].texture
    assert texture is not None
    srgb = 188 / 255
    assert texture[0, 0, 0] == pytest.approx(((srgb + 0.055) / 1.055) ** 2.4, rel=1e-6)


@pytest.mark.parametrize(
    ("obj", "mtl", "message"),
    [
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", None, "no faces"),
        ("mtllib m.mtl\nusemtl x\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
         "newmtl x\nmap_Kd missing_tex.png\n", "missing_tex.png"),
        ("usemtl nope\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", None, "'nope'"),
        ("v 0 0 0\nv 1 0 0\nf 1 2 7\n", None, "line 3: vertex index 7 out of range"),
        ("mtllib gone.mtl\n", None, "gone.mtl"),
    ],
)  # fmt: skip
def test_bad_scenes_raise_input_errors_naming_the_problem(
    tmp_path: Path, obj: str, mtl: str | None, message: str
) -> None:
    (tmp_path / "s.obj").write_text(obj)
    if mtl is not None:
        (tmp_path / "m.mtl").write_text(mtl)
    with pytest.raises(InputError) as info:
        load_obj(tmp_path / "s.obj")
    assert message in str(info.value)
    assert info.value.exit_code == 3


def test_missing_scene_file() -> None:
    with pytest.raises(InputError, match="scene file not found"):
        load_obj("/nonexistent/scene.obj")


def test_animation_interpolates_camera_and_objects() -> None:
    scene = load_obj(TESTDATA / "cornell.obj")
    anim = load_animation(TESTDATA / "anim.json", [o.name for o in scene.objects])
    data = json.loads((TESTDATA / "anim.json").read_text())
    first = data["camera"][0]
    cam1 = anim.camera(1, 64, 36)
    assert np.allclose(cam1.position, first["position"]) and cam1.fov_y == first["fov_y"]
    mid = anim.camera(24.5, 64, 36)
    last = np.array(data["camera"][1]["position"])
    assert np.allclose(mid.position, (np.array(first["position"]) + last) / 2)
    # Frames outside the keys hold the end keys.
    assert np.allclose(anim.camera(-5, 64, 36).position, first["position"])

    block = scene.object_by_name("short_block")
    assert block is not None
    pts = scene.positions[block.start : block.stop].reshape(-1, 3)
    pivot = (pts.min(0) + pts.max(0)) / 2
    m24 = anim.object_matrix("short_block", 24, pivot)
    angle = math.radians(35)
    # Rotation about +y by 35 degrees about the block's centre, then translated.
    assert np.allclose(m24[:3, :3], [[math.cos(angle), 0, math.sin(angle)], [0, 1, 0],
                                     [-math.sin(angle), 0, math.cos(angle)]])  # fmt: skip
    assert np.allclose(m24[:3, :3] @ pivot + m24[:3, 3], pivot + [60, 0, 50])
    # Half way between keys: half the angle (slerp) and half the translation.
    m12 = anim.object_matrix("short_block", 12.5, pivot)
    assert np.allclose(m12[:3, 3] + m12[:3, :3] @ pivot, pivot + [30, 0, 25])
    assert math.degrees(math.atan2(m12[0, 2], m12[0, 0])) == pytest.approx(17.5)
    # world_vertices applies it to exactly that object's triangles.
    verts, _ = world_vertices(scene, anim, 24)
    assert np.array_equal(verts[: block.start], scene.positions[: block.start])
    moved = slice(block.start, block.stop)
    assert not np.allclose(verts[moved], scene.positions[moved])


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("{not json", "invalid JSON"),
        ('{"objects": {"teapot": []}}', "object 'teapot' is not in the scene"),
        ('{"camera": [{"frame": 1, "position": [0, 0, 0]}]}', 'missing "look_at"'),
        ('{"camera": [{"position": [0, 0, 1], "look_at": [0, 0, 0]}]}', 'needs a "frame"'),
        ('{"objects": {"floor": [{"frame": 1, "translate": [1, 2]}]}}', "translate"),
    ],
)
def test_bad_animation_files(tmp_path: Path, content: str, message: str) -> None:
    path = tmp_path / "a.json"
    path.write_text(content)
    with pytest.raises(InputError) as info:
        load_animation(path, ["floor"])
    assert message in str(info.value) and "a.json" in str(info.value)


def test_emission_keys_are_their_own_track(tmp_path: Path) -> None:
    path = TESTDATA / "cornell.obj"
    scene = load_obj(path)
    names = [o.name for o in scene.objects]
    data = {"objects": {"light": [
        {"frame": 1, "translate": [0, 0, 0]},
        {"frame": 9, "emission_scale": 1.0},
        {"frame": 10, "emission_scale": 0.45},
        {"frame": 17, "translate": [-160, 0, 0], "emission_scale": [0.45, 0.45, 0.9]},
    ]}}  # fmt: skip
    (tmp_path / "a.json").write_text(json.dumps(data))
    anim = load_animation(tmp_path / "a.json", names)
    pivot = np.zeros(3)
    # The emission-only keys leave the slide alone: linear from frame 1 to frame 17.
    assert np.allclose(anim.object_matrix("light", 9, pivot)[:3, 3], [-80, 0, 0])
    # A step between consecutive keys; before the first key the first holds; linear after.
    assert np.array_equal(anim.emission_scale("light", 1), np.ones(3))
    assert np.array_equal(anim.emission_scale("light", 9), np.ones(3))
    assert np.allclose(anim.emission_scale("light", 10), 0.45)
    assert np.allclose(anim.emission_scale("light", 13.5), [0.45, 0.45, 0.675])
    assert np.allclose(anim.emission_scale("light", 30), [0.45, 0.45, 0.9])
    assert np.array_equal(anim.emission_scale("floor", 10), np.ones(3))
    # The frame's triangles carry it (only the light's).
    tri_ke = render.triangle_emission(scene, anim, 10)
    light = scene.object_by_name("light")
    assert light is not None
    assert np.allclose(tri_ke[light.start : light.stop], [17 * 0.45, 12 * 0.45, 4 * 0.45])
    assert np.all(tri_ke[: light.start] == 0)


@pytest.mark.parametrize(
    ("key", "message"),
    [('{"frame": 1, "emission_scale": -1}', "must not be negative"),
     ('{"frame": 1, "emission_scale": [1, 2]}', "emission_scale: expected 3"),
     ('{"frame": 1, "emission_scale": "dim"}', "emission_scale")],
)  # fmt: skip
def test_bad_emission_keys(tmp_path: Path, key: str, message: str) -> None:
    path = tmp_path / "a.json"
    path.write_text('{"objects": {"light": [' + key + "]}}")
    with pytest.raises(InputError) as info:
        load_animation(path, ["light"])
    assert message in str(info.value) and "objects.light[0]" in str(info.value)
