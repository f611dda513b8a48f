"""The presets are what the user documentation says they are, and what they always were.

Every parameter of ``SVGFParams`` has a row in the table of docs/denoise.md with its group,
valid range, ``paper`` and ``falcor`` values; ``default`` is ``paper`` except for the
parameters that page lists, which are the preset's declared departures. Each preset's
resolved values are pinned to the values before presets became departure lists (they are
stored in every output's ``svgf/params``); ``default``'s
``feedback_iteration`` -1 since 2026-11-27 (docs/stability.md). (The filter tests compare
the kernels with the float64 reference under the same parameters, so a changed preset value
would pass them all.)
``check_params`` refuses a value outside the declared range with a message naming the
parameter, its value and the range."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest

from svgf_cli.filters.params import (
    AUTO_ITERATIONS,
    DEFAULT_PRESET,
    DEPARTURES,
    GROUPS,
    PRESETS,
    SVGFParams,
    antilag_radius_for,
    atrous_iterations_for,
    check_params,
    colour_blend_for,
    param_fields,
)

DOC = Path(__file__).resolve().parent.parent / "docs" / "denoise.md"
HEADER = "| parameter | group | values | paper | falcor | meaning |"

# Each preset's resolved values as they were before the presets became the paper's values
# plus departures (computed from the old PRESETS, 2026-11-27): they must never change, as
# every output stores them in svgf/params. Added since: warm_start (2026-11-27, issue 29),
# medium_fill_radius (2026-11-27, issue 30), medium_coverage_radius (2026-11-28),
# samples_per_pixel, noisy_outline_weight (2026-11-28, issue 30), medium_motion
# (2026-12-07, issue 30). Changed
# since: default's sigma_luminance 4 -> 2
# and mixed_sigma_luminance 2.5 -> 1.5 (2026-11-27, issue 29:
# docs/stability.md#a-tighter-luminance-stop).
PINNED: dict[str, dict[str, object]] = {
    "paper": {
        "alpha": 0.2, "moments_alpha": 0.2, "history_cap": 32, "temporal": True,
        "depth_tolerance": 10.0, "depth_slack": 0.002, "normal_tolerance": 16.0,
        "history_catmull_rom": False, "bidirectional": False, "variance_history_threshold": 4,
        "spatial_variance_radius": 3, "spatial_variance_sigma_luminance": 10.0,
        "spatial_variance_blur_color": False, "antilag": False, "antilag_radius": 2,
        "antilag_sigma": 3.5, "antilag_sigma_start": 2.0, "antilag_spatial_samples": 64.0,
        "antilag_tolerance": 0.02, "antilag_gain": False,
        "antilag_gradients": True, "object_history": False, "glossy_history_clamp": 0.0,
        "glossy_sigma_luminance": 0.0,
        "mixed_sigma_luminance": 0.0, "glossy_emitter_radiance": False, "reflected_albedo": False,
        "glossy_spread_fireflies": False, "glossy_heavy_tail": 0.0,
        "atrous_iterations": 5,
        "feedback_iteration": 0, "moving_feedback_share": 1.0, "sigma_luminance": 4.0,
        "sigma_normal": 128.0, "sigma_depth": 1.0, "luminance_stop_scale": 1.0,
        "luminance_guide_blur": False,
        "mixed_symmetric_stop": False,
        "albedo_epsilon": 0.001,
        "guide_albedo_floor": 0.0, "temporal_albedo": False, "albedo_catmull_rom": False,
        "firefly_clamp": 0.0, "spread_fireflies": 0.0, "history_clamp": 0.0,
        "history_clamp_radius": 1, "despike": 0.0,
        "pixel_filter": 0.0, "edge_filter": 0.0, "taa": False,
        "taa_jittered": False, "taa_alpha": 0.5, "still_emission_mean": False,
        "warm_start": 0,
        "medium_fill_radius": 0,
        "medium_coverage_radius": 0,
        "medium_motion": False,
        "samples_per_pixel": 1,
        "noisy_outline_weight": 0.0,
    },
    "default": {
        "alpha": 0.2, "moments_alpha": 0.2, "history_cap": 32, "temporal": True,
        "depth_tolerance": 10.0, "depth_slack": 0.002, "normal_tolerance": 16.0,
        "history_catmull_rom": False, "bidirectional": False, "variance_history_threshold": 4,
        "spatial_variance_radius": 3, "spatial_variance_sigma_luminance": 0.5,
        "spatial_variance_blur_color": False, "antilag": True, "antilag_radius": -1,
        "antilag_sigma": 3.5, "antilag_sigma_start": 2.0, "antilag_spatial_samples": 64.0,
        "antilag_tolerance": 0.02, "antilag_gain": True,
        "antilag_gradients": True, "object_history": True, "glossy_history_clamp": 1.0,
        "glossy_sigma_luminance": 1.0,
        "mixed_sigma_luminance": 1.5, "glossy_emitter_radiance": True, "reflected_albedo": True,
        "glossy_spread_fireflies": True, "glossy_heavy_tail": 2.0,
        "atrous_iterations": -1,
        "feedback_iteration": -1, "moving_feedback_share": 0.0, "sigma_luminance": 2.0,
        "sigma_normal": 128.0, "sigma_depth": 1.0, "luminance_stop_scale": -1.0,
        "luminance_guide_blur": True,
        "mixed_symmetric_stop": True,
        "albedo_epsilon": 0.001,
        "guide_albedo_floor": 0.1, "temporal_albedo": True, "albedo_catmull_rom": True,
        "firefly_clamp": 0.0, "spread_fireflies": 10.0, "history_clamp": 3.0,
        "history_clamp_radius": -1, "despike": 2.0,
        "pixel_filter": -1.0, "edge_filter": -1.0, "taa": False,
        "taa_jittered": True, "taa_alpha": 0.65, "still_emission_mean": True,
        "warm_start": 8,
        "medium_fill_radius": 4,
        "medium_coverage_radius": -1,
        "medium_motion": True,
        "samples_per_pixel": -1,
        "noisy_outline_weight": 0.25,
    },
    "falcor": {
        "alpha": 0.05, "moments_alpha": 0.2, "history_cap": 32, "temporal": True,
        "depth_tolerance": 10.0, "depth_slack": 0.002, "normal_tolerance": 16.0,
        "history_catmull_rom": False, "bidirectional": False, "variance_history_threshold": 4,
        "spatial_variance_radius": 3, "spatial_variance_sigma_luminance": 10.0,
        "spatial_variance_blur_color": True, "antilag": False, "antilag_radius": 2,
        "antilag_sigma": 3.5, "antilag_sigma_start": 2.0, "antilag_spatial_samples": 64.0,
        "antilag_tolerance": 0.02, "antilag_gain": False,
        "antilag_gradients": True, "object_history": False, "glossy_history_clamp": 0.0,
        "glossy_sigma_luminance": 0.0,
        "mixed_sigma_luminance": 0.0, "glossy_emitter_radiance": False, "reflected_albedo": False,
        "glossy_spread_fireflies": False, "glossy_heavy_tail": 0.0,
        "atrous_iterations": 4,
        "feedback_iteration": 1, "moving_feedback_share": 1.0, "sigma_luminance": 10.0,
        "sigma_normal": 128.0, "sigma_depth": 1.0, "luminance_stop_scale": 1.0,
        "luminance_guide_blur": False,
        "mixed_symmetric_stop": False,
        "albedo_epsilon": 0.001,
        "guide_albedo_floor": 0.0, "temporal_albedo": False, "albedo_catmull_rom": False,
        "firefly_clamp": 0.0, "spread_fireflies": 0.0, "history_clamp": 0.0,
        "history_clamp_radius": 1, "despike": 0.0,
        "pixel_filter": 0.0, "edge_filter": 0.0, "taa": False,
        "taa_jittered": False, "taa_alpha": 0.5, "still_emission_mean": False,
        "warm_start": 0,
        "medium_fill_radius": 0,
        "medium_coverage_radius": 0,
        "medium_motion": False,
        "samples_per_pixel": 1,
        "noisy_outline_weight": 0.0,
    },
}


def _value(text: str, field: dataclasses.Field) -> object:
    if text in ("on", "off"):
        return text == "on"
    if text == "auto":
        return AUTO_ITERATIONS
    return int(text) if field.type in ("int", int) else float(text)


def _field(name: str) -> dataclasses.Field:
    """```spatial_variance_radius```: the field it names."""
    name = name.strip("`")
    fields = {f.name: f for f in dataclasses.fields(SVGFParams)}
    assert name in fields, f"docs/denoise.md documents an unknown parameter {name}"
    return fields[name]


def _values_text(field: dataclasses.Field) -> str:
    valid = field.metadata["valid"]
    return "on, off" if valid is None else valid.text()


def _documented() -> tuple[dict[str, dict[str, object]], dict[str, object]]:
    """The table's paper and falcor columns by field name (checking its group and values
    columns against the declaration), and the parameters the text says ``default`` changes,
    with their values."""
    text = DOC.read_text()
    table = text.split(HEADER, 1)[1].split("\n\n", 1)[0]
    columns: dict[str, dict[str, object]] = {"paper": {}, "falcor": {}}
    for row in table.strip().splitlines()[1:]:
        name, group, values, paper, falcor = (c.strip() for c in row.strip("|").split(" | ")[:5])
        field = _field(name)
        assert group == field.metadata["group"], name
        assert values == _values_text(field), name
        columns["paper"][field.name] = _value(paper, field)
        columns["falcor"][field.name] = _value(falcor, field)
    sentence = re.search(r"same value in `default` as in `paper` except (.*?)\.\n\n", text,
                         re.S)
    assert sentence is not None
    changes = {}
    for name, value in re.findall(r"`([a-z_]+)`\s+\((-?[\w.]+)\)", sentence.group(1)):
        field = _field(name)
        changes[field.name] = _value(value, field)
    return columns, changes


def test_every_parameter_is_documented() -> None:
    columns, changes = _documented()
    names = {f.name for f in dataclasses.fields(SVGFParams)}
    assert set(columns["paper"]) == names == set(columns["falcor"])
    assert changes  # the default preset's differences are listed


@pytest.mark.parametrize("preset", ["paper", "falcor"])
def test_preset_values_are_the_documented_ones(preset: str) -> None:
    columns, _ = _documented()
    assert dataclasses.asdict(PRESETS[preset]) == columns[preset]


def test_default_preset_is_paper_with_the_documented_changes() -> None:
    columns, changes = _documented()
    assert DEFAULT_PRESET == "default"
    assert dataclasses.asdict(PRESETS["default"]) == {**columns["paper"], **changes}
    assert set(PRESETS) == {"default", "paper", "falcor"}
    assert {d.name: d.value for d in DEPARTURES["default"]} == changes


@pytest.mark.parametrize("preset", sorted(PINNED))
def test_presets_resolve_to_their_pinned_values(preset: str) -> None:
    assert dataclasses.asdict(PRESETS[preset]) == PINNED[preset]
    assert set(PINNED) == set(PRESETS)


@pytest.mark.parametrize("preset", sorted(DEPARTURES))
def test_each_departure_changes_the_paper_and_says_why(preset: str) -> None:
    paper = SVGFParams()
    names = [d.name for d in DEPARTURES[preset]]
    assert len(names) == len(set(names)), "a parameter departs twice"
    for departure in DEPARTURES[preset]:
        assert getattr(paper, departure.name) != departure.value, departure
        assert len(departure.reason) > 10 and "\n" not in departure.reason
    check_params(PRESETS[preset])


def test_every_field_has_a_group_help_and_a_range_unless_boolean() -> None:
    for field in param_fields():
        assert field.metadata["group"] in GROUPS, field.name
        assert field.metadata["help"], field.name
        is_bool = field.type in ("bool", bool)
        assert (field.metadata["valid"] is None) == is_bool, field.name


@pytest.mark.parametrize(
    ("name", "value", "message"),
    [
        ("alpha", 0.0, "alpha = 0.0: must be (0, 1]"),
        ("sigma_luminance", 0.0, "sigma_luminance = 0.0: must be > 0"),
        ("history_cap", 0, "history_cap = 0: must be >= 1"),
        ("antilag_radius", 17, "antilag_radius = 17: must be 1..16 or auto (auto is -1)"),
        ("despike", 0.5, "despike = 0.5: must be 0 (off) or >= 1"),
        ("atrous_iterations", -2, "atrous_iterations = -2: must be 0..12 or auto (auto is -1)"),
        ("pixel_filter", 0.5, "pixel_filter = 0.5: must be 0..1/3 or auto (auto is -1)"),
    ],
)
def test_check_params_names_the_parameter_its_value_and_range(
    name: str, value: object, message: str
) -> None:
    with pytest.raises(ValueError) as info:
        check_params(PRESETS["paper"].replace(**{name: value}))
    assert str(info.value) == message


@pytest.mark.parametrize(("height", "width", "count"), [
    (72, 128, 3), (159, 4000, 3), (160, 160, 4), (1920, 319, 4), (320, 320, 5),
    (1080, 1920, 5), (2160, 4096, 5),
])
def test_auto_iterations_grow_with_the_shorter_side(height: int, width: int, count: int) -> None:
    auto = PRESETS["default"]
    assert auto.atrous_iterations == AUTO_ITERATIONS
    assert atrous_iterations_for(auto, height, width) == count


@pytest.mark.parametrize(("samples", "fewer"), [(1, 0), (2, 0), (3, 0), (4, 1), (15, 1),
                                                (16, 2), (64, 3), (4096, 6)])
def test_auto_iterations_fall_by_one_per_factor_four_of_samples(samples: int,
                                                                fewer: int) -> None:
    auto = PRESETS["default"]
    assert atrous_iterations_for(auto, 1080, 1920, samples) == max(1, 5 - fewer)
    assert atrous_iterations_for(auto, 72, 128, samples) == max(1, 3 - fewer)
    # A count set by hand, or one sample said by the settings, keeps the image's count.
    assert atrous_iterations_for(auto.replace(samples_per_pixel=1), 1080, 1920, samples) == 5
    assert atrous_iterations_for(auto.replace(atrous_iterations=4), 1080, 1920, samples) == 4


@pytest.mark.parametrize(("samples", "radii"), [
    (1, (2, 4, 6)), (3, (2, 4, 6)), (4, (1, 2, 3)), (15, (1, 2, 3)), (16, (1, 1, 2)),
    (64, (1, 1, 1)),
])
def test_auto_antilag_window_halves_per_factor_four_of_samples(
        samples: int, radii: tuple[int, int, int]) -> None:
    """The window's area falls by 4 per factor 4 of samples (its side, rounded up, at least
    one cell), at 72, 216 and 360 rows; one set by hand, or one sample said by the
    settings, keeps the image's."""
    auto = PRESETS["default"]
    sizes = ((72, 128), (216, 384), (360, 640))
    assert tuple(antilag_radius_for(auto, h, w, samples) for h, w in sizes) == radii
    assert antilag_radius_for(auto.replace(antilag_radius=3), 216, 384, samples) == 3
    assert antilag_radius_for(auto.replace(samples_per_pixel=1), 360, 640, samples) == 6
    assert antilag_radius_for(auto.replace(samples_per_pixel=samples), 360, 640) == radii[2]


@pytest.mark.parametrize("alpha", [0.05, 0.2, 0.5])
def test_colour_blend_is_the_steady_gain_of_a_kalman_filter(alpha: float) -> None:
    """The colours' blend at N samples: ``K^2 / (1 - K) = N alpha^2 / (1 - alpha)``, growing
    with N, above one sample's and below the light's ``1 - (1 - alpha)^N``; ``alpha``
    itself (the same float) at one sample."""
    params = PRESETS["default"].replace(alpha=alpha)
    assert colour_blend_for(params, 1) == alpha
    previous = alpha
    for samples in (2, 4, 16, 64):
        gain = colour_blend_for(params, samples)
        assert gain**2 / (1.0 - gain) == pytest.approx(samples * alpha**2 / (1.0 - alpha))
        assert previous < gain < 1.0 - (1.0 - alpha) ** samples
        previous = gain
    assert colour_blend_for(params.replace(samples_per_pixel=1), 16) == alpha
    assert colour_blend_for(params.replace(samples_per_pixel=4), 1) == colour_blend_for(
        params, 4)
    assert colour_blend_for(params.replace(alpha=1.0), 4) == 1.0


@pytest.mark.parametrize("explicit", [0, 1, 5, 12])
def test_an_explicit_iteration_count_is_kept(explicit: int) -> None:
    params = PRESETS["default"].replace(atrous_iterations=explicit)
    assert atrous_iterations_for(params, 72, 128) == explicit
    assert atrous_iterations_for(params, 2160, 4096) == explicit
