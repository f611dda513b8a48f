"""The `svgf` command group: wires the subcommands, maps errors to exit codes."""

from __future__ import annotations

import importlib
import sys

import click

from svgf_cli import __version__
from svgf_cli.errors import EXIT_RUNTIME, SvgfError
from svgf_cli.heap import map_large_blocks
from svgf_cli.openmp import wait_passively

# Subcommand name -> module defining a click command named `command`. Imported lazily so
# `svgf --help` does not pay for numba or OpenImageIO.
COMMANDS = {
    "denoise": "svgf_cli.commands.denoise",
    "trace": "svgf_cli.commands.trace",
    "evaluate": "svgf_cli.commands.evaluate",
    "plan": "svgf_cli.commands.plan",
    "params": "svgf_cli.commands.params",
    "inspect": "svgf_cli.commands.inspect",
}


class LazyGroup(click.Group):
    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(COMMANDS)

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        module = COMMANDS.get(cmd_name)
        if module is None:
            return None
        return importlib.import_module(module).command


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="svgf")
def cli() -> None:
    """Spatiotemporal Variance-Guided Filtering for OpenEXR sequences."""


def main(argv: list[str] | None = None) -> None:
    """Console entry point: one-line `ERROR:` messages and published exit codes."""
    # Before any frame is read: blocks already in a heap arena would stay there.
    map_large_blocks()
    # Before the first parallel kernel loads the OpenMP runtime (it reads this once).
    wait_passively()
    try:
        cli.main(args=argv, prog_name="svgf", standalone_mode=False)
    except click.exceptions.Abort:
        click.echo("ERROR: aborted", err=True)
        sys.exit(130)
    except click.ClickException as exc:
        click.echo(f"ERROR: {exc.format_message()}", err=True)
        sys.exit(exc.exit_code)
    except click.exceptions.Exit as exc:
        sys.exit(exc.exit_code)
    except SvgfError as exc:
        click.echo(f"ERROR: {exc}", err=True)
        sys.exit(exc.exit_code)
    except KeyboardInterrupt:
        click.echo("ERROR: interrupted", err=True)
        sys.exit(130)
    except Exception as exc:  # noqa: BLE001 - last resort: one line, not a traceback
        click.echo(f"ERROR: {type(exc).__name__}: {exc}", err=True)
        sys.exit(EXIT_RUNTIME)
    sys.exit(0)
