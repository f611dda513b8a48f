"""`--help` in sections: everyday options first, filter parameters last, ranges shown."""

from __future__ import annotations

from pathlib import Path

import click
import pytest
from test_cli_support import run_cli, write_sequence

from svgf_cli.commands.denoise import command as denoise
from svgf_cli.commands.evaluate import command as evaluate
from svgf_cli.commands.options import FILTER_SECTION
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
    # everyday options before the first filter parameter; ranges from click's range types
    assert text.index("--frames") < text.index("--warmup") < text.index("--alpha")
    assert text.index("--preset-aovs") < text.index(FILTER_SECTION)
    assert "[0.0<x<=1.0]" in text and "[1<=x<=16]" in text and "[x>=1]" in text
    assert "--atrous-iterations N|AUTO" in text and "default: auto" in text
    assert max(len(line) for line in text.splitlines()) <= 100


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
    assert text.index(FILTER_SECTION) < text.index("--preset ") < text.index("--alpha")


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
