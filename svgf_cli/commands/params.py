"""`svgf params [--preset NAME] [--group G]`: the filter parameters, their groups, valid
ranges, each preset's value (and why a preset departs from the paper) and meaning.

The text is made by ``options.parameter_listing`` from ``SVGFParams`` field metadata, the one
place each parameter is declared; ``svgf denoise --list-params`` prints the same.
"""

from __future__ import annotations

import click

from svgf_cli.commands.options import parameter_listing
from svgf_cli.filters.params import GROUPS, PRESETS


@click.command(
    "params",
    short_help="List the filter parameters, their ranges and presets.",
    context_settings={"help_option_names": ["-h", "--help"]},
)
@click.option(
    "--preset",
    type=click.Choice(list(PRESETS)),
    default=None,
    help="Show only this preset's values, with the reason for each departure from the "
    "paper [default: every preset's values].",
)
@click.option(
    "--group",
    type=click.Choice(list(GROUPS)),
    default=None,
    help="Show only this group of parameters.",
)
def command(preset: str | None, group: str | None) -> None:
    """List every filter parameter: its group, valid range, each preset's value and meaning.

    Set a parameter with `svgf denoise --set NAME=VALUE` (repeatable; also `svgf evaluate`
    and the arguments after `--` of `svgf plan`). The per-parameter options of earlier
    versions (--history-clamp 2) still work but are not listed in --help.
    """
    click.echo(parameter_listing(preset, group), nl=False)
