"""svgf trace --lobes: Blender Cycles' light passes in the input files.

Cycles' identity R,G,B = sum over lobes (Dir + Ind) x Col + emission must hold with the
stored values (exactly up to float/half rounding), the Col passes must be reflectances, and
albedo must be DiffCol + GlossCol.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from tracescenes import TESTDATA, glossy_cornell, read_exr, rgb

from svgf_cli.cli import main

LOBE_LAYERS = ("DiffDir", "DiffInd", "DiffCol", "GlossDir", "GlossInd", "GlossCol")


@pytest.fixture(scope="module")
def lobe_frames(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("lobes")
    # White: glossy dielectric; red wall: rough copper-ish metal; green wall: Lambertian.
    scene = glossy_cornell(out, {"white": "Pr 0.3", "red": "Pm 1\nPr 0.25"})
    for suffix, extra in (("h", []), ("f", ["--float"])):
        with pytest.raises(SystemExit) as info:
            main(["trace", str(scene), "-o", str(out / f"{suffix}.####.exr"), "--frames", "2",
                  "--resolution", "48x27", "--spp", "2", "--max-depth", "4", "--lobes",
                  "--animation", str(TESTDATA / "anim.json"), "-q", *extra])  # fmt: skip
        assert info.value.code == 0
    return out


def recombined(layers: dict[str, np.ndarray]) -> np.ndarray:
    return ((rgb(layers, "DiffDir") + rgb(layers, "DiffInd")) * rgb(layers, "DiffCol")
            + (rgb(layers, "GlossDir") + rgb(layers, "GlossInd")) * rgb(layers, "GlossCol")
            + rgb(layers, "emission"))  # fmt: skip


def test_cycles_identity_holds_with_float_passes(lobe_frames: Path) -> None:
    layers, spec = read_exr(lobe_frames / "f.0002.exr")
    assert {f"{n}.{c}" for n in LOBE_LAYERS for c in "RGB"} <= set(layers)
    assert spec.getattribute("svgf/lobes") == "cycles"
    combined = rgb(layers, "")
    np.testing.assert_allclose(recombined(layers), combined, rtol=1e-5, atol=1e-6)
    assert combined.max() > 1.0  # the light is in view: emission is part of the identity
    # Both lobes carry light in this scene.
    assert (rgb(layers, "GlossDir") * rgb(layers, "GlossCol")).max() > 0.05
    assert (rgb(layers, "DiffDir") * rgb(layers, "DiffCol")).max() > 0.05


def test_cycles_identity_holds_to_half_rounding(lobe_frames: Path) -> None:
    layers, spec = read_exr(lobe_frames / "h.0002.exr")
    formats = {n: str(spec.channelformat(k)) for k, n in enumerate(spec.channelnames)}
    for name in ("DiffDir", "DiffInd", "GlossDir", "GlossInd"):
        assert formats[f"{name}.R"] == "half"
    assert formats["DiffCol.G"] == "float" and formats["GlossCol.B"] == "float"
    combined = rgb(layers, "")
    # Each stored half carries a relative error of at most 2^-11 (plus the subnormal step):
    # a few of those per term, as R,G,B is itself the half sum of two stored halves.
    magnitude = recombined({name: np.abs(plane) for name, plane in layers.items()})
    tolerance = 4 * 2.0**-11 * (magnitude + np.abs(combined)) + 1e-6
    error = np.abs(recombined(layers) - combined)
    assert np.all(error <= tolerance), (error - tolerance).max()
    assert error.max() > 0  # really a half file: rounding is visible


def test_colour_passes_are_reflectances_and_albedo_is_their_sum(lobe_frames: Path) -> None:
    layers, _ = read_exr(lobe_frames / "f.0002.exr")
    diff_col, gloss_col = rgb(layers, "DiffCol"), rgb(layers, "GlossCol")
    albedo = rgb(layers, "albedo")
    ids = layers["id"].astype(int)
    assert np.all(diff_col >= 0) and np.all(gloss_col >= 0)
    assert np.all(diff_col + gloss_col <= 1.0 + 1e-6)
    np.testing.assert_allclose(albedo, diff_col + gloss_col, rtol=1e-6, atol=1e-7)
    green = ids == 4  # Lambertian: DiffCol is Kd, no glossy lobe, its passes are 0
    red = ids == 3  # metal: no diffuse lobe
    floor, back = ids == 0, ids == 2  # glossy dielectric
    assert green.any() and red.any() and floor.any() and back.any()
    np.testing.assert_allclose(diff_col[green], np.broadcast_to([0.14, 0.45, 0.091],
                                                                diff_col[green].shape), rtol=1e-6)
    assert np.all(gloss_col[green] == 0) and np.all(rgb(layers, "GlossDir")[green] == 0)
    assert np.all(diff_col[red] == 0) and np.all(rgb(layers, "DiffInd")[red] == 0)
    # Metal F0 is its base colour: the red wall reflects red.
    assert np.all(gloss_col[red][:, 0] > gloss_col[red][:, 1])
    # Dielectric coat: about 0.04 seen head-on (the back wall), more at grazing angles (the
    # floor), and the diffuse base gets what the coat leaves (Kd 0.725 at most).
    assert gloss_col[back].min() > 0.03 and gloss_col[back].max() < 0.06
    assert gloss_col[floor].min() > gloss_col[back].max()
    assert np.all(diff_col[floor | back] < 0.725 * (1 - 0.03))


def test_lobes_are_off_by_default_and_leave_the_other_layers_alone(
    lobe_frames: Path, tmp_path: Path
) -> None:
    scene = lobe_frames / "g.obj"
    with pytest.raises(SystemExit) as info:
        main(["trace", str(scene), "-o", str(tmp_path / "n.####.exr"), "--frames", "2",
              "--resolution", "48x27", "--spp", "2", "--max-depth", "4", "--float",
              "--animation", str(TESTDATA / "anim.json"), "-q"])  # fmt: skip
    assert info.value.code == 0
    plain, spec = read_exr(tmp_path / "n.0002.exr")
    with_lobes, _ = read_exr(lobe_frames / "f.0002.exr")
    assert not any(name.startswith(LOBE_LAYERS) for name in plain)
    assert spec.getattribute("svgf/lobes") is None
    for name, plane in plain.items():
        assert np.array_equal(plane, with_lobes[name]), name
