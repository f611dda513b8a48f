"""`-v` prints the wall milliseconds of every stage per frame (`run.filter.stage_line`)."""

from __future__ import annotations

from dataclasses import dataclass

from svgf_cli.run.filter import stage_line


class _Pipeline:
    def __init__(self, seconds: dict[str, float]) -> None:
        self.stage_seconds = seconds


class _Layered:
    def __init__(self) -> None:
        self.colour = _Pipeline({"values": 0.0123, "atrous": 0.5})
        self.groups = _Pipeline({"atrous": 0.25})
        self.params = object()


@dataclass(slots=True)
class _Slotted:
    value: int = 0


def test_stage_line_lists_stages_in_pipeline_order() -> None:
    assert stage_line(_Pipeline({"values": 0.0123, "atrous": 0.5})) == "values 12, atrous 500"


def test_stage_line_of_a_filter_made_of_pipelines_names_each() -> None:
    assert stage_line(_Layered()) == "colour: values 12, atrous 500; groups: atrous 250"


def test_stage_line_is_empty_for_other_filters() -> None:
    assert stage_line(object()) == ""
    assert stage_line(_Slotted()) == ""


def test_a_layered_denoiser_reports_its_light_layers_after_its_filters() -> None:
    """The real LayeredDenoiser on two frames of the production shot: the colour's and the
    groups' stages, then the light layers' own parts."""
    from pathlib import Path

    from svgf_cli.filters.composable import LayeredDenoiser
    from svgf_cli.filters.params import PRESETS
    from svgf_cli.io.exr import fix_signal_set, read_frame
    from svgf_cli.io.layers import build_mapping
    from svgf_cli.io.lightlayers import read_light_layers

    shot = Path(__file__).resolve().parents[1] / "testdata/cycles/production"
    mapping, _ = fix_signal_set(shot / "in.0001.exr", build_mapping("cycles"))
    layered = LayeredDenoiser(PRESETS["default"])
    for frame in (1, 2):
        result = read_frame(shot / f"in.{frame:04d}.exr", mapping)
        result.frame.light = read_light_layers(result, "cycles")
        layered.process(result.frame)
        line = stage_line(layered)
        colour, groups, layers = line.split("; ")
        assert colour.startswith("colour: values ") and groups.startswith("groups: values ")
        assert layers.startswith("layers: passes ") and ", groups " in layers


class _Detailed:
    def __init__(self) -> None:
        self.stage_seconds = {"reproject": 0.03}
        self.stage_detail_seconds = {"reproject": 0.01, "history_clamp": 0.02}


def test_stage_line_of_every_stage_reads_the_detail() -> None:
    assert stage_line(_Detailed(), "stage_detail_seconds") == "reproject 10, history_clamp 20"
    assert stage_line(_Detailed()) == "reproject 30"
    assert stage_line(_Pipeline({"values": 0.0}), "stage_detail_seconds") == ""


def test_a_denoiser_times_every_stage_that_ran_under_its_own_name() -> None:
    """The clocks group stages (reproject holds the history clamp and the anti-lag); the
    detail names each stage that ran, in pipeline order, and none that did not."""
    from test_filters_glossy import _highlight_frame

    from svgf_cli.filters.denoiser import Denoiser
    from svgf_cli.filters.params import PRESETS

    denoiser = Denoiser(PRESETS["default"])
    denoiser.process(_highlight_frame(0, marked=True))
    first = list(denoiser.stage_detail_seconds)
    assert "history_clamp" not in first  # no history to clamp on the first frame
    denoiser.process(_highlight_frame(1, marked=True))
    detail = list(denoiser.stage_detail_seconds)
    assert {"reproject", "history_clamp", "antilag", "atrous"} <= set(detail)
    assert "history_clamp" not in denoiser.stage_seconds  # it is in the reproject clock
    order = list(denoiser.stages)
    assert detail == sorted(detail, key=order.index)
    assert all(seconds >= 0.0 for seconds in denoiser.stage_detail_seconds.values())
