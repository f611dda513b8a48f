"""Filter parameters on the command line (issue 28): `--set NAME=VALUE` sets every kind of
parameter with the range declared in ``SVGFParams`` metadata and refuses anything else with
exit 2; the per-parameter options of earlier versions still work, hidden, and mean the same;
the click types and ``check_params`` agree on every boundary; `svgf params` lists them all."""

from __future__ import annotations

import dataclasses
import json
import math
import re
from pathlib import Path
from typing import Any

import click
import pytest
from test_cli_support import run_cli, write_sequence

from svgf_cli.commands.denoise import command as denoise
from svgf_cli.commands.evaluate import command as evaluate
from svgf_cli.commands.options import PARAM_TYPES, param_fields, params_from_options
from svgf_cli.errors import UsageError
from svgf_cli.filters.params import (
    AUTO_ITERATIONS,
    AUTO_PIXEL_FILTER,
    DEPARTURES,
    GROUPS,
    PRESETS,
    check_params,
)

BASE = ["in.####.exr", "-o", "out.####.exr"]  # parsing only: nothing is read


def resolved(*args: str, command: click.Command = denoise, base: list[str] = BASE) -> Any:
    ctx = command.make_context(command.name, [*base, *args])
    return params_from_options(ctx.params["preset"], ctx.params)


@pytest.mark.parametrize(
    ("setting", "name", "value"),
    [
        ("alpha=0.3", "alpha", 0.3),  # float
        ("history_cap=8", "history_cap", 8),  # int
        ("history-clamp=2", "history_clamp", 2.0),  # dashes as in the old option names
        ("antilag=off", "antilag", False),  # booleans: on/off, true/false, 1/0
        ("antilag=FALSE", "antilag", False),
        ("antilag=0", "antilag", False),
        ("taa=on", "taa", True),
        ("taa=true", "taa", True),
        ("taa=1", "taa", True),
        ("atrous_iterations=auto", "atrous_iterations", AUTO_ITERATIONS),  # auto
        ("atrous_iterations=7", "atrous_iterations", 7),
        ("pixel_filter=auto", "pixel_filter", AUTO_PIXEL_FILTER),
        ("despike=0", "despike", 0.0),  # the off value outside the range
    ],
)
def test_set_sets_each_kind(setting: str, name: str, value: object) -> None:
    params = resolved("--preset", "paper", "--set", setting)
    assert getattr(params, name) == value
    assert type(getattr(params, name)) is type(value)
    assert params == PRESETS["paper"].replace(**{name: value})


def test_set_is_repeatable_and_a_later_value_wins() -> None:
    params = resolved("--set", "alpha=0.3", "--set", "sigma_luminance=6", "--set", "alpha=0.4")
    assert params == PRESETS["default"].replace(alpha=0.4, sigma_luminance=6.0)


@pytest.mark.parametrize(
    ("setting", "message"),
    [
        ("alpah=0.3", "no parameter 'alpah' (did you mean alpha?)"),
        ("alpha", "'alpha': expected NAME=VALUE"),
        ("alpha=1.5", "alpha: 1.5 is not in the range 0.0<x<=1.0 (alpha takes float in (0, 1])"),
        ("alpha=x", "alpha: 'x' is not a valid float range (alpha takes float in (0, 1])"),
        ("history_cap=0", "history_cap: 0 is not in the range x>=1 (history_cap takes int >= 1)"),
        ("antilag=maybe", "antilag: 'maybe' is not true|false (on|off, 1|0)"),
        ("atrous_iterations=13",
         "atrous_iterations: 13: must lie in 0..12 or be 'auto' (atrous_iterations takes int "
         "in 0..12 or auto)"),
        ("despike=0.5", "despike: 0.5: must be 0 (off) or >= 1"),
        ("sigma_normal=auto", "sigma_normal: 'auto' is not a valid float range"),
    ],
)
def test_set_refuses_bad_names_and_values_with_exit_2(
    capsys: pytest.CaptureFixture[str], setting: str, message: str
) -> None:
    code, _, err = run_cli(["denoise", *BASE, "--set", setting], capsys)
    assert code == 2
    assert err.startswith("ERROR: Invalid value for '--set': ")
    assert message in err


def test_a_hidden_parameter_option_still_works_and_equals_set(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The per-parameter options of earlier versions (farm templates, scripts) are hidden
    aliases: the same resolved parameters, the same start-up log; one parameter given both
    ways with two values is refused."""
    old = resolved("--preset", "falcor", "--sigma-luminance", "6", "--no-temporal",
                   "--atrous-iterations", "auto")
    new = resolved("--preset", "falcor", "--set", "sigma_luminance=6", "--set", "temporal=off",
                   "--set", "atrous_iterations=auto")
    assert old == new and old.to_json() == new.to_json()
    assert resolved("--alpha", "0.3", "--set", "alpha=0.3").alpha == 0.3
    with pytest.raises(UsageError, match="alpha is given twice"):
        resolved("--alpha", "0.3", "--set", "alpha=0.4")

    write_sequence(tmp_path, range(1, 3), width=8, height=6)
    logs = []
    for args in (["--history-clamp", "2", "--no-antilag"],
                 ["--set", "history_clamp=2", "--set", "antilag=off"]):
        code, out, err = run_cli(["denoise", tmp_path / "in.####.exr", "-o",
                                  tmp_path / "o.####.exr", "--dry-run", *args], capsys)
        assert code == 0, err
        logs.append(next(line for line in out.splitlines() if line.startswith("Parameters:")))
    assert logs[0] == logs[1] and "history_clamp=2.0" in logs[0] and "antilag=False" in logs[0]


def test_evaluate_takes_set_too() -> None:
    params = resolved("--set", "history_clamp=1", "--set", "taa=on", command=evaluate,
                      base=["den.####.exr", "-r", "ref.####.exr"])
    assert params == PRESETS["default"].replace(history_clamp=1.0, taa=True)


def _accepts_click(name: str, value: float) -> bool:
    try:
        PARAM_TYPES[name].convert(str(value), None, None)
    except click.BadParameter:
        return False
    return True


def _accepts_check(name: str, value: float) -> bool:
    try:
        check_params(PRESETS["paper"].replace(**{name: value}))
    except ValueError:
        return False
    return True


def _probes(field: dataclasses.Field) -> list[float]:
    valid = field.metadata["valid"]
    integer = field.type in ("int", int)
    values: list[float] = [0, 1, -1, 1e9, -1e9]
    for bound in (valid.low, valid.high, valid.auto, valid.off):
        if bound is None:
            continue
        if integer:
            values += [int(bound) - 1, int(bound), int(bound) + 1]
        else:
            values += [math.nextafter(bound, -math.inf), float(bound),
                       math.nextafter(bound, math.inf)]
    return [int(v) if integer else float(v) for v in values]


NUMERIC = [f for f in param_fields() if f.metadata["valid"] is not None]


@pytest.mark.parametrize("field", NUMERIC, ids=[f.name for f in NUMERIC])
def test_click_types_and_check_params_agree_on_every_boundary(field: dataclasses.Field) -> None:
    valid = field.metadata["valid"]
    for value in _probes(field):
        # the auto sentinel (-1 in svgf/params) is written `auto` on the command line
        via_click = _accepts_click(field.name, "auto" if value == valid.auto else value)
        assert via_click == _accepts_check(field.name, value), (field.name, value)
        assert via_click == valid.contains(value), (field.name, value)
    assert _accepts_click(field.name, "auto") == (valid.auto is not None)


def test_svgf_params_lists_every_parameter_with_group_range_and_presets(
    capsys: pytest.CaptureFixture[str],
) -> None:
    code, out, err = run_cli(["params"], capsys)
    assert code == 0, err
    for field in param_fields():
        assert f"\n  {field.name} = " in out, field.name
    for group in GROUPS:
        assert f"\n{group}: " in out
    assert "\n  alpha = float in (0, 1]\n      paper 0.2, default 0.2, falcor 0.05\n" in out
    assert max(len(line) for line in out.splitlines() if "docs/" not in line) <= 80
    code, listed, _ = run_cli(["denoise", "--list-params"], capsys)
    assert code == 0 and listed == out  # one place makes the text


def test_svgf_params_by_preset_gives_the_reasons_and_by_group_one_group(
    capsys: pytest.CaptureFixture[str],
) -> None:
    code, out, _ = run_cli(["params", "--preset", "default"], capsys)
    assert code == 0
    for departure in DEPARTURES["default"]:
        assert f"why default: {departure.reason.split(':')[0]}" in " ".join(out.split())
    assert "falcor" not in out.split("\n", 1)[1].split("why")[0]
    code, out, _ = run_cli(["params", "--group", "antilag"], capsys)
    assert code == 0
    names = re.findall(r"^  (\w+) = ", out, re.M)
    assert names == [f.name for f in param_fields() if f.metadata["group"] == "antilag"]
    code, _, err = run_cli(["params", "--group", "nope"], capsys)
    assert code == 2 and "'nope' is not one of" in err


def test_plan_sees_set_bidirectional(capsys: pytest.CaptureFixture[str]) -> None:
    """`svgf plan` warms a bidirectional chunk up on both sides, however it is asked for."""
    plan = ["plan", "--frames", "5-8", "--chunk-size", "2", "--warmup", "1", "--last-frame",
            "9", "--"]
    outputs = []
    for args in (["--bidirectional"], ["--set", "bidirectional=on"], ["--set=bidirectional=1"],
                 ["--set", "bidirectional=on", "--no-bidirectional"], []):
        code, out, err = run_cli([*plan, *BASE, *args], capsys)
        assert code == 0, err
        outputs.append(json.loads(out))
    assert outputs[0] == outputs[1] == outputs[2] != outputs[3] == outputs[4]
