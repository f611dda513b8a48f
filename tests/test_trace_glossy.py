"""svgf trace: the glossy material (GGX over a diffuse base, metals) and its MTL keys.

Energy and sampling are checked against quadratures written here, independently of the
tables the BRDF uses; the integrator's three strategies (MIS, BSDF only, light only) must
estimate the same image; a smooth metal must be a mirror.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from tracescenes import cornell_camera, glossy_cornell, plane_and_lamp

from svgf_cli.errors import InputError
from svgf_trace import bsdf, kernels
from svgf_trace.animation import Animation, CameraKey, load_animation
from svgf_trace.render import frame_key, prepare_frame, trace_batch, trace_primary
from svgf_trace.scene import load_obj

SIGMAS = 5.0


def test_mtl_keys_decide_the_material(tmp_path: Path) -> None:
    (tmp_path / "m.mtl").write_text(
        "newmtl plain\nKd 0.5 0.5 0.5\n"
        "newmtl pbr\nKd 0.8 0.2 0.1\nPr 0.3\nPm 0.25\n"
        "newmtl metal_ns\nPm 1\nNs 250\n"
        "newmtl phong\nKs 0.5 0.5 0.5\nNs 810\n"
        "newmtl phong_matte\nKs 0.5 0.5 0.5\nNs 100\nillum 1\n"
        "newmtl no_spec\nKs 0 0 0\nNs 500\n"
        "newmtl bright_spec\nPr 0.2\nKs 1 1 1\n"
    )
    lines = ["mtllib m.mtl", "v 0 0 0", "v 1 0 0", "v 0 1 0"]
    for name in ("plain", "pbr", "metal_ns", "phong", "phong_matte", "no_spec", "bright_spec"):
        lines += [f"o {name}", f"usemtl {name}", "f 1 2 3"]
    (tmp_path / "s.obj").write_text("\n".join(lines) + "\n")
    mats = {m.name: m for m in load_obj(tmp_path / "s.obj").materials}
    assert not mats["plain"].glossy
    assert mats["pbr"].glossy and mats["pbr"].roughness == 0.3 and mats["pbr"].metallic == 0.25
    assert mats["pbr"].dielectric_f0 == pytest.approx(0.04)
    # Pm alone: roughness from Ns with Blender's mapping 1 - sqrt(Ns / 1000).
    assert mats["metal_ns"].glossy and mats["metal_ns"].metallic == 1.0
    assert mats["metal_ns"].roughness == pytest.approx(0.5)
    # Classic Phong keys: glossy dielectric, F0 = 0.08 mean(Ks).
    assert mats["phong"].glossy and mats["phong"].metallic == 0.0
    assert mats["phong"].roughness == pytest.approx(0.1)
    assert mats["phong"].dielectric_f0 == pytest.approx(0.04)
    assert not mats["phong_matte"].glossy  # illum 1: no highlights
    assert not mats["no_spec"].glossy
    assert mats["bright_spec"].dielectric_f0 == pytest.approx(0.08)


@pytest.mark.parametrize(("line", "message"), [("Pr 1.5", "Pr 1.5 is not in [0, 1]"),
                                               ("Pm -1", "Pm -1.0 is not in [0, 1]"),
                                               ("Ks 0.5 -0.1 0", "Ks must not be negative")])
def test_bad_glossy_keys_are_named(tmp_path: Path, line: str, message: str) -> None:
    (tmp_path / "m.mtl").write_text(f"newmtl x\n{line}\n")
    (tmp_path / "s.obj").write_text("mtllib m.mtl\nusemtl x\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(InputError) as info:
        load_obj(tmp_path / "s.obj")
    assert message in str(info.value) and "m.mtl" in str(info.value) and "line 2" in str(info)


def _setup(rough: float, metal: float, base: tuple[float, float, float], mu: float):  # noqa: ANN202
    alpha = max(rough * rough, bsdf.MIN_ALPHA)
    tables = bsdf.albedo_tables()
    s = bsdf.glossy_setup(*base, rough, alpha, metal, 0.04, mu, *tables)
    return alpha, s, tables


def _eval(o, i, rough, alpha, s, tables):  # noqa: ANN001, ANN202
    return bsdf.glossy_eval(*o, *i, rough, alpha, 0.04, *s[:8], s[14], tables[0], tables[1])


CASES = [
    (0.5, 0.0, (1.0, 1.0, 1.0)),
    (0.45, 0.0, (0.7, 0.5, 0.2)),
    (0.7, 1.0, (0.9, 0.6, 0.3)),
    (0.4, 0.5, (0.95, 0.8, 0.4)),
    (1.0, 0.0, (0.8, 0.8, 0.8)),
]


@pytest.mark.parametrize(("rough", "metal", "base"), CASES)
def test_lobe_albedos_match_a_quadrature_and_stay_below_one(
    rough: float, metal: float, base: tuple[float, float, float]
) -> None:
    """int f cos over the hemisphere (midpoint rule in cos(theta), phi) equals DiffCol and
    GlossCol per lobe; their sum is at most 1 (and 1 for a white dielectric)."""
    n_cos, n_phi = 48, 96
    for mu in (0.95, 0.5, 0.3):
        alpha, s, tables = _setup(rough, metal, base, mu)
        o = (math.sqrt(1 - mu * mu), 0.0, mu)
        diff = np.zeros(3)
        spec = np.zeros(3)
        weight = (1.0 / n_cos) * (2 * math.pi / n_phi)
        for a in range(n_cos):
            c = (a + 0.5) / n_cos
            sin_t = math.sqrt(1 - c * c)
            for b in range(n_phi):
                phi = 2 * math.pi * (b + 0.5) / n_phi
                f = _eval(o, (sin_t * math.cos(phi), sin_t * math.sin(phi), c), rough, alpha, s,
                          tables)  # fmt: skip
                diff += np.array(f[0:3]) * c * weight
                spec += np.array(f[3:6]) * c * weight
        gloss_col = np.array(s[8:11])
        diff_col = np.array(s[11:14])
        np.testing.assert_allclose(diff, diff_col, atol=2e-3, err_msg=f"DiffCol mu={mu}")
        np.testing.assert_allclose(spec, gloss_col, atol=4e-3, err_msg=f"GlossCol mu={mu}")
        assert np.all(gloss_col + diff_col <= 1.0 + 1e-3)
        assert np.all(gloss_col <= 1.0) and np.all(diff_col >= 0.0)
        if metal == 0.0 and base == (1.0, 1.0, 1.0):
            np.testing.assert_allclose(gloss_col + diff_col, 1.0, atol=1e-3)
        if metal == 1.0:
            assert np.all(diff_col == 0.0)


@pytest.mark.parametrize(("rough", "metal", "base"), [*CASES, (0.05, 1.0, (1.0, 0.8, 0.6)),
                                                      (0.1, 0.0, (0.5, 0.5, 0.5))])
def test_sampled_directions_follow_the_pdf(
    rough: float, metal: float, base: tuple[float, float, float]
) -> None:
    """E[f cos / pdf] over the sampler's directions is the lobes' albedo only if ``pdf`` is
    the sampler's true density (checked down to near-mirror roughness)."""
    rng = np.random.default_rng(7)
    n = 10000
    for mu in (0.6, 0.15):
        alpha, s, tables = _setup(rough, metal, base, mu)
        o = (math.sqrt(1 - mu * mu), 0.0, mu)
        values = np.zeros((n, 3))
        for k, (u0, u1, u2) in enumerate(rng.random((n, 3))):
            i = bsdf.glossy_sample(*o, alpha, s[14], u0, u1, u2)
            if i[2] <= 0.0:
                continue
            f = _eval(o, i, rough, alpha, s, tables)
            if f[6] > 0.0:
                values[k] = (np.array(f[0:3]) + np.array(f[3:6])) * i[2] / f[6]
        # The tables are accurate to about 1% of the albedo at grazing view.
        expected = np.array(s[8:11]) + np.array(s[11:14])
        bound = SIGMAS * values.std(axis=0) / math.sqrt(n) + 0.01 * expected + 1e-4
        assert np.all(np.abs(values.mean(axis=0) - expected) < bound), (mu, values.mean(0),
                                                                        expected)  # fmt: skip


def test_white_glossy_dielectric_furnace(tmp_path: Path) -> None:
    """A closed box of white glossy dielectric (albedo 1 in every direction: what the coat
    does not reflect the white base does) emitting Le: radiance Le (max_depth + 1)."""
    (tmp_path / "f.mtl").write_text("newmtl m\nKd 1 1 1\nPr 0.4\nKe 1 1 1\n")
    corners = [(-1, -1, -1), (1, -1, -1), (1, 1, -1), (-1, 1, -1),
               (-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1)]  # fmt: skip
    faces = [(1, 2, 3, 4), (8, 7, 6, 5), (1, 5, 6, 2), (2, 6, 7, 3), (3, 7, 8, 4), (4, 8, 5, 1)]
    lines = ["mtllib f.mtl", "o box", "usemtl m"]
    lines += [f"v {x} {y} {z}" for x, y, z in corners]
    lines += ["f " + " ".join(map(str, f)) for f in faces]
    (tmp_path / "f.obj").write_text("\n".join(lines) + "\n")
    scene = load_obj(tmp_path / "f.obj")
    anim = Animation([CameraKey(0, np.array([0.2, -0.1, 0.3]), np.array([0.0, 0.3, -1.0]),
                                np.array([0.0, 1.0, 0.0]), 100.0)])  # fmt: skip
    max_depth = 3
    geo = prepare_frame(scene, anim, 0, 8, 8)
    try:
        hits = trace_primary(geo)
        batch = trace_batch(geo, hits, 0, 96, max_depth, frame_key(0, 0, 0))
    finally:
        geo.tracer.close()
    values = (batch.direct + batch.indirect)[:, :, 0].ravel()
    expected = max_depth + 1.0
    bound = SIGMAS * values.std() / math.sqrt(values.size) + 2e-3 * expected
    assert abs(values.mean() - expected) < bound, (values.mean(), bound)
    assert values.std() > 0.01  # glossy and diffuse bounces really are sampled


def _glossy_scene(tmp_path: Path) -> tuple:
    path = glossy_cornell(tmp_path, {"white": "Pr 0.35", "red": "Pm 1\nPr 0.2",
                                     "green": "Pr 0.6\nKs 1 1 1"})  # fmt: skip
    scene = load_obj(path)
    cam = cornell_camera()[0]
    key = CameraKey(0, np.array(cam["position"], float), np.array(cam["look_at"], float),
                    np.array([0.0, 1.0, 0.0]), cam["fov_y"])  # fmt: skip
    anim = Animation([key])
    return scene, anim


@pytest.mark.parametrize("scene_kind", ["cornell", "glossy_floor"])
def test_mis_bsdf_only_and_light_only_estimate_the_same_image(
    tmp_path: Path, scene_kind: str
) -> None:
    if scene_kind == "cornell":
        scene, anim = _glossy_scene(tmp_path)
    else:
        # A near-mirror coat over a diffuse floor, seeing the lamp's reflection: light
        # sampling fails on the sharp reflection, BSDF sampling on the diffuse base.
        scene = load_obj(plane_and_lamp(tmp_path, floor_mtl="Kd 0.5 0.5 0.5\nPr 0.12",
                                        half=0.3))  # fmt: skip
        anim = Animation([CameraKey(0, np.array([0.0, 0.9, 2.0]), np.array([0.0, 0.0, 0.0]),
                                    np.array([0.0, 1.0, 0.0]), 60.0)])  # fmt: skip
    geo = prepare_frame(scene, anim, 0, 12, 9)
    spp = 256
    try:
        hits = trace_primary(geo)
        sums = {}
        pixel_noise = {}
        for mode in (kernels.MIS_POWER, kernels.MIS_BSDF_ONLY, kernels.MIS_LIGHT_ONLY):
            batch = trace_batch(geo, hits, 0, spp, 3, frame_key(1, 0, 0), mis_mode=mode)
            samples = batch.direct + batch.indirect
            # Per sample: the image's total radiance (a sum over pixels, all channels).
            sums[mode] = samples.sum(axis=(1, 2))
            pixel_noise[mode] = samples.var(axis=0).sum()
    finally:
        geo.tracer.close()
    means = {m: v.mean() for m, v in sums.items()}
    errors = {m: v.std() / math.sqrt(spp) for m, v in sums.items()}
    for other in (kernels.MIS_BSDF_ONLY, kernels.MIS_LIGHT_ONLY):
        bound = SIGMAS * math.hypot(errors[kernels.MIS_POWER], errors[other])
        assert abs(means[kernels.MIS_POWER] - means[other]) < bound, (means, errors)
    if scene_kind == "glossy_floor":
        # What MIS is for: sharp reflections of the light converge; less per-pixel noise
        # than either strategy alone.
        assert pixel_noise[kernels.MIS_POWER] < 0.5 * pixel_noise[kernels.MIS_BSDF_ONLY]
        assert pixel_noise[kernels.MIS_POWER] < 0.5 * pixel_noise[kernels.MIS_LIGHT_ONLY]


def test_lobe_passes_split_the_image_without_changing_it(tmp_path: Path) -> None:
    scene, anim = _glossy_scene(tmp_path)
    geo = prepare_frame(scene, anim, 0, 16, 9)
    try:
        hits = trace_primary(geo)
        plain = trace_batch(geo, hits, 0, 4, 4, frame_key(2, 0, 0))
        split = trace_batch(geo, hits, 0, 4, 4, frame_key(2, 0, 0), lobes=True)
    finally:
        geo.tracer.close()
    assert plain.lobes is None and split.lobes is not None
    assert np.array_equal(plain.direct, split.direct)
    assert np.array_equal(plain.indirect, split.indirect)
    # Everything but the emission seen at the primary hit lands in exactly one lobe pass.
    mats = geo.materials
    emission = np.where((hits.prim >= 0)[:, None], geo.tri_ke[np.maximum(hits.prim, 0)], 0.0)
    lit = split.lobes.sum(axis=2)
    total = split.direct + split.indirect
    not_light = mats.ke[geo.tri_mat[np.maximum(hits.prim, 0)]].sum(axis=1) == 0
    np.testing.assert_allclose(lit[:, not_light], total[:, not_light], rtol=1e-12, atol=1e-12)
    assert np.all(split.lobes[:, ~not_light].sum(axis=2) <= total[:, ~not_light]
                  - emission[~not_light] + 1e-9)  # fmt: skip
    # Both lobes carry light, and the direct/indirect split matches the frame's.
    assert split.lobes[:, :, 2:].sum() > 0.01 * split.lobes.sum()
    direct_lobes = split.lobes[:, :, 0] + split.lobes[:, :, 2]
    np.testing.assert_allclose(direct_lobes[:, not_light], split.direct[:, not_light],
                               rtol=1e-12, atol=1e-12)  # fmt: skip


def test_smooth_metal_is_a_mirror(tmp_path: Path) -> None:
    """Roughness 0 metal (F0 = 0.9): where the mirror ray hits the lamp the floor shows
    F(cos) Le, elsewhere nothing (a black world and no diffuse lobe)."""
    le, half, height = 5.0, 0.5, 1.0
    path = plane_and_lamp(tmp_path, floor_mtl="Kd 0.9 0.9 0.9\nPm 1\nPr 0", le=le, half=half,
                          height=height)  # fmt: skip
    scene = load_obj(path)
    anim = Animation([CameraKey(0, np.array([0.0, 0.8, 2.2]), np.array([0.0, 0.0, 0.0]),
                                np.array([0.0, 1.0, 0.0]), 60.0)])  # fmt: skip
    geo = prepare_frame(scene, anim, 0, 40, 30)
    try:
        hits = trace_primary(geo)
        batch = trace_batch(geo, hits, 0, 8, 3, frame_key(0, 0, 0))
    finally:
        geo.tracer.close()
    radiance = (batch.direct + batch.indirect).mean(axis=0)[:, 0]
    floor = (hits.prim >= 0) & (hits.prim < 2)
    d = hits.directions[floor].astype(np.float64)
    points = hits.origins[floor] + d * hits.t[floor, None]
    reflected = d * np.array([1.0, -1.0, 1.0])
    s = (height - points[:, 1]) / reflected[:, 1]
    at = points + reflected * s[:, None]
    margin = np.maximum(np.abs(at[:, 0]), np.abs(at[:, 2]))
    inside = margin < half - 0.03
    outside = margin > half + 0.03
    assert inside.sum() > 10 and outside.sum() > 100
    cos = -d[:, 1]
    fresnel = 0.9 + 0.1 * (1 - cos) ** 5
    # GGX's long tail and light sampling inside the (1e-4 wide) lobe leave rare deviations
    # (unbiased, MIS-weighted): almost every pixel within 1%, the mean within 0.5%.
    close = np.isclose(radiance[floor][inside], fresnel[inside] * le, rtol=1e-2)
    assert close.mean() > 0.95
    assert radiance[floor][inside].mean() == pytest.approx((fresnel[inside] * le).mean(),
                                                           rel=5e-3)  # fmt: skip
    assert np.all(radiance[floor][outside] < 1e-3 * le)


def test_existing_scenes_take_the_lambertian_path() -> None:
    """The bundled scenes have no glossy keys: every material stays Lambertian (so their
    renders are unchanged; the bundled sequence test checks the pixels)."""
    for name in ("cornell.obj", "cornell_checker.obj"):
        scene = load_obj(Path(__file__).resolve().parent.parent / "testdata" / name)
        assert not any(m.glossy for m in scene.materials)
    anim = load_animation(Path(__file__).resolve().parent.parent / "testdata" / "anim.json",
                          [o.name for o in scene.objects])  # fmt: skip
    assert anim.emission_keys == {}
