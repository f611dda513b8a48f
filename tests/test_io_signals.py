"""Signal sets on read (`--signals`): which signals each set builds from real Cycles frames,
the tracer's files and other presets' lobe AOVs; the light-pass check and its fallback to the
combined colour; gradient samples attached per signal."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenEXR
import pytest

from svgf_cli.errors import InputError
from svgf_cli.io.exr import fix_signal_set, read_frame, write_exr
from svgf_cli.io.layers import build_mapping, resolve_layers
from svgf_cli.io.signals import CHECK_SHARE, _gradient_channels, check_sum, plan_signals

TESTDATA = Path(__file__).resolve().parent.parent / "testdata"
METAL = TESTDATA / "cycles" / "metal"
ROLL = TESTDATA / "cycles" / "roll"
GLOSSY = TESTDATA / "lag" / "glossy"
LIGHT_STEP = TESTDATA / "lag" / "light_step"


def channels(path: Path) -> dict[str, np.ndarray]:
    """Every channel of ``path`` as stored, read with the OpenEXR library (not our reader)."""
    with OpenEXR.File(str(path), separate_channels=True) as f:
        return {name: np.asarray(ch.pixels) for name, ch in f.channels().items()}


def rgb(layers: dict[str, np.ndarray], name: str, prefix: str = "ViewLayer.") -> np.ndarray:
    return np.stack([layers[f"{prefix}{name}.{c}"].astype(np.float32) for c in "RGB"])


def cycles_copy(src: Path, dst: Path, drop: tuple[str, ...] = (),
                scale: dict[str, float] | None = None) -> Path:
    """``src`` rewritten without the passes in ``drop`` (and ``scale``d passes): a Cycles
    frame whose light passes no longer add up to Combined."""
    out = {}
    for name, pixels in channels(src).items():
        pass_name = name.split(".")[1]
        if pass_name in drop:
            continue
        out[name] = pixels.astype(np.float32) * np.float32((scale or {}).get(pass_name, 1.0))
    write_exr(dst, out)
    return dst


# ---------------------------------------------------------------------------- Cycles


@pytest.mark.parametrize("frame", [ROLL / "in.0003.exr", METAL / "in.0006.exr"])
def test_cycles_sets_build_their_signals_exactly_from_the_light_passes(frame: Path) -> None:
    layers = channels(frame)
    combined = rgb(layers, "Combined")
    emission = rgb(layers, "Emit") + rgb(layers, "Env")
    lobe = {name: (rgb(layers, f"{short}Dir") + rgb(layers, f"{short}Ind")) * rgb(layers,
            f"{short}Col") for name, short in (("diffuse", "Diff"), ("glossy", "Gloss"),
                                                ("transmission", "Trans"))}  # fmt: skip
    # Glossy and transmission light are one signal ("specular"), in the renderer's order.
    specular = lobe["glossy"] + lobe["transmission"]
    expected = {
        "lobes": {"diffuse": lobe["diffuse"], "specular": specular},
        "lobes-split": {
            "diffuse_direct": rgb(layers, "DiffDir") * rgb(layers, "DiffCol"),
            "diffuse_indirect": rgb(layers, "DiffInd") * rgb(layers, "DiffCol"),
            "specular": specular,
        },
        "direct-indirect": {
            part: sum(rgb(layers, f"{s}{tag}") * rgb(layers, f"{s}Col")
                      for s in ("Diff", "Gloss", "Trans"))
            for part, tag in (("direct", "Dir"), ("indirect", "Ind"))
        },
        "combined": {"color": combined - emission},
    }  # fmt: skip
    for name, signals in expected.items():
        result = read_frame(frame, build_mapping("cycles", signals=name))
        frame_read = result.frame
        assert result.plan is not None and result.plan.set == name
        assert frame_read.names == tuple(signals)
        for signal in frame_read.signals:
            # float32, in the renderer's own order: bit for bit what Cycles' identity gives.
            np.testing.assert_array_equal(signal.radiance, signals[signal.name])
            assert signal.gradient is None  # Cycles writes no gradient samples
        np.testing.assert_array_equal(frame_read.emission, emission)
        assert result.warnings == []
        if name != "combined":
            assert result.sum_check is not None and result.sum_check.failing == 0
            # the measured margin: half rounding stays far inside the tolerance
            assert result.sum_check.worst < 0.2
            total = frame_read.total_radiance()
            assert np.all(np.abs(total - combined) <= 3e-3 * np.abs(combined) + 1e-6)
    lobes = read_frame(frame, build_mapping("cycles", signals="lobes")).frame
    np.testing.assert_array_equal(lobes.signal("diffuse").albedo, rgb(layers, "DiffCol"))
    # The sum of both colours, not capped: a metal's colour above 1 stays radiance.
    np.testing.assert_array_equal(lobes.signal("specular").albedo,
                                  rgb(layers, "GlossCol") + rgb(layers, "TransCol"))
    assert lobes.signal("specular").glossy and not lobes.signal("diffuse").glossy
    # Each lobe's whole light, direct and indirect together (the mixed signals' sigma_l).
    assert lobes.signal("specular").mixed and lobes.signal("diffuse").mixed
    np.testing.assert_array_equal(lobes.albedo, rgb(layers, "Denoising Albedo"))


def test_cycles_direct_indirect_is_demodulated_by_the_capped_sum_of_the_colour_passes() -> None:
    layers = channels(METAL / "in.0006.exr")
    frame = read_frame(METAL / "in.0006.exr", build_mapping("cycles", signals="direct-indirect"))
    colours = rgb(layers, "DiffCol") + rgb(layers, "GlossCol") + rgb(layers, "TransCol")
    expected = np.minimum(colours, 1.0)
    for signal in frame.frame.signals:
        np.testing.assert_array_equal(signal.albedo, expected)
    # Denoising Albedo is no reflectance on the mirror ball; the colour passes are.
    assert rgb(layers, "Denoising Albedo").max() > 1.05 >= expected.max()


def test_the_sum_of_colour_passes_is_capped_at_one(tmp_path: Path) -> None:
    # Diffuse colour x4 and its light passes /4 (exact in float): the same light, colour
    # passes summing above 1, which the demodulating albedo caps at 1.
    copy = cycles_copy(METAL / "in.0006.exr", tmp_path / "in.0006.exr",
                       scale={"DiffCol": 4.0, "DiffDir": 0.25, "DiffInd": 0.25})
    layers = channels(copy)
    # The scene has no glass (no transmission light): a transmission colour of 0.25 changes
    # no light but is the third term of the sum.
    for c in "RGB":
        layers[f"ViewLayer.TransCol.{c}"] = np.full_like(layers[f"ViewLayer.TransCol.{c}"], 0.25)
    write_exr(copy, layers)
    colours = rgb(layers, "DiffCol") + rgb(layers, "GlossCol") + rgb(layers, "TransCol")
    assert colours.max() > 1.5
    frame = read_frame(copy, build_mapping("cycles", signals="direct-indirect")).frame
    for signal in frame.signals:
        np.testing.assert_array_equal(signal.albedo, np.minimum(colours, 1.0))


def test_a_pass_used_twice_is_cleaned_and_reported_once(tmp_path: Path) -> None:
    # The diffuse colour multiplies the diffuse light and demodulates it: read once, so its
    # NaN is one warning, not one per use.
    layers = {n: p.astype(np.float32) for n, p in channels(METAL / "in.0006.exr").items()}
    layers["ViewLayer.DiffCol.R"][0, 0] = np.nan
    write_exr(tmp_path / "in.exr", layers)
    result = read_frame(tmp_path / "in.exr", build_mapping("cycles", signals="lobes"))
    assert [w for w in result.warnings if "diffuse_color" in w] == [
        f"{tmp_path / 'in.exr'}: 1 NaN/Inf values in diffuse_color scrubbed to 0"]


def test_traced_direct_indirect_without_its_layers_is_built_from_the_lobes(
    tmp_path: Path
) -> None:
    # A tracer file whose direct/indirect layers were dropped: the pair is rebuilt from the
    # lobe light passes times their colour passes (all of which must be read).
    layers = {n: p.astype(np.float32) for n, p in channels(GLOSSY / "in.0004.exr").items()
              if not n.startswith(("direct.", "indirect."))}
    write_exr(tmp_path / "in.exr", layers)
    frame = read_frame(tmp_path / "in.exr", build_mapping("svgf", signals="direct-indirect"))
    for part, tag in (("direct", "Dir"), ("indirect", "Ind")):
        expected = sum(rgb(layers, f"{s}{tag}", "") * rgb(layers, f"{s}Col", "")
                       for s in ("Diff", "Gloss"))
        np.testing.assert_allclose(frame.frame.signal(part).radiance, expected, rtol=1e-6)
        # Demodulated by the G-buffer albedo, which does not describe the glossy light in
        # it: marked so (its floor; firefly spreading's colour test), as the combined colour.
        assert frame.frame.signal(part).guide_albedo
    # Cycles builds the pair over the lobes' own colours: reflectances, not the guide.
    cycles = read_frame(ROLL / "in.0001.exr", build_mapping("cycles", signals="direct-indirect"))
    assert not any(s.guide_albedo for s in cycles.frame.signals)


def test_auto_takes_the_first_set_of_the_measured_order_the_file_offers() -> None:
    cycles = read_frame(ROLL / "in.0001.exr", build_mapping("cycles"))
    assert cycles.plan.set == "lobes-split" and cycles.plan.checked  # from the lobes
    assert cycles.plan.offered == ("lobes-split", "direct-indirect", "lobes", "combined")
    # The glossy lobe is a signal of its own, marked glossy (the filter's glossy rules).
    glossy = {s.name: s.glossy for s in cycles.frame.signals}
    assert glossy == {"diffuse_direct": False, "diffuse_indirect": False, "specular": True}
    # Lobe signals are demodulated by their own colours; only a signal demodulated by the
    # G-buffer albedo AOV (combined; the tracer's direct + indirect) is marked as such.
    assert not any(s.guide_albedo for s in cycles.frame.signals)
    combined = read_frame(ROLL / "in.0001.exr", build_mapping("cycles", signals="combined"))
    assert [s.guide_albedo for s in combined.frame.signals] == [True]
    paired = read_frame(TESTDATA / "seq" / "in.0001.exr", build_mapping("svgf")).frame
    assert [s.guide_albedo for s in paired.signals] == [True, True]
    # Only a signal holding direct and indirect light together is mixed.
    assert [s.mixed for s in combined.frame.signals] == [True]
    assert not any(s.mixed for s in paired.signals)
    split = {s.name: s.mixed for s in cycles.frame.signals}
    assert split == {"diffuse_direct": False, "diffuse_indirect": False, "specular": True}
    # The tracer's lobe passes where it wrote them, else its own direct and indirect layers.
    traced = read_frame(GLOSSY / "in.0002.exr", build_mapping("svgf"))
    assert traced.plan.set == "lobes-split" and traced.plan.checked
    # Without transmission passes the glossy lobe keeps its own name (and gradient samples).
    assert traced.frame.names == ("diffuse_direct", "diffuse_indirect", "glossy")
    assert traced.frame.signal("glossy").glossy
    plain = read_frame(LIGHT_STEP / "in.0002.exr", build_mapping("svgf"))
    assert plain.plan.set == "direct-indirect" and plain.plan.checked is False
    assert plain.plan.offered == ("direct-indirect", "combined")


def test_a_missing_lobe_falls_back_to_combined_with_one_warning(tmp_path: Path) -> None:
    broken = cycles_copy(METAL / "in.0006.exr", tmp_path / "in.0006.exr",
                         drop=("GlossDir", "GlossInd", "GlossCol"))
    mapping = build_mapping("cycles")
    result = read_frame(broken, mapping)
    assert result.plan.set == "combined"  # auto took lobes-split, from the lobes
    assert result.frame.names == ("color",)
    assert result.sum_check is not None and not result.sum_check.passed
    share = result.sum_check.share
    assert 0.2 < share < 0.9  # the glossy floor and the metal ball
    assert result.warnings == [result.signal_warning]
    assert str(broken) in result.signal_warning
    assert f"{share:.2%} of pixels" in result.signal_warning
    assert "filtering the combined colour for the whole run" in result.signal_warning
    # The run decides once: every later read is the combined set, unchecked, silent.
    fixed, decided = fix_signal_set(broken, mapping)
    assert fixed.signals == "combined" and fixed.signals_fixed
    assert decided.signal_warning == result.signal_warning
    again = read_frame(broken, fixed)
    assert again.warnings == [] and again.sum_check is None


def test_a_later_frame_failing_the_check_keeps_the_set_and_warns(tmp_path: Path) -> None:
    fixed, decided = fix_signal_set(METAL / "in.0005.exr",
                                    build_mapping("cycles", signals="lobes"))
    assert fixed.signals == "lobes" and decided.signal_warning is None
    # A light group or holdout: the diffuse light no longer adds up.
    broken = cycles_copy(METAL / "in.0006.exr", tmp_path / "in.0006.exr",
                         scale={"DiffInd": 0.5})
    result = read_frame(broken, fixed)
    assert result.plan.set == "lobes"
    assert result.frame.names == ("diffuse", "specular")
    assert result.signal_warning is not None and "keeping lobes" in result.signal_warning


def _with_volume(src: Path, dst: Path, passes: bool) -> tuple[Path, np.ndarray]:
    """``src`` with volume light (a fog patch over the left third) added to Combined, and
    its VolumeDir/VolumeInd passes written when ``passes``."""
    layers = {n: p.astype(np.float32) for n, p in channels(src).items()}
    h, w = layers["ViewLayer.Combined.R"].shape
    fog = np.zeros((h, w), np.float32)
    fog[:, : w // 3] = 0.25
    for i, c in enumerate("RGB"):
        layers[f"ViewLayer.Combined.{c}"] += fog * (1 + i) + fog * 0.5
        if passes:
            layers[f"ViewLayer.VolumeDir.{c}"] = fog * (1 + i)
            layers[f"ViewLayer.VolumeInd.{c}"] = fog * 0.5
    write_exr(dst, layers)
    return dst, fog


def test_volume_light_is_its_own_lobe_and_missing_volume_passes_fall_back(
    tmp_path: Path,
) -> None:
    with_passes, fog = _with_volume(ROLL / "in.0003.exr", tmp_path / "v.exr", passes=True)
    result = read_frame(with_passes, build_mapping("cycles", signals="lobes"))
    assert result.frame.names == ("diffuse", "specular", "volume")
    volume = result.frame.signal("volume")
    np.testing.assert_array_equal(volume.radiance[1], 2 * fog + 0.5 * fog)
    np.testing.assert_array_equal(volume.albedo, np.ones_like(volume.albedo))  # no colour
    assert result.sum_check.failing == 0
    direct = read_frame(with_passes, build_mapping("cycles", signals="direct-indirect")
                        ).frame.signal("direct")
    assert direct.radiance[0][:, 0].min() >= 0.25  # volume direct light is direct light
    without, _ = _with_volume(ROLL / "in.0003.exr", tmp_path / "n.exr", passes=False)
    result = read_frame(without, build_mapping("cycles"))
    assert result.plan.set == "combined"
    assert abs(result.sum_check.share - 1 / 3) < 0.02  # the fog's third of the image


def test_a_few_pixels_off_are_tolerated() -> None:
    frame = read_frame(ROLL / "in.0003.exr", build_mapping("cycles", signals="lobes")).frame
    colour = frame.total_radiance()
    few = int(CHECK_SHARE * colour.shape[1] * colour.shape[2])
    colour.reshape(3, -1)[:, :few] += 5.0
    check = check_sum(frame.signals, frame.emission, colour)
    assert check.failing == few and check.passed
    colour.reshape(3, -1)[:, few : few + 2] += 5.0
    assert not check_sum(frame.signals, frame.emission, colour).passed


def test_the_check_is_the_same_at_any_exposure() -> None:
    frame = read_frame(METAL / "in.0006.exr", build_mapping("cycles", signals="lobes")).frame
    colour = frame.total_radiance() * np.float32(1.004)  # 0.4 %: half rounding's order
    for k in (1e-3, 1.0, 1e3):
        scaled = [type(s)(s.name, s.radiance * np.float32(k), s.albedo) for s in frame.signals]
        check = check_sum(scaled, frame.emission * np.float32(k), colour * np.float32(k))
        assert check.failing == 0, k
        colour_off = colour * np.float32(1.05 * k)  # 5 %: a lobe's worth
        assert check_sum(scaled, frame.emission * np.float32(k), colour_off).share > 0.9, k


def test_an_explicit_set_the_file_cannot_offer_is_a_clear_error() -> None:
    with pytest.raises(InputError) as info:
        read_frame(LIGHT_STEP / "in.0002.exr", build_mapping("svgf", signals="lobes"))
    message = str(info.value)
    assert "light_step/in.0002.exr" in message
    assert "--signals lobes is not possible: no light passes (looked for DiffDir.R" in message
    assert info.value.exit_code == 3


def test_a_lobe_with_one_light_pass_offers_no_lobe_set() -> None:
    names = [n for n in channels(ROLL / "in.0001.exr") if ".DiffInd." not in n]
    mapping = build_mapping("cycles")
    resolved = resolve_layers(mapping, names, "f.exr")
    plan = plan_signals(mapping, resolved, names, "f.exr")
    assert plan is not None and plan.set == "combined" and plan.offered == ("combined",)
    assert read_frame(ROLL / "in.0001.exr", mapping).plan.set != "combined"
    assert "lobe sets unavailable: diffuse has only its direct light" in resolved.notes


# ------------------------------------------------------------- radiance-style lobe AOVs


def _arnold_frame(path: Path) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(5)
    h, w = 6, 8
    planes: dict[str, np.ndarray] = {}

    def layer(name: str, value: np.ndarray) -> np.ndarray:
        for i, c in enumerate("RGB"):
            planes[f"{name}.{c}"] = value[i]
        return value

    diffuse = [layer(n, rng.uniform(0.1, 1.0, (3, h, w)).astype(np.float32))
               for n in ("diffuse_direct", "diffuse_indirect")]
    specular = [layer(n, rng.uniform(0.0, 0.5, (3, h, w)).astype(np.float32))
                for n in ("specular_direct", "specular_indirect")]
    layer("diffuse_albedo", np.full((3, h, w), 0.5, np.float32))
    layer("specular_albedo", np.full((3, h, w), 0.04, np.float32))
    emission = layer("emission", np.zeros((3, h, w), np.float32))
    emission[:, 0, 0] = 4.0
    direct = layer("direct", diffuse[0] + specular[0])
    indirect = layer("indirect", diffuse[1] + specular[1])
    beauty = direct + indirect + emission
    for i, c in enumerate("RGB"):
        planes[c] = beauty[i]
    layer("denoise_albedo", np.full((3, h, w), 0.5, np.float32))
    for i, c in enumerate("XYZ"):
        planes[f"N.{c}"] = np.full((h, w), float(i == 2), np.float32)
    planes["Z"] = np.full((h, w), 3.0, np.float32)
    planes["motionvector.R"] = planes["motionvector.G"] = np.zeros((h, w), np.float32)
    write_exr(path, planes)
    return planes


def test_arnold_lobe_aovs_are_radiance_and_its_direct_excludes_emission(tmp_path: Path) -> None:
    planes = _arnold_frame(tmp_path / "a.exr")

    def layer(name: str) -> np.ndarray:
        return np.stack([planes[f"{name}.{c}"] for c in "RGB"])

    lobes = read_frame(tmp_path / "a.exr", build_mapping("arnold", signals="lobes"))
    assert lobes.plan.set == "lobes" and lobes.frame.names == ("diffuse", "glossy")
    np.testing.assert_array_equal(lobes.frame.signal("diffuse").radiance,
                                  layer("diffuse_direct") + layer("diffuse_indirect"))
    np.testing.assert_array_equal(lobes.frame.signal("glossy").albedo, layer("specular_albedo"))
    assert lobes.sum_check is not None and lobes.sum_check.failing == 0
    pair = read_frame(tmp_path / "a.exr", build_mapping("arnold", signals="direct-indirect"))
    # Arnold's `direct` AOV (C[DSV]L) holds no emission: nothing is taken out of it.
    np.testing.assert_array_equal(pair.frame.signal("direct").radiance, layer("direct"))
    np.testing.assert_allclose(pair.frame.total_radiance(),
                               np.stack([planes[c] for c in "RGB"]), rtol=1e-6)


# Per preset, the channel names of a small direct/indirect file: (prefix, colour layer or
# None for bare R, G, B, emission layer, albedo layer, normal, depth, motion channels).
_DIRECT_INDIRECT_FILES = {
    "svgf": ("", None, "emission", "albedo", ("N.X", "N.Y", "N.Z"), "Z",
             ("motion.X", "motion.Y")),
    "cycles": ("ViewLayer.", "Combined", "Emit", "Denoising Albedo",
               ("Normal.X", "Normal.Y", "Normal.Z"), "Depth.Z", ("Vector.X", "Vector.Y")),
    "arnold": ("", None, "emission", "denoise_albedo", ("N.X", "N.Y", "N.Z"), "Z",
               ("motionvector.R", "motionvector.G")),
    "karma": ("", "C", "emission", "albedo", ("N.X", "N.Y", "N.Z"), "Pz",
              ("motionvector.X", "motionvector.Y")),
}


@pytest.mark.parametrize(("preset", "emission_in_direct"),
                         [("svgf", True), ("cycles", True), ("arnold", False), ("karma", True)])
def test_the_emission_is_taken_out_of_direct_exactly_where_direct_holds_it(
    tmp_path: Path, preset: str, emission_in_direct: bool
) -> None:
    # `svgf trace`'s `direct` holds the camera-visible emission, and so do Karma's and a
    # Cycles compositor's direct/indirect layers (built from the light passes); Arnold's
    # built-in C[DSV]L does not. The emission is filtered apart and added back once: the
    # frame adds up to the beauty either way.
    prefix, colour, emit, albedo, normal, depth, motion = _DIRECT_INDIRECT_FILES[preset]
    rng = np.random.default_rng(6)
    h, w = 6, 8
    planes: dict[str, np.ndarray] = {}

    def layer(name: str | None, value: np.ndarray) -> np.ndarray:
        for i, c in enumerate("RGB"):
            planes[f"{prefix}{name}.{c}" if name else c] = value[i]
        return value

    emission = np.zeros((3, h, w), np.float32)
    emission[:, 1, 2] = 5.0
    layer(emit, emission)
    lit = rng.uniform(0.1, 1.0, (3, h, w)).astype(np.float32)
    direct = layer("direct", lit + emission if emission_in_direct else lit)
    indirect = layer("indirect", rng.uniform(0.0, 0.5, (3, h, w)).astype(np.float32))
    beauty = layer(colour, direct + indirect + (0 if emission_in_direct else emission))
    layer(albedo, np.full((3, h, w), 0.5, np.float32))
    for name, value in zip(normal, (0.0, 0.0, 1.0), strict=True):
        planes[prefix + name] = np.full((h, w), value, np.float32)
    planes[prefix + depth] = np.full((h, w), 3.0, np.float32)
    for name in motion:
        planes[prefix + name] = np.zeros((h, w), np.float32)
    write_exr(tmp_path / "d.exr", planes)
    pair = read_frame(tmp_path / "d.exr", build_mapping(preset, signals="direct-indirect"))
    assert pair.plan.set == "direct-indirect"
    np.testing.assert_allclose(pair.frame.signal("direct").radiance, lit, rtol=1e-6)
    np.testing.assert_allclose(pair.frame.total_radiance(), beauty, rtol=1e-6)


def test_arnold_lobes_need_no_albedo_aovs(tmp_path: Path) -> None:
    # Radiance-style lobe AOVs are not divided by a colour: without the albedo AOVs the lobe
    # set is still offered, each lobe filtered undemodulated (albedo 1).
    planes = _arnold_frame(tmp_path / "a.exr")
    kept = {n: p for n, p in planes.items() if not n.startswith(("diffuse_albedo",
                                                                   "specular_albedo"))}
    write_exr(tmp_path / "b.exr", kept)
    lobes = read_frame(tmp_path / "b.exr", build_mapping("arnold", signals="lobes"))
    assert lobes.plan.set == "lobes" and lobes.frame.names == ("diffuse", "glossy")
    assert all(np.all(lobes.frame.signal(n).albedo == 1.0) for n in ("diffuse", "glossy"))


def test_a_single_colour_pass_is_used_as_stored(tmp_path: Path) -> None:
    # Only a sum of colour passes is capped at 1; one pass (here Arnold's specular albedo,
    # above 1 on one pixel) demodulates its lobe with the values the renderer wrote.
    planes = _arnold_frame(tmp_path / "a.exr")
    planes["specular_albedo.G"][2, 3] = 1.5
    write_exr(tmp_path / "b.exr", planes)
    lobes = read_frame(tmp_path / "b.exr", build_mapping("arnold", signals="lobes"))
    albedo = np.stack([planes[f"specular_albedo.{c}"] for c in "RGB"])
    np.testing.assert_array_equal(lobes.frame.signal("glossy").albedo, albedo)


# ------------------------------------------------------------------ gradient samples


def test_traced_gradient_samples_are_attached_to_the_signals_they_measure() -> None:
    path = GLOSSY / "in.0004.exr"
    layers = channels(path)

    def samples(name: str) -> tuple[np.ndarray, np.ndarray]:
        return layers[f"gradient.{name}.prev"], layers[f"gradient.{name}.curr"]

    mask = layers["gradient.mask"]
    assert mask.sum() > 100
    by_set = {s: read_frame(path, build_mapping("svgf", signals=s)).frame for s in
              ("lobes", "lobes-split", "direct-indirect", "combined")}
    for name in ("diffuse", "glossy"):
        gradient = by_set["lobes"].signal(name).gradient
        assert gradient is not None
        np.testing.assert_array_equal(gradient.mask, mask)
        np.testing.assert_array_equal(gradient.previous, samples(name)[0])
        np.testing.assert_array_equal(gradient.current, samples(name)[1])
    for name in ("direct", "indirect"):
        gradient = by_set["direct-indirect"].signal(name).gradient
        np.testing.assert_array_equal(gradient.current, samples(name)[1])
    # The combined colour's samples are direct's + indirect's (luminance is linear).
    combined = by_set["combined"].signal("color").gradient
    np.testing.assert_array_equal(combined.previous, samples("direct")[0] + samples("indirect")[0])
    # The diffuse samples measure direct + indirect: neither diffuse signal of lobes-split.
    split = by_set["lobes-split"]
    assert split.signal("diffuse_direct").gradient is None
    assert split.signal("diffuse_indirect").gradient is None
    assert split.signal("glossy").gradient is not None


def test_gradient_samples_are_found_under_a_layer_prefix() -> None:
    # A compositor may put the tracer's layers under a view-layer prefix: the samples are
    # those next to the mask, whole sample names only, each with both of its halves.
    names = ["ViewLayer.gradient.mask", "ViewLayer.gradient.diffuse.prev",
             "ViewLayer.gradient.diffuse.curr", "ViewLayer.gradient.glossy.prev",
             "ViewLayer.gradient.a.b.prev", "ViewLayer.gradient.a.b.curr"]
    mask, samples = _gradient_channels(names)
    assert mask == "ViewLayer.gradient.mask"
    assert samples == {"diffuse": ("ViewLayer.gradient.diffuse.prev",
                                   "ViewLayer.gradient.diffuse.curr")}
