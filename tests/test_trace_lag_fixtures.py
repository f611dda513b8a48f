"""The committed lag sequences (testdata/lag): complete, within budget, reproducible, and the
frame facts testdata/lag/README.md states are really in the files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from tracescenes import TESTDATA, read_exr, rgb

from svgf_cli.cli import main

LAG = TESTDATA / "lag"
SEQUENCES = ("light_slide_dim", "light_step", "shadow", "camera", "glossy")
FRAMES = range(1, 17)
LIGHT_KE = np.array([17.0, 12.0, 4.0])
LIGHT_ID = 5
BASE_CHANNELS = {
    "R", "G", "B", "direct.R", "direct.G", "direct.B", "indirect.R", "indirect.G",
    "indirect.B", "emission.R", "emission.G", "emission.B", "albedo.R", "albedo.G",
    "albedo.B", "N.X", "N.Y", "N.Z", "Z", "motion.X", "motion.Y", "id", "motion_next.X",
    "motion_next.Y", "gradient.mask", "gradient.direct.prev", "gradient.direct.curr",
    "gradient.indirect.prev", "gradient.indirect.curr",
}  # fmt: skip
LOBE_CHANNELS = {f"{n}.{c}" for n in ("DiffDir", "DiffInd", "DiffCol", "GlossDir", "GlossInd",
                                      "GlossCol") for c in "RGB"} | {
    f"gradient.{s}.{w}" for s in ("diffuse", "glossy") for w in ("prev", "curr")}  # fmt: skip


def test_sequences_are_complete_and_within_budget() -> None:
    total = 0
    for name in SEQUENCES:
        folder = LAG / name
        inputs = sorted(p.name for p in folder.glob("in.*.exr"))
        refs = sorted(p.name for p in folder.glob("ref.*.exr"))
        assert inputs == [f"in.{f:04d}.exr" for f in FRAMES], name
        assert refs == [f"ref.{f:04d}.exr" for f in FRAMES], name
        total += sum(p.stat().st_size for p in folder.iterdir())
    assert total <= 25 * 1024 * 1024, total


@pytest.mark.parametrize("name", SEQUENCES)
def test_layers_and_references(name: str) -> None:
    layers, spec = read_exr(LAG / name / "in.0008.exr")
    expected = BASE_CHANNELS | (LOBE_CHANNELS if name == "glossy" else set())
    assert set(layers) == expected
    assert (spec.width, spec.height) == (128, 72) and spec.getattribute("svgf/spp") == 1
    assert spec.getattribute("compression") == "zip"
    ref, ref_spec = read_exr(LAG / name / "ref.0008.exr")
    assert set(ref) == {"R", "G", "B"} and ref_spec.getattribute("svgf/spp") >= 512
    # The reference is the converged version of the input: close on average.
    noisy, converged = rgb(layers, "").mean(), rgb(ref, "").mean()
    assert converged > 0.01 and abs(noisy - converged) < 0.1 * converged


def light_emission(name: str, frame: int) -> np.ndarray:
    """The emission layer where the light is seen, as multiples of the light's Ke."""
    layers, _ = read_exr(LAG / name / f"in.{frame:04d}.exr")
    light = layers["id"] == LIGHT_ID
    assert light.any()
    return rgb(layers, "emission")[light] / LIGHT_KE


def gradient(name: str, frame: int, signal: str = "direct") -> tuple[np.ndarray, np.ndarray]:
    layers, _ = read_exr(LAG / name / f"in.{frame:04d}.exr")
    on = layers["gradient.mask"] == 1
    return layers[f"gradient.{signal}.prev"][on], layers[f"gradient.{signal}.curr"][on]


def test_light_step_dims_on_frames_6_to_10() -> None:
    for frame in FRAMES:
        scale = 0.3 if 6 <= frame <= 10 else 1.0
        np.testing.assert_allclose(light_emission("light_step", frame), scale, rtol=1e-3)
    for frame, ratio in ((6, 0.3), (11, 1 / 0.3), (8, 1.0), (3, 1.0)):
        for signal in ("direct", "indirect"):
            prev, curr = gradient("light_step", frame, signal)
            lit = prev > 1e-6
            assert lit.mean() > 0.3
            np.testing.assert_allclose(curr[lit], ratio * prev[lit], rtol=1e-5)


def test_light_slide_dim_dims_at_frame_10() -> None:
    np.testing.assert_allclose(light_emission("light_slide_dim", 9), 1.0, rtol=1e-3)
    for frame in (10, 16):
        np.testing.assert_allclose(light_emission("light_slide_dim", frame), 0.45, rtol=1e-3)
    # The light moves every frame, so direct light changes nearly everywhere; at the dimming
    # frame it drops by about the dimming factor.
    prev, curr = gradient("light_slide_dim", 10)
    assert 0.35 < curr.sum() / prev.sum() < 0.55
    prev, curr = gradient("light_slide_dim", 5)
    assert np.mean(curr != prev) > 0.5 and 0.9 < curr.sum() / prev.sum() < 1.1


def test_camera_move_changes_nothing_but_the_view() -> None:
    """All materials Lambertian, lights and objects static: re-shaded samples are exact."""
    for frame in (2, 9, 16):
        for signal in ("direct", "indirect"):
            prev, curr = gradient("camera", frame, signal)
            assert prev.size > 500 and np.array_equal(prev, curr)
    layers, _ = read_exr(LAG / "camera" / "in.0009.exr")
    hit = layers["id"] >= 0
    assert np.median(np.abs(layers["motion.X"][hit])) > 0.1


def test_shadow_changes_only_near_the_sphere() -> None:
    for frame in (5, 12):
        prev, curr = gradient("shadow", frame)
        changed = curr != prev
        assert 0.0 < changed.mean() < 0.2
        layers, _ = read_exr(LAG / "shadow" / f"in.{frame:04d}.exr")
        sphere = layers["id"] == 8
        moving = np.hypot(layers["motion.X"], layers["motion.Y"]) > 0
        assert sphere.any() and np.array_equal(moving, sphere)
    # Frames 8 and 9 sit symmetrically about the turn at 8.5: the same pose, no change.
    prev, curr = gradient("shadow", 9)
    assert np.array_equal(prev, curr)


def test_glossy_sequence_has_both_lobes() -> None:
    layers, _ = read_exr(LAG / "glossy" / "in.0008.exr")
    gloss = (rgb(layers, "GlossDir") + rgb(layers, "GlossInd")) * rgb(layers, "GlossCol")
    diff = (rgb(layers, "DiffDir") + rgb(layers, "DiffInd")) * rgb(layers, "DiffCol")
    assert gloss.sum() > 0.05 * diff.sum()
    metal = np.isin(layers["id"], [7, 8])  # steel tall block, gold sphere
    assert metal.any() and np.all(rgb(layers, "DiffCol")[metal] == 0)
    # Reflections change with the camera and the light (where there is a glossy lobe).
    prev, curr = gradient("glossy", 8, "glossy")
    shiny = prev > 0
    assert shiny.mean() > 0.1 and np.mean(curr[shiny] != prev[shiny]) > 0.8


def test_documented_command_reproduces_a_frame(tmp_path: Path) -> None:
    """testdata/make_lag.py's command re-renders a committed input frame (to float
    tolerance: Embree picks its SIMD kernels per CPU)."""
    import sys

    sys.path.insert(0, str(TESTDATA))
    try:
        from make_lag import trace_command
    finally:
        sys.path.remove(str(TESTDATA))
    command = trace_command("light_step", "svgf")[1:]
    out = command.index("-o")
    command[out + 1] = str(tmp_path / "in.####.exr")
    ref = command.index("--reference")
    del command[ref : ref + 2]
    for option in ("--reference-spp", "--reference-channels"):
        at = command.index(option)
        del command[at : at + 2]
    command.remove("--reference-half")
    command[command.index("--frames") + 1] = "7"
    command = [str(TESTDATA.parent / c) if c.startswith("testdata/") else c for c in command]
    with pytest.raises(SystemExit) as info:
        main(command)
    assert info.value.code == 0
    fresh, _ = read_exr(tmp_path / "in.0007.exr")
    committed, _ = read_exr(LAG / "light_step" / "in.0007.exr")
    assert set(fresh) == set(committed)
    for name in ("Z", "N.Y", "albedo.G", "motion.X", "id", "gradient.mask"):
        np.testing.assert_allclose(fresh[name], committed[name], rtol=1e-4, atol=1e-4,
                                   err_msg=name)  # fmt: skip
    assert np.isclose(fresh["R"], committed["R"], rtol=2e-3, atol=1e-3).mean() > 0.99
