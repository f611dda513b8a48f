"""svgf trace --gradient-samples: A-SVGF temporal gradient samples.

A sample re-shades last frame's surface point with last frame's random numbers, so where the
scene did not change it reproduces last frame's value exactly, where only the light changed
it changes by exactly the light's factor, and ``prev`` is what the previous frame traced.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from tracescenes import (
    REC709,
    TESTDATA,
    copy_cornell,
    cornell_camera,
    glossy_cornell,
    read_exr,
    write_animation,
)

from svgf_cli.cli import main
from svgf_trace.animation import Animation, load_animation
from svgf_trace.gradients import gradient_samples
from svgf_trace.render import prepare_frame, render_frame, trace_primary
from svgf_trace.scene import load_obj

WIDTH, HEIGHT = 48, 27


def samples_for(scene_path: Path, anim_path: Path | None, frame: int, *, spp: int = 1,
                lobes: bool = False):  # noqa: ANN201 - test helper  # fmt: skip
    scene = load_obj(scene_path)
    names = [o.name for o in scene.objects]
    anim = load_animation(anim_path, names) if anim_path else Animation()
    geo = prepare_frame(scene, anim, frame, WIDTH, HEIGHT)
    try:
        samples = gradient_samples(scene, anim, geo, spp=spp, max_depth=4, seed=3, lobes=lobes)
        samples.visible_pixels = int((trace_primary(geo).prim >= 0).sum())
    finally:
        geo.tracer.close()
    return scene, anim, samples


def test_static_scene_reshades_exactly_and_density_is_one_ninth(tmp_path: Path) -> None:
    anim = write_animation(tmp_path / "a.json", {"camera": cornell_camera()})
    _, _, samples = samples_for(TESTDATA / "cornell_checker.obj", anim, 5, spp=2)
    # About one sample per nine visible pixels (strata on silhouettes count partly).
    assert 0.09 < samples.source_pixel.size / samples.visible_pixels < 0.125
    for name in ("direct", "indirect"):
        assert np.array_equal(samples.curr[name], samples.prev[name]), name
        assert samples.prev[name].max() > 0
    # Nothing moved: every sample lands on the pixel it came from, one per stratum.
    assert np.array_equal(samples.target_pixel, samples.source_pixel)
    x, y = samples.source_pixel % WIDTH, samples.source_pixel // WIDTH
    stratum = (y // 3) * math.ceil(WIDTH / 3) + x // 3
    assert np.unique(stratum).size == stratum.size
    # The choice inside each stratum is spread over all nine positions.
    assert np.unique((y % 3) * 3 + x % 3).size == 9


def test_dimmed_light_scales_every_sample_by_its_factor(tmp_path: Path) -> None:
    obj = copy_cornell(tmp_path)
    anim = write_animation(tmp_path / "a.json", {
        "camera": cornell_camera(),
        "objects": {"light": [{"frame": 4, "emission_scale": 1.0},
                              {"frame": 5, "emission_scale": 0.45}]},
    })  # fmt: skip
    _, _, samples = samples_for(obj, anim, 5)
    for name, share in (("direct", 0.5), ("indirect", 0.3)):  # 1 spp: shadows, escapes
        prev, curr = samples.prev[name], samples.curr[name]
        lit = prev > 1e-6
        assert lit.mean() > share
        np.testing.assert_allclose(curr[lit], 0.45 * prev[lit], rtol=1e-5)
        assert np.all(curr[~lit] == 0)
    # The frame after the step is static again: no change.
    _, _, after = samples_for(obj, anim, 6)
    assert np.array_equal(after.curr["direct"], after.prev["direct"])


def test_prev_is_the_previous_frame_and_samples_land_on_the_moved_point(tmp_path: Path) -> None:
    """Camera and object motion (the bundled animation at frame 20): ``prev`` equals the
    previous frame's traced pixel, and the sample sits where its surface point moved to,
    computed here from the previous frame's P layer and the object transforms."""
    frame = 20
    anim_path = TESTDATA / "anim.json"
    scene, anim, samples = samples_for(TESTDATA / "cornell.obj", anim_path, frame)
    previous, _ = render_frame(scene, anim, frame - 1, WIDTH, HEIGHT, 1, 4, 3)
    direct = previous.direct.reshape(-1, 3).astype(np.float64) @ REC709
    indirect = previous.indirect.reshape(-1, 3).astype(np.float64) @ REC709
    np.testing.assert_allclose(samples.prev["direct"], direct[samples.source_pixel], rtol=1e-6,
                               atol=1e-9)  # fmt: skip
    np.testing.assert_allclose(samples.prev["indirect"], indirect[samples.source_pixel],
                               rtol=1e-6, atol=1e-9)  # fmt: skip

    points = previous.layers["P"].reshape(-1, 3)[samples.source_pixel].astype(np.float64)
    ids = previous.layers["id"].reshape(-1)[samples.source_pixel].astype(int)
    moved = points.copy()
    for obj in scene.objects:
        pts = scene.positions[obj.start : obj.stop].reshape(-1, 3)
        pivot = (pts.min(0) + pts.max(0)) / 2
        carry = anim.object_matrix(obj.name, frame, pivot) @ np.linalg.inv(
            anim.object_matrix(obj.name, frame - 1, pivot)
        )
        mask = ids == obj.index
        moved[mask] = points[mask] @ carry[:3, :3].T + carry[:3, 3]
    cam = anim.camera(frame, WIDTH, HEIGHT)
    expected = cam.project(moved)
    assert np.abs(samples.position - expected).max() < 1e-2
    target = np.floor(expected[:, 1]).astype(int) * WIDTH + np.floor(expected[:, 0]).astype(int)
    exact = np.abs(expected - np.round(expected)).min(axis=1) > 1e-2  # not on a pixel border
    assert np.array_equal(samples.target_pixel[exact], target[exact])
    # The short block moves and the camera moves: real motion, and the lit static walls
    # changed only through the camera (their diffuse direct light is the same).
    shift = np.linalg.norm(expected - (np.stack([samples.source_pixel % WIDTH,
                                                 samples.source_pixel // WIDTH], 1) + 0.5),
                           axis=1)  # fmt: skip
    assert np.median(shift) > 0.05
    walls = np.isin(ids, [2, 3, 4])  # Lambertian and static: only the view changed
    assert np.array_equal(samples.curr["direct"][walls], samples.prev["direct"][walls])


def test_cli_writes_the_gradient_layer(tmp_path: Path) -> None:
    scene = glossy_cornell(tmp_path, {"white": "Pr 0.3"})
    anim = write_animation(tmp_path / "a.json", {
        "camera": cornell_camera(),
        "objects": {"light": [{"frame": 1, "emission_scale": 1.0},
                              {"frame": 2, "emission_scale": 0.45}]},
    })  # fmt: skip
    out = tmp_path / "g.####.exr"
    with pytest.raises(SystemExit) as info:
        main(["trace", str(scene), "-o", str(out), "--frames", "1-2", "--resolution",
              f"{WIDTH}x{HEIGHT}", "--max-depth", "3", "--gradient-samples", "--lobes",
              "--animation", str(anim), "--float", "-q"])  # fmt: skip
    assert info.value.code == 0
    layers, spec = read_exr(tmp_path / "g.0002.exr")
    assert spec.getattribute("svgf/gradient/stratum") == 3
    names = {f"gradient.{s}.{w}" for s in ("direct", "indirect", "diffuse", "glossy")
             for w in ("prev", "curr")}  # fmt: skip
    assert names | {"gradient.mask"} <= set(layers)
    formats = {n: str(spec.channelformat(k)) for k, n in enumerate(spec.channelnames)}
    assert all(formats[n] == "float" for n in names)
    mask = layers["gradient.mask"]
    assert set(np.unique(mask)) == {0.0, 1.0}
    visible = (layers["id"] >= 0).sum()
    assert 0.08 < mask.sum() / visible < 0.12
    on = mask == 1
    for name in names:
        assert np.all(layers[name][~on] == 0)
    for signal in ("direct", "indirect", "diffuse", "glossy"):
        prev, curr = layers[f"gradient.{signal}.prev"][on], layers[f"gradient.{signal}.curr"][on]
        lit = prev > 1e-6
        assert lit.mean() > 0.2, signal
        np.testing.assert_allclose(curr[lit], 0.45 * prev[lit], rtol=1e-5, err_msg=signal)
    # The lobes split the same light: diffuse + glossy = direct + indirect off the light.
    off_light = on & (layers["emission.R"] == 0)
    total = layers["gradient.direct.prev"] + layers["gradient.indirect.prev"]
    lobes = layers["gradient.diffuse.prev"] + layers["gradient.glossy.prev"]
    np.testing.assert_allclose(lobes[off_light], total[off_light], rtol=1e-5, atol=1e-7)
    # Frame 1 is compared with frame 0, which the animation holds equal to it.
    first, _ = read_exr(tmp_path / "g.0001.exr")
    on1 = first["gradient.mask"] == 1
    assert np.array_equal(first["gradient.direct.curr"][on1], first["gradient.direct.prev"][on1])
