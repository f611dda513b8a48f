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
