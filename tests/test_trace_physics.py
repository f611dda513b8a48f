"""svgf trace: the integrator against closed-form answers, with noise bounds from the samples.

Every bound below is k standard errors computed from the per-sample (or per-frame) spread of
the very estimates being checked, so the tests are as tight as the sample count allows and
do not depend on magic tolerances.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from tracescenes import plane_and_lamp

from svgf_trace.animation import Animation, CameraKey, load_animation
from svgf_trace.render import (
    frame_key,
    prepare_frame,
    render_frame,
    trace_batch,
    trace_primary,
)
from svgf_trace.scene import load_obj

TESTDATA = Path(__file__).resolve().parent.parent / "testdata"
SIGMAS = 5.0


def camera(position, look_at, fov=60.0) -> Animation:  # noqa: ANN001 - test helper
    key = CameraKey(0, np.asarray(position, float), np.asarray(look_at, float),
                    np.array([0.0, 1.0, 0.0]), fov)  # fmt: skip
    return Animation([key])


def per_sample_radiance(scene_path: Path, anim: Animation, size: tuple[int, int], spp: int,
                        max_depth: int, seed: int = 0):  # noqa: ANN201 - test helper
    """(spp, H*W, 3) combined radiance samples, plus the G-buffer ids of the primary hits."""
    scene = load_obj(scene_path)
    geo = prepare_frame(scene, anim, 0, size[0], size[1])
    try:
        hits = trace_primary(geo)
        direct, indirect, _ = trace_batch(geo, hits, 0, spp, max_depth, frame_key(seed, 0, 0))
    finally:
        geo.tracer.close()
    return direct + indirect, direct, indirect, hits


def write_furnace(tmp_path: Path, albedo: float, emission: float) -> Path:
    """A closed cube [-1, 1]^3, every face wound to face inwards, all emissive."""
    (tmp_path / "f.mtl").write_text(
        f"newmtl m\nKd {albedo} {albedo} {albedo}\nKe {emission} {emission} {emission}\n"
    )
    corners = [(-1, -1, -1), (1, -1, -1), (1, 1, -1), (-1, 1, -1),
               (-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1)]  # fmt: skip
    faces = [(1, 2, 3, 4), (8, 7, 6, 5), (1, 5, 6, 2), (2, 6, 7, 3), (3, 7, 8, 4), (4, 8, 5, 1)]
    lines = ["mtllib f.mtl", "o box", "usemtl m"]
    lines += [f"v {x} {y} {z}" for x, y, z in corners]
    lines += ["f " + " ".join(map(str, f)) for f in faces]
    (tmp_path / "f.obj").write_text("\n".join(lines) + "\n")
    return tmp_path / "f.obj"


def test_white_furnace_converges_to_le_over_one_minus_albedo(tmp_path: Path) -> None:
    albedo, le = 0.6, 1.0
    path = write_furnace(tmp_path, albedo, le)
    anim = camera([0.2, -0.1, 0.3], [0.0, 0.3, -1.0], fov=100.0)
    for max_depth, spp in ((2, 16), (40, 48)):
        samples, _, _, hits = per_sample_radiance(path, anim, (12, 12), spp, max_depth)
        assert np.all(hits.prim >= 0)  # closed: every ray hits
        # Emission of path vertices 0..max_depth: Le * sum a^k (Russian roulette is
        # unbiased, so only the depth limit truncates the series).
        expected = le * (1 - albedo ** (max_depth + 1)) / (1 - albedo)
        values = samples[:, :, 0].ravel()
        bound = SIGMAS * values.std() / math.sqrt(values.size)
        assert abs(values.mean() - expected) < bound, (max_depth, values.mean(), expected, bound)
        # Grey in, grey out; and every pixel's own mean is plausible too.
        assert np.array_equal(samples[:, :, 0], samples[:, :, 1])
        pixel_means = samples[:, :, 0].mean(axis=0)
        pixel_bound = 6.0 * samples[:, :, 0].std(axis=0).max() / math.sqrt(spp) + 1e-12
        assert np.all(np.abs(pixel_means - expected) < pixel_bound)
    # The deep case is essentially the infinite series Le / (1 - a).
    assert expected == pytest.approx(le / (1 - albedo), rel=1e-8)


def _rectangle_irradiance(x: np.ndarray, z: np.ndarray, height: float, x1: float, x2: float,
                          z1: float, z2: float) -> np.ndarray:
    """Irradiance per unit radiance at floor points (x, 0, z) from a rectangle parallel to the
    floor at ``height``: the configuration factor of a parallel rectangle, times pi, built
    from signed corner rectangles."""

    def corner(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        ah, bh = a / height, b / height
        ra, rb = np.sqrt(1 + ah * ah), np.sqrt(1 + bh * bh)
        return 0.5 * (ah / ra * np.arctan(bh / ra) + bh / rb * np.arctan(ah / rb))

    return (corner(x2 - x, z2 - z) - corner(x1 - x, z2 - z) - corner(x2 - x, z1 - z)
            + corner(x1 - x, z1 - z))  # fmt: skip


def test_direct_lighting_of_a_plane_under_a_square_light(tmp_path: Path) -> None:
    rho, le, half, height = 0.7, 5.0, 0.25, 1.0
    (tmp_path / "p.mtl").write_text(
        f"newmtl floor\nKd {rho} {rho} {rho}\nnewmtl lamp\nKd 0 0 0\nKe {le} {le} {le}\n"
    )
    (tmp_path / "p.obj").write_text(
        "mtllib p.mtl\n"
        "o floor\nusemtl floor\nv -4 0 -4\nv -4 0 4\nv 4 0 4\nv 4 0 -4\nf 1 2 3 4\n"
        # Wound so the normal points down, towards the floor.
        f"o lamp\nusemtl lamp\nv {-half} {height} {-half}\nv {half} {height} {-half}\n"
        f"v {half} {height} {half}\nv {-half} {height} {half}\nf 5 6 7 8\n"
    )
    anim = camera([0.0, 2.5, 2.5], [0.0, 0.0, 0.0], fov=50.0)
    samples, direct, indirect, hits = per_sample_radiance(
        tmp_path / "p.obj", anim, (20, 20), 64, max_depth=1
    )
    # With one bounce everything is direct light.
    assert np.all(indirect == 0.0)
    floor = np.flatnonzero(hits.prim >= 0)
    floor = floor[hits.prim[floor] < 2]  # triangles 0-1 are the floor
    assert floor.size > 200
    origin = hits.origins[floor].astype(np.float64)
    points = origin + hits.directions[floor] * hits.t[floor, None]
    irradiance = le * _rectangle_irradiance(points[:, 0], points[:, 2], height,
                                            -half, half, -half, half)  # fmt: skip
    expected = rho / math.pi * irradiance
    values = samples[:, floor, 0]
    means = values.mean(axis=0)
    errors = values.std(axis=0) / math.sqrt(values.shape[0])
    # Per pixel within its own noise (NEE makes these tight), and in aggregate.
    assert np.all(np.abs(means - expected) <= SIGMAS * errors + 1e-6 * expected)
    total_error = math.sqrt(float((errors**2).sum()))
    assert abs(means.sum() - expected.sum()) < SIGMAS * total_error
    assert expected.max() > 5 * expected.min()  # the falloff is really being tested


def test_direct_plus_indirect_is_combined_and_split_is_by_bounce(tmp_path: Path) -> None:
    path = write_furnace(tmp_path, 0.5, 1.0)
    anim = camera([0.0, 0.0, 0.5], [0.0, 0.0, -1.0], fov=90.0)
    samples, direct, indirect, _ = per_sample_radiance(path, anim, (6, 6), 32, max_depth=4)
    assert np.array_equal(samples, direct + indirect)
    # Direct = primary emission + one bounce of light: Le (1 + a); indirect the rest.
    d = direct[:, :, 0].ravel()
    i = indirect[:, :, 0].ravel()
    assert abs(d.mean() - 1.5) < SIGMAS * d.std() / math.sqrt(d.size)
    expected_indirect = 0.25 + 0.125 + 0.0625
    assert abs(i.mean() - expected_indirect) < SIGMAS * i.std() / math.sqrt(i.size)


def test_mean_of_one_spp_frames_matches_the_reference() -> None:
    """Static Cornell box: frames differ only in their seeds, so the mean of N 1-spp frames
    estimates the same image as the reference (which uses an independent stream)."""
    scene = load_obj(TESTDATA / "cornell.obj")
    names = [o.name for o in scene.objects]
    static = Animation(load_animation(TESTDATA / "anim.json", names).camera_keys[:1])
    size = (16, 9)
    frames = []
    reference = None
    for frame in range(1, 41):
        result, ref = render_frame(scene, static, frame, *size, spp=1, max_depth=3, seed=7,
                                   reference_spp=256 if frame == 1 else 0)  # fmt: skip
        frames.append(result.direct + result.indirect)
        if ref is not None:
            reference = ref.direct + ref.indirect
    assert reference is not None
    stack = np.stack(frames).astype(np.float64)
    mean = stack.mean(axis=0)
    # Standard error of the difference: the frames' spread plus the reference's own noise
    # (256 samples of the same per-sample variance).
    var = stack.var(axis=0, ddof=1)
    se_total = math.sqrt(float(var.sum() * (1 / len(frames) + 1 / 256)))
    assert abs(mean.sum() - reference.sum()) < SIGMAS * se_total
    assert reference.mean() > 0.01  # a lit image, not zeros on both sides
    # Reference and frames are different sample streams.
    assert not np.array_equal(frames[0], reference)


def test_moving_and_dimming_a_light_moves_and_scales_what_it_lights(tmp_path: Path) -> None:
    """Next-event estimation samples the light where the animation puts it, with the
    animated emission: the lit spot follows the lamp and scales with emission_scale."""
    rho, le, half, height, shift = 0.7, 5.0, 0.25, 1.0, 0.8
    path = plane_and_lamp(tmp_path, floor_mtl=f"Kd {rho} {rho} {rho}", le=le, half=half,
                          height=height)  # fmt: skip
    scene = load_obj(path)
    (tmp_path / "a.json").write_text(json.dumps({
        "camera": [{"frame": 0, "position": [0.4, 3.0, 2.5], "look_at": [0.4, 0.0, 0.0],
                    "fov_y": 55.0}],
        "objects": {"lamp": [{"frame": 0, "translate": [0, 0, 0]},
                             {"frame": 1, "translate": [shift, 0, 0], "emission_scale": 1.0},
                             {"frame": 2, "emission_scale": 0.45}]},
    }))  # fmt: skip
    anim = load_animation(tmp_path / "a.json", [o.name for o in scene.objects])
    for frame, offset, scale in ((0, 0.0, 1.0), (1, shift, 1.0), (2, shift, 0.45)):
        geo = prepare_frame(scene, anim, frame, 24, 20)
        try:
            hits = trace_primary(geo)
            direct, indirect, _ = trace_batch(geo, hits, 0, 48, 1, frame_key(0, frame, 0))
        finally:
            geo.tracer.close()
        floor = np.flatnonzero((hits.prim >= 0) & (hits.prim < 2))
        points = hits.origins[floor] + hits.directions[floor] * hits.t[floor, None]
        irradiance = scale * le * _rectangle_irradiance(
            points[:, 0], points[:, 2], height, offset - half, offset + half, -half, half
        )
        expected = rho / math.pi * irradiance
        values = direct[:, floor, 0]
        means = values.mean(axis=0)
        errors = values.std(axis=0) / math.sqrt(values.shape[0])
        assert np.all(np.abs(means - expected) <= SIGMAS * errors + 1e-6 * expected), frame
        if frame == 1:
            # ... and not where the lamp was: the unmoved lamp's image is far off.
            unmoved = rho / math.pi * le * _rectangle_irradiance(
                points[:, 0], points[:, 2], height, -half, half, -half, half
            )
            assert np.mean(np.abs(means - unmoved) > SIGMAS * errors + 0.01 * unmoved) > 0.5
        # The lamp's own emission (what a camera facing it, and the emission layer, see).
        assert np.array_equal(geo.tri_ke[2:], np.full((2, 3), scale * le))
