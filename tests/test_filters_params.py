"""The presets are what the user documentation says they are: every parameter of
``SVGFParams`` has a row in the table of docs/denoise.md with its ``paper`` and ``falcor``
values, and ``default`` is ``paper`` except for the options that page lists. (The filter
tests compare the kernels with the float64 reference under the same parameters, so a
changed preset value would pass them all.)"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest

from svgf_cli.filters.params import (
    AUTO_ITERATIONS,
    DEFAULT_PRESET,
    PRESETS,
    SVGFParams,
    atrous_iterations_for,
)

DOC = Path(__file__).resolve().parent.parent / "docs" / "denoise.md"


def _value(text: str, field: dataclasses.Field) -> object:
    if text in ("on", "off"):
        return text == "on"
    if text == "auto":
        return AUTO_ITERATIONS
    return int(text) if field.type in ("int", int) else float(text)


def _field(option: str) -> dataclasses.Field:
    """``--spatial-variance-radius`` or ``--temporal/--no-temporal``: the field it sets."""
    name = option.strip("`").split("/")[0].removeprefix("--").replace("-", "_")
    fields = {f.name: f for f in dataclasses.fields(SVGFParams)}
    assert name in fields, f"docs/denoise.md documents an unknown parameter {option}"
    return fields[name]


def _documented() -> tuple[dict[str, dict[str, object]], dict[str, object]]:
    """The table's paper and falcor columns by field name, and the options the text says
    ``default`` changes, with their values."""
    text = DOC.read_text()
    table = text.split("| option | paper | falcor | meaning |", 1)[1].split("\n\n", 1)[0]
    columns: dict[str, dict[str, object]] = {"paper": {}, "falcor": {}}
    for row in table.strip().splitlines()[1:]:
        option, paper, falcor = (cell.strip() for cell in row.strip("|").split("|")[:3])
        field = _field(option)
        columns["paper"][field.name] = _value(paper, field)
        columns["falcor"][field.name] = _value(falcor, field)
    sentence = re.search(r"same value in `default` as in `paper` except (.*?)\.\n\n", text,
                         re.S)
    assert sentence is not None
    changes = {}
    for option, value in re.findall(r"`(--[a-z-]+)`\s+\(([\w.]+)\)", sentence.group(1)):
        field = _field(option)
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


@pytest.mark.parametrize(("height", "width", "count"), [
    (72, 128, 3), (159, 4000, 3), (160, 160, 4), (1920, 319, 4), (320, 320, 5),
    (1080, 1920, 5), (2160, 4096, 5),
])
def test_auto_iterations_grow_with_the_shorter_side(height: int, width: int, count: int) -> None:
    auto = PRESETS["default"]
    assert auto.atrous_iterations == AUTO_ITERATIONS
    assert atrous_iterations_for(auto, height, width) == count


@pytest.mark.parametrize("explicit", [0, 1, 5, 12])
def test_an_explicit_iteration_count_is_kept(explicit: int) -> None:
    params = PRESETS["default"].replace(atrous_iterations=explicit)
    assert atrous_iterations_for(params, 72, 128) == explicit
    assert atrous_iterations_for(params, 2160, 4096) == explicit
