"""`--help` in sections: everyday options first, the filter parameters as --set; short."""

from __future__ import annotations

from pathlib import Path

import click
import pytest
from test_cli_support import run_cli, write_sequence

from svgf_cli.commands.denoise import command as denoise
from svgf_cli.commands.evaluate import command as evaluate
from svgf_cli.commands.options import FILTER_SECTION
from svgf_cli.commands.plan import command as plan
from svgf_cli.farm.plan import DEFAULT_WARMUP


def help_text(command: click.Command, width: int = 100) -> str:
    ctx = click.Context(command, info_name=command.name, terminal_width=width)
    return command.get_help(ctx)


def test_denoise_help_sections_in_order_and_fits_100_columns() -> None:
    text = help_text(denoise)
    titles = [
        "Input and output:",
        "Frames, warm-up and resume:",
        "Presets and layers:",
        "Run and progress:",
        "Farm chunks and Dask:",
        "Other options:",
        f"{FILTER_SECTION}:",
    ]
    positions = [text.index(t) for t in titles]
    assert positions == sorted(positions)
    # everyday options first; the filter parameters are set with --set, listed elsewhere
    assert text.index("--frames") < text.index("--warmup") < text.index("\n  --set NAME=VALUE")
    assert text.index("--preset-aovs") < text.index(FILTER_SECTION)
    assert text.index(FILTER_SECTION) < text.index("--list-params")
    assert "--alpha" not in text and "--history-clamp" not in text  # hidden aliases
    assert max(len(line) for line in text.splitlines()) <= 100


def test_denoise_help_is_short_at_80_columns() -> None:
    """Issue 28: everyday options only, one screen-ish (it was 298 lines)."""
    assert len(help_text(denoise, width=80).splitlines()) <= 120


def test_unlisted_options_land_in_the_default_section() -> None:
    extra = click.Option(["--brand-new"], is_flag=True, help="Added by someone else.")
    denoise.params.append(extra)
    try:
        text = help_text(denoise)
    finally:
        denoise.params.remove(extra)
    other = text.index("Other options:")
    assert other < text.index("--brand-new") < text.index(FILTER_SECTION)
    text = help_text(evaluate)  # no section table: everything but the filter in "Options"
    options = text.index("\nOptions:")
    assert options < text.index("-r, --reference", options) < text.index(FILTER_SECTION)
    assert text.index(FILTER_SECTION) < text.index("--preset ") < text.index("\n  --set NAME=VALUE")
    assert "--alpha" not in text


def test_plan_and_denoise_share_the_frame_options() -> None:
    """--frames, --warmup and --chunk-size are declared once (options.frame_options): the
    same help and type; plan requires --frames and --chunk-size, and denoise's warm-up
    default applies only with --frames (docs/farm.md)."""
    def option(command: click.Command, name: str) -> click.Option:
        return next(p for p in command.params if p.name == name)

    for name in ("frames_spec", "warmup", "chunk_size"):
        ours, theirs = option(denoise, name), option(plan, name)
        assert ours.opts == theirs.opts and type(ours.type) is type(theirs.type)
        assert ours.default == theirs.default
        assert ours.required is False and theirs.required is (name != "warmup")
    assert option(plan, "warmup").default == DEFAULT_WARMUP


@pytest.mark.parametrize(
    ("extra", "processed"),
    [
        (["--frames", "19-20"], f"process {21 - 2 - DEFAULT_WARMUP}-20"),  # bounded default
        (["--frames", "19-20", "--warmup", "all"], "process 1-20"),
        (["--frames", "19-20", "--warmup", "3"], "process 16-20"),
        ([], "process 1-20"),  # the whole sequence: unchanged, exact
    ],
)
def test_frame_ranges_get_a_bounded_default_warmup(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], processed: str
) -> None:
    write_sequence(tmp_path, range(1, 21), width=8, height=6)
    args = ["denoise", tmp_path / "in.####.exr", "-o", tmp_path / "o.####.exr", "--dry-run"]
    code, out, err = run_cli([*args, *extra], capsys)
    assert code == 0, err
    assert f"chunk 0: {processed} " in out
    defaulted = "the default with --frames" in out
    assert defaulted == (extra == ["--frames", "19-20"])
    if defaulted:
        assert f"warm-up {DEFAULT_WARMUP} (the default with --frames; on a 48-frame" in out


def test_warmup_value_errors_are_usage_errors(capsys: pytest.CaptureFixture[str]) -> None:
    plan = ["plan", "--frames", "1-9", "--chunk-size"]
    code, _, err = run_cli([*plan, "3", "--warmup", "-1"], capsys)
    assert code == 2 and err.startswith("ERROR: Invalid value for '--warmup': -1: must be >= 0")
    code, _, err = run_cli([*plan, "0"], capsys)
    assert code == 2 and "'--chunk-size': 0 is not in the range x>=1" in err
