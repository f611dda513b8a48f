"""The declared pipelines (``filters.pipeline``) and buffers (``filters.buffers``)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from synthetic import make_frame

from svgf_cli.filters.buffers import SHARING, live_ranges
from svgf_cli.filters.denoiser import Denoiser
from svgf_cli.filters.params import PRESETS, SVGFParams
from svgf_cli.filters.pipeline import KINDS, build, stage_names, update_docs
from svgf_cli.filters.two_pass import ForwardPass, Keep, ReversePass
from svgf_cli.frame import Frame, Signal

ROOT = Path(__file__).resolve().parents[1]

TEMPORAL = ["values", "gradients", "demodulate", "reproject"]
DEFAULT_TEMPORAL = ["values", "fill_medium", "medium_coverage", "gradients",
                    "reflected_albedo", "reflected_lights", "demodulate", "medium_motion",
                    "reproject",
                    "object_history", "history_clamp", "antilag", "adopt_object_history",
                    "spread_fireflies"]


@pytest.mark.parametrize(("preset", "kind", "expected"), [
    ("paper", "causal", [*TEMPORAL, "accumulate", "variance", "atrous", "store_history",
                         "remodulate"]),
    ("falcor", "causal", [*TEMPORAL, "accumulate", "variance", "atrous", "store_history",
                          "remodulate"]),
    ("default", "causal", [*DEFAULT_TEMPORAL[:10], "history_gain", *DEFAULT_TEMPORAL[10:],
                           "accumulate", "temporal_albedo", "variance",
                           "atrous", "store_history", "emission_mean", "despike",
                           "remodulate", "despike_lone", "taa", "pixel_filter",
                           "edge_filter"]),
    ("paper", "forward", [*TEMPORAL, "capture", "accumulate", "pass_history",
                          "store_history"]),
    ("default", "forward", [*DEFAULT_TEMPORAL, "temporal_albedo", "capture", "accumulate",
                            "pass_history", "store_history"]),
    ("paper", "reverse", [*TEMPORAL, "combine", "accumulate", "pass_history", "variance",
                          "atrous", "store_history", "remodulate", "release_combination"]),
    ("default", "reverse", [*DEFAULT_TEMPORAL, "combine", "accumulate", "temporal_albedo",
                            "combine_albedo", "pass_history", "variance", "atrous",
                            "store_history", "emission_mean", "despike", "remodulate",
                            "despike_lone",
                            "taa", "pixel_filter", "edge_filter", "release_combination"]),
])
def test_stage_order_per_preset(preset: str, kind: str, expected: list[str]) -> None:
    assert stage_names(PRESETS[preset], kind) == expected


@pytest.mark.parametrize(("changes", "stages"), [
    ({"glossy_emitter_radiance": True}, ("reflected_lights",)),
    ({"reflected_albedo": True}, ("reflected_albedo",)),
    ({"firefly_clamp": 3.0}, ("firefly_clamp",)),
    ({"history_clamp": 3.0}, ("history_clamp",)),
    ({"glossy_history_clamp": 1.0}, ("history_clamp",)),
    ({"antilag": True}, ("antilag",)),
    ({"antilag": True, "object_history": True},
     ("antilag", "object_history", "adopt_object_history")),
    ({"spread_fireflies": 10.0}, ("spread_fireflies",)),
    ({"temporal_albedo": True}, ("temporal_albedo",)),
    ({"despike": 2.0}, ("despike", "despike_lone")),
    ({"taa": True}, ("taa",)),
    ({"still_emission_mean": True}, ("emission_mean",)),
    ({"pixel_filter": 0.05}, ("pixel_filter",)),
    ({"edge_filter": 0.05}, ("edge_filter",)),
])
def test_an_optional_stage_runs_only_when_its_setting_is_on(
    changes: dict[str, object], stages: tuple[str, ...],
) -> None:
    off, on = PRESETS["paper"], PRESETS["paper"].replace(**changes)
    for name in stages:
        assert name not in stage_names(off)
        assert name in stage_names(on)
    assert Denoiser(on).stages == tuple(stage_names(on))
    added = [name for name in stage_names(on) if name not in stage_names(off)]
    assert sorted(added) == sorted(stages)


def test_bidirectional_passes_have_their_own_stages() -> None:
    params = PRESETS["default"]
    assert ForwardPass(params).stages == tuple(stage_names(params, "forward"))
    assert ReversePass(params).stages == tuple(stage_names(params, "reverse"))
    assert "taa" in stage_names(params, "reverse")  # on its output frames, backwards
    assert "taa" not in stage_names(params.replace(taa_jittered=False), "forward")
    with pytest.raises(ValueError, match="unknown pipeline"):
        build(params, "sideways")


SETTINGS = [*PRESETS.values(), PRESETS["default"].replace(firefly_clamp=3.0, taa=True),
            PRESETS["falcor"].replace(firefly_clamp=3.0, despike=2.0)]


@pytest.mark.parametrize("params", SETTINGS)
@pytest.mark.parametrize("kind", KINDS)
def test_no_plane_is_handed_to_two_live_roles_at_once(params: SVGFParams, kind: str) -> None:
    """From the declared lifetimes: the roles sharing a host's memory never overlap."""
    names = stage_names(params, kind)
    ranges = live_ranges(names, params)
    assert {share.role for share, _, _ in ranges} >= {"depth_slope", "stale_colour"}
    for i, (a, a0, a1) in enumerate(ranges):
        for b, b0, b1 in ranges[i + 1:]:
            if a.host == b.host:
                assert a1 < b0 or b1 < a0, f"{a.role} and {b.role} share {a.host} in {names}"


def test_the_buffer_table_names_only_stages_that_exist() -> None:
    known = {name for params in SETTINGS for kind in KINDS
             for name in stage_names(params.replace(firefly_clamp=1.0, taa=True), kind)}
    for share in SHARING:
        assert set(share.since) | set(share.until) <= known, share


def test_the_pipeline_section_of_the_docs_is_current() -> None:
    assert update_docs(ROOT / "docs" / "development.md", write=False), (
        "run .venv/bin/python -m svgf_cli.filters.pipeline docs/development.md")


def _frames(count: int, signals: int) -> list[Frame]:
    frames = []
    for index in range(count):
        frame = make_frame(64, 48, noise=0.1, seed=index, split=signals != 1,
                           motion=(0.5, 0.0))
        if signals == 3:
            second = frame.signals[1]
            frame = dataclasses.replace(frame, signals=[
                *frame.signals,
                Signal("spec", second.radiance.copy(), second.albedo, glossy=True)])
        frames.append(frame)
    return frames


# held_bytes at 64x48 after 3 frames, measured before the pipeline was declared (issue 28).
HELD_BEFORE = {
    "default.1.causal": 408576, "default.1.forward": 408576, "default.1.reverse": 420864,
    "default.2.causal": 595968, "default.2.forward": 595968, "default.2.reverse": 620544,
    "default.3.causal": 798948, "default.3.forward": 798948, "default.3.reverse": 835812,
    "falcor.1.causal": 344064, "falcor.1.forward": 344064, "falcor.1.reverse": 356352,
    "falcor.2.causal": 528384, "falcor.2.forward": 528384, "falcor.2.reverse": 552960,
    "falcor.3.causal": 724992, "falcor.3.forward": 724992, "falcor.3.reverse": 761856,
    "paper.1.causal": 344064, "paper.1.forward": 344064, "paper.1.reverse": 356352,
    "paper.2.causal": 528384, "paper.2.forward": 528384, "paper.2.reverse": 552960,
    "paper.3.causal": 724992, "paper.3.forward": 724992, "paper.3.reverse": 761856,
}


@pytest.mark.parametrize("signals", [1, 2, 3])
@pytest.mark.parametrize("preset", ["paper", "default", "falcor"])
def test_held_bytes_are_not_larger_than_before(preset: str, signals: int) -> None:
    params, frames = PRESETS[preset], _frames(3, signals)
    causal = Denoiser(params)
    for frame in frames:
        causal.process(frame)
    forward = ForwardPass(params)
    kept = [forward.process(frame, Keep.COPY) for frame in frames]
    reverse = ReversePass(params)
    for t in (2, 1, 0):
        reverse.process(frames[t], kept[t] if t < 2 else None)
    for kind, held in (("causal", causal), ("forward", forward), ("reverse", reverse)):
        assert held.held_bytes() <= HELD_BEFORE[f"{preset}.{signals}.{kind}"], kind
