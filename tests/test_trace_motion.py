"""svgf trace: motion vectors and camera matrices agree with an independent reprojection."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from tracescenes import read_exr

from svgf_cli.cli import main
from svgf_trace.animation import load_animation
from svgf_trace.scene import load_obj

TESTDATA = Path(__file__).resolve().parent.parent / "testdata"
WIDTH, HEIGHT = 64, 36


def project(camera_key_position, look_at, up, fov_y, points):  # noqa: ANN001, ANN201
    """Pinhole projection written out independently of svgf_trace.camera."""
    forward = np.asarray(look_at, float) - np.asarray(camera_key_position, float)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    rel = points - camera_key_position
    x, y, z = rel @ right, rel @ true_up, rel @ forward
    tan_y = math.tan(math.radians(fov_y) / 2)
    tan_x = tan_y * WIDTH / HEIGHT
    px = (x / (z * tan_x) + 1) / 2 * WIDTH
    py = (1 - y / (z * tan_y)) / 2 * HEIGHT
    return np.stack([px, py], axis=-1)


@pytest.fixture(scope="module")
def animated_frames(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("motion")
    with pytest.raises(SystemExit) as info:
        main([
            "trace", str(TESTDATA / "cornell.obj"), "-o", str(out / "m.####.exr"),
            "--frames", "1,6", "--resolution", f"{WIDTH}x{HEIGHT}", "--spp", "1",
            "--max-depth", "0", "--animation", str(TESTDATA / "anim.json"), "--motion-next",
            "-q",
        ])  # fmt: skip
    assert info.value.code == 0
    return out


def expected_motion(layers: dict[str, np.ndarray], frame: int, other: int) -> np.ndarray:
    """Pixel offsets, written out independently: each pixel's world point (P layer) carried
    by its object's transforms from ``frame`` to ``other`` and projected with ``other``'s
    camera, minus the pixel centre."""
    scene = load_obj(TESTDATA / "cornell.obj")
    anim = load_animation(TESTDATA / "anim.json", [o.name for o in scene.objects])
    ids = layers["id"].astype(int)
    points = np.stack([layers["P.X"], layers["P.Y"], layers["P.Z"]], axis=-1).astype(np.float64)
    moved = points.copy()
    for obj in scene.objects:
        pts = scene.positions[obj.start : obj.stop].reshape(-1, 3)
        pivot = (pts.min(0) + pts.max(0)) / 2
        now = anim.object_matrix(obj.name, frame, pivot)
        then = anim.object_matrix(obj.name, other, pivot)
        carry = then @ np.linalg.inv(now)
        mask = ids == obj.index
        moved[mask] = points[mask] @ carry[:3, :3].T + carry[:3, 3]
    cam = anim.camera(other, WIDTH, HEIGHT)
    pixels = project(cam.position, cam.look_at, cam.up, cam.fov_y, moved)
    ys, xs = np.mgrid[0:HEIGHT, 0:WIDTH]
    return pixels - np.stack([xs + 0.5, ys + 0.5], axis=-1)


def test_motion_matches_reprojection_of_world_positions(animated_frames: Path) -> None:
    layers, _ = read_exr(animated_frames / "m.0006.exr")
    scene = load_obj(TESTDATA / "cornell.obj")
    ids = layers["id"].astype(int)
    hit = ids >= 0
    assert hit.mean() > 0.5
    expected = expected_motion(layers, 6, 5)
    motion = np.stack([layers["motion.X"], layers["motion.Y"]], axis=-1)
    error = np.abs(motion - expected)[hit]
    assert error.max() < 0.01, error.max()
    # Both kinds of motion are really present: the camera moves every static surface, and
    # the short block moves differently from the tall one next to it.
    magnitude = np.linalg.norm(motion, axis=-1)
    short = scene.object_by_name("short_block").index  # type: ignore[union-attr]
    tall = scene.object_by_name("tall_block").index  # type: ignore[union-attr]
    assert np.median(magnitude[ids == tall]) > 0.02
    assert np.median(magnitude[ids == short]) > 3 * np.median(magnitude[ids == tall])
    # Background: no motion, -1 id, infinite depth.
    assert np.all(motion[~hit] == 0) and np.all(np.isinf(layers["Z"][~hit]))


def test_header_matrices_project_positions_to_pixel_centres(animated_frames: Path) -> None:
    layers, spec = read_exr(animated_frames / "m.0006.exr")
    hit = layers["id"] >= 0
    points = np.stack([layers["P.X"], layers["P.Y"], layers["P.Z"]], axis=-1)[hit]
    homogeneous = np.concatenate([points, np.ones((points.shape[0], 1))], axis=1)
    # OpenEXR matrices are Imath row-vector matrices: p_row @ M.
    to_ndc = np.array(spec.getattribute("worldToNDC"), dtype=np.float64).reshape(4, 4)
    ndc = homogeneous @ to_ndc
    pixels = np.stack([ndc[:, 0] / ndc[:, 3] * WIDTH, ndc[:, 1] / ndc[:, 3] * HEIGHT], axis=1)
    ys, xs = np.mgrid[0:HEIGHT, 0:WIDTH]
    centres = np.stack([xs + 0.5, ys + 0.5], axis=-1)[hit]
    assert np.abs(pixels - centres).max() < 1e-3
    # worldToCamera: +z is the view axis and its z is the Z layer (linear view depth).
    to_camera = np.array(spec.getattribute("worldToCamera"), dtype=np.float64).reshape(4, 4)
    camera_space = homogeneous @ to_camera
    np.testing.assert_allclose(camera_space[:, 2], layers["Z"][hit], rtol=1e-5)
    assert spec.getattribute("svgf/motion_convention") == "backward-pixels"


def test_first_frame_and_static_scenes_have_zero_motion(
    animated_frames: Path, tmp_path: Path
) -> None:
    layers, _ = read_exr(animated_frames / "m.0001.exr")
    assert np.all(layers["motion.X"] == 0) and np.all(layers["motion.Y"] == 0)
    with pytest.raises(SystemExit) as info:
        main(["trace", str(TESTDATA / "cornell.obj"), "-o", str(tmp_path / "s.####.exr"),
              "--frames", "3", "--resolution", "16x9", "--max-depth", "0", "-q"])  # fmt: skip
    assert info.value.code == 0
    static, _ = read_exr(tmp_path / "s.0003.exr")
    assert np.all(static["motion.X"] == 0) and np.all(static["motion.Y"] == 0)
    assert (static["id"] >= 0).any()


def test_motion_next_matches_reprojection_into_the_next_frame(animated_frames: Path) -> None:
    layers, spec = read_exr(animated_frames / "m.0006.exr")
    assert spec.getattribute("svgf/motion_next_convention") == "forward-pixels"
    hit = layers["id"] >= 0
    expected = expected_motion(layers, 6, 7)
    motion_next = np.stack([layers["motion_next.X"], layers["motion_next.Y"]], axis=-1)
    error = np.abs(motion_next - expected)[hit]
    assert error.max() < 0.01, error.max()
    # It really is the other direction: between frames 5, 6 and 7 the motion is nearly
    # uniform, so forward motion is close to minus the backward motion, not equal to it.
    motion = np.stack([layers["motion.X"], layers["motion.Y"]], axis=-1)
    opposite = np.median(np.linalg.norm(motion_next + motion, axis=-1)[hit])
    same = np.median(np.linalg.norm(motion_next - motion, axis=-1)[hit])
    assert opposite < 0.1 * same, (opposite, same)
    assert np.all(motion_next[~hit] == 0)


def test_motion_next_is_zero_where_nothing_moves_on(tmp_path: Path) -> None:
    # Frame 48 is the animation's last key: the next frame holds still.
    with pytest.raises(SystemExit) as info:
        main(["trace", str(TESTDATA / "cornell.obj"), "-o", str(tmp_path / "e.####.exr"),
              "--frames", "48", "--resolution", "16x9", "--max-depth", "0", "--motion-next",
              "--animation", str(TESTDATA / "anim.json"), "-q"])  # fmt: skip
    assert info.value.code == 0
    last, _ = read_exr(tmp_path / "e.0048.exr")
    assert np.all(last["motion_next.X"] == 0) and np.all(last["motion_next.Y"] == 0)
    assert np.any(last["motion.X"] != 0)
