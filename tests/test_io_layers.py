"""Role -> channel resolution, presets, overrides and motion conventions."""

from __future__ import annotations

import numpy as np
import pytest

from svgf_cli.errors import InputError, UsageError
from svgf_cli.io.layers import (
    AOV_PRESETS,
    EMISSION_IN_DIRECT,
    LOBE_LIGHT_DIVIDED,
    PRESET_MOTION_CONVENTION,
    ROLES,
    build_mapping,
    describe_output_colour,
    parse_aov_override,
    resolve_layers,
    to_backward_pixels,
    to_next_pixels,
)

SVGF_CHANNELS = [
    "R", "G", "B", "A",
    "albedo.R", "albedo.G", "albedo.B",
    "N.X", "N.Y", "N.Z",
    "Z",
    "motion.X", "motion.Y",
]  # fmt: skip


def test_every_preset_covers_every_role() -> None:
    # (What describe() prints per role is tested in test_io_presets.py.)
    for preset, table in AOV_PRESETS.items():
        assert set(table) == set(ROLES), preset
    # ...and has its conventions: a preset missing here would silently get the defaults.
    for conventions in (EMISSION_IN_DIRECT, LOBE_LIGHT_DIVIDED, PRESET_MOTION_CONVENTION):
        assert set(conventions) == set(AOV_PRESETS)


def test_resolution_is_by_name_not_order() -> None:
    mapping = build_mapping()
    forward = resolve_layers(mapping, SVGF_CHANNELS, "f.exr")
    backward = resolve_layers(mapping, list(reversed(SVGF_CHANNELS)), "f.exr")
    for resolved in (forward, backward):
        assert resolved["normal"] == ("N.X", "N.Y", "N.Z")
        assert resolved["motion"] == ("motion.X", "motion.Y")
        assert resolved["color"] == ("R", "G", "B")
        assert resolved["alpha"] == ("A",)
        assert resolved["id"] is None
        assert resolved.signal_roles == ("color",)


def test_normal_rgb_fallback_and_split_signals() -> None:
    names = [
        n.replace("N.X", "N.R").replace("N.Y", "N.G").replace("N.Z", "N.B") for n in SVGF_CHANNELS
    ]
    names += ["direct.R", "direct.G", "direct.B", "indirect.B", "indirect.G", "indirect.R"]
    resolved = resolve_layers(build_mapping(), names, "f.exr")
    assert resolved["normal"] == ("N.R", "N.G", "N.B")
    assert resolved.split
    assert resolved.signal_roles == ("direct", "indirect")
    assert resolved["indirect"] == ("indirect.R", "indirect.G", "indirect.B")
    assert "color" not in resolved.roles_to_read()


def test_lone_direct_falls_back_to_color_with_a_note() -> None:
    resolved = resolve_layers(build_mapping(), [*SVGF_CHANNELS, "direct.R", "direct.G", "direct.B"])
    assert resolved.signal_roles == ("color",)
    assert any("without its partner" in note for note in resolved.notes)


def test_a_file_with_only_the_colour_has_no_partner_note() -> None:
    # The note is for a lone direct or indirect pass; a plain beauty file gets none.
    resolved = resolve_layers(build_mapping(), SVGF_CHANNELS)
    assert resolved.signal_roles == ("color",) and resolved.notes == []


def test_description_shows_absent_roles_but_not_absent_lobes() -> None:
    # `svgf inspect`: every basic role gets a line ("-" when absent); the many lobe roles
    # appear only when the file has them.
    lines = [line.strip() for line in
             resolve_layers(build_mapping(), SVGF_CHANNELS).describe().splitlines()]
    assert "emission: -" in lines and "id: -" in lines
    assert not any(line.startswith(("diffuse_direct", "glossy_color", "environment"))
                   for line in lines)


def test_output_colour_description_lists_what_evaluate_looks_for() -> None:
    # The words of `svgf evaluate`'s error for a file without a colour layer.
    assert describe_output_colour(build_mapping("cycles")) == (
        "Combined.R,Combined.G,Combined.B or Noisy Image.R,Noisy Image.G,Noisy Image.B")
    assert describe_output_colour(build_mapping("svgf", ["color=none"])) == "(none)"


def test_cycles_view_layer_prefix() -> None:
    names = [
        f"ViewLayer.{n}"
        for n in (
            "Combined.R", "Combined.G", "Combined.B", "Combined.A",
            "Denoising Albedo.R", "Denoising Albedo.G", "Denoising Albedo.B",
            "Normal.X", "Normal.Y", "Normal.Z",
            "Depth.Z",
            "Vector.X", "Vector.Y", "Vector.Z", "Vector.W",
        )
    ]  # fmt: skip
    mapping = build_mapping("cycles")
    assert mapping.motion_convention == "cycles"
    resolved = resolve_layers(mapping, names, "c.exr")
    assert resolved["color"] == (
        "ViewLayer.Combined.R",
        "ViewLayer.Combined.G",
        "ViewLayer.Combined.B",
    )
    assert resolved["normal"] == ("ViewLayer.Normal.X", "ViewLayer.Normal.Y", "ViewLayer.Normal.Z")
    assert resolved["depth"] == ("ViewLayer.Depth.Z",)
    assert resolved["motion"] == ("ViewLayer.Vector.X", "ViewLayer.Vector.Y")
    assert resolved["alpha"] == ("ViewLayer.Combined.A",)


def test_prefix_matching_is_whole_components_and_unambiguous() -> None:
    base = [n for n in SVGF_CHANNELS if not n.startswith("motion")]
    # "Xmotion.X" must not match "motion.X": only whole dotted components count.
    with pytest.raises(InputError, match="motion"):
        resolve_layers(build_mapping(), [*base, "Xmotion.X", "Xmotion.Y"], "f.exr")
    # Two view layers both holding motion: ambiguous, reported rather than guessed.
    two = [*base, "A.motion.X", "A.motion.Y", "B.motion.X", "B.motion.Y"]
    with pytest.raises(InputError, match=r"ambiguous \(A\.motion\.X, B\.motion\.X\)"):
        resolve_layers(build_mapping(), two, "f.exr")
    # A bare "R" never matches "albedo.R".
    no_beauty = [n for n in SVGF_CHANNELS if n not in ("R", "G", "B")]
    resolved = resolve_layers(build_mapping(), no_beauty, "f.exr", strict=False)
    assert resolved["color"] is None
    assert "color" in resolved.missing


def test_missing_channel_error_names_file_and_lists_channels() -> None:
    names = [n for n in SVGF_CHANNELS if not n.startswith("N.")]
    with pytest.raises(InputError) as err:
        resolve_layers(build_mapping(), names, "shots/f.1001.exr")
    message = str(err.value)
    assert "\n" not in message
    assert message.startswith("shots/f.1001.exr: missing channel(s) for normal")
    assert "N.X,N.Y,N.Z or N.R,N.G,N.B" in message
    assert "file has: R, G, B, A, albedo.R" in message
    assert err.value.exit_code == 3


def test_missing_channel_error_shortens_a_long_channel_list() -> None:
    # A deep compositing file can hold hundreds of channels: the one-line error lists 40.
    names = [n for n in SVGF_CHANNELS if not n.startswith("N.")]
    names += [f"extra{i}.R" for i in range(45)]
    with pytest.raises(InputError) as err:
        resolve_layers(build_mapping(), names, "f.exr")
    assert str(err.value).endswith(f", ... ({len(names) - 40} more)")


def test_an_override_with_nuke_style_names_matches_under_a_view_layer() -> None:
    # Nuke names RGB channels rgba.red/green/blue (names of different lengths).
    names = [n for n in SVGF_CHANNELS if n not in ("R", "G", "B")]
    names += ["ViewLayer.rgba.red", "ViewLayer.rgba.green", "ViewLayer.rgba.blue"]
    mapping = build_mapping("svgf", ["color=rgba.red,rgba.green,rgba.blue"])
    resolved = resolve_layers(mapping, names, "f.exr")
    assert resolved["color"] == ("ViewLayer.rgba.red", "ViewLayer.rgba.green",
                                 "ViewLayer.rgba.blue")


def test_overrides() -> None:
    assert parse_aov_override("motion=Vector.X,Vector.Y") == ("motion", ("Vector.X", "Vector.Y"))
    assert parse_aov_override(" Emission = none ") == ("emission", ())
    mapping = build_mapping("svgf", ["motion=Vector.X,Vector.Y", "normal=Nw"])
    assert mapping.candidates["motion"] == (("Vector.X", "Vector.Y"),)
    assert ("Nw.X", "Nw.Y", "Nw.Z") in mapping.candidates["normal"]
    assert mapping.overridden == ("motion", "normal")
    assert build_mapping("svgf", {"depth": "Pz"}).candidates["depth"][0] == ("Pz",)
    assert parse_aov_override("motion_next=Vector.Z,Vector.W")[1] == ("Vector.Z", "Vector.W")
    # The albedo is an RGB role: three channels, or a layer name expanded to them.
    assert parse_aov_override("albedo=DiffCol.R,DiffCol.G,DiffCol.B")[1] == (
        "DiffCol.R", "DiffCol.G", "DiffCol.B")
    assert build_mapping("svgf", ["albedo=DiffCol"]).candidates["albedo"][0] == (
        "DiffCol.R", "DiffCol.G", "DiffCol.B")
    names = [n for n in SVGF_CHANNELS if not n.startswith(("N.", "motion"))]
    names += ["Nw.R", "Nw.G", "Nw.B", "Vector.X", "Vector.Y"]
    resolved = resolve_layers(mapping, names, "f.exr")
    assert resolved["normal"] == ("Nw.R", "Nw.G", "Nw.B")
    assert resolved["motion"] == ("Vector.X", "Vector.Y")


@pytest.mark.parametrize("text", ["motion", "speed=a,b", "motion=a,b,c", "normal=a,,b", "=x"])
def test_bad_overrides_are_usage_errors(text: str) -> None:
    with pytest.raises(UsageError):
        parse_aov_override(text)


def test_bad_preset_and_convention() -> None:
    with pytest.raises(UsageError, match="preset"):
        build_mapping("vray")
    with pytest.raises(UsageError, match="motion convention"):
        build_mapping("svgf", motion_convention="sideways")
    assert build_mapping("cycles", motion_convention="backward-pixels").motion_convention == (
        "backward-pixels"
    )


def test_motion_conventions() -> None:
    xy = np.stack([np.full((2, 3), 1.5), np.full((2, 3), -2.0)]).astype(np.float32)
    backward = to_backward_pixels(xy, "backward-pixels")
    assert np.array_equal(backward, xy) and backward is xy  # canonical float32: no copy
    as_float64 = to_backward_pixels(xy.astype(np.float64), "backward-pixels")
    assert as_float64.dtype == np.float32 and np.array_equal(as_float64, xy)
    # forward: previous = current - v
    assert np.array_equal(to_backward_pixels(xy, "forward-pixels"), -xy)
    # Cycles: XY = prev - cur with +Y up; our rows run down, so only Y flips
    cycles = to_backward_pixels(xy, "cycles")
    assert np.array_equal(cycles[0], xy[0]) and np.array_equal(cycles[1], -xy[1])
    for convention in ("backward-pixels", "forward-pixels", "cycles"):
        out = to_backward_pixels(xy, convention)
        assert out.dtype == np.float32 and out.flags.c_contiguous
    with pytest.raises(ValueError):
        to_backward_pixels(xy, "nope")
    with pytest.raises(ValueError):
        to_backward_pixels(xy[0], "cycles")


def test_resolved_description_marks_only_the_colour_the_split_signals_replace() -> None:
    # What `svgf inspect` shows: the user must see which colour layer the filter ignores.
    names = [*SVGF_CHANNELS, "direct.R", "direct.G", "direct.B",
             "indirect.R", "indirect.G", "indirect.B"]
    lines = resolve_layers(build_mapping(), names).describe().splitlines()
    unused = [line.split(":")[0].strip() for line in lines if "(present, not used)" in line]
    assert unused == ["color"]
    stripped = [line.strip() for line in lines]
    assert "depth: Z" in stripped and "signals: direct + indirect" in stripped
    assert not [line for line in lines if "note:" in line]  # nothing absent is "ambiguous"


def test_cycles_next_motion_flips_only_x() -> None:
    # Cycles' Vector.Z/W is current - next with y up: forward pixels flip x only (y up and
    # "current - next" cancel for y).
    xy = np.stack([np.full((2, 3), 1.5, np.float32), np.full((2, 3), -0.25, np.float32)])
    forward = to_next_pixels(xy, "cycles")
    np.testing.assert_array_equal(forward[0], -xy[0])
    np.testing.assert_array_equal(forward[1], xy[1])
