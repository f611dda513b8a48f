"""`svgf plan`: print the chunk list of a farm submission (JSON or one command per chunk)."""

from __future__ import annotations

import json
import shlex

import click

from svgf_cli.commands.options import WARMUP, warmup_label
from svgf_cli.errors import UsageError
from svgf_cli.farm.plan import DEFAULT_WARMUP, plan_chunks
from svgf_cli.io.patterns import format_frame_spec, parse_frame_spec

# Options `plan` sets on every chunk's command line; passing them after `--` would conflict.
_PLANNED_OPTIONS = ("-f", "--frames", "--warmup", "--chunk-size", "--workers", "--scheduler")


@click.command(
    "plan",
    short_help="Print the chunk list (JSON or commands) for farm submission.",
    context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100}
)
@click.option(
    "-f",
    "--frames",
    "frames_spec",
    required=True,
    metavar="SPEC",
    help="Frames to write: 1001-1100, 1,5,7-9, 1001-1100x2.",
)
@click.option(
    "--chunk-size",
    type=click.IntRange(min=1),
    required=True,
    metavar="N",
    help="Output frames per chunk (one farm task each).",
)
@click.option(
    "--warmup",
    type=WARMUP,
    default=DEFAULT_WARMUP,
    show_default=True,
    metavar="N|all",
    help="Frames each chunk replays before its first output frame.",
)
@click.option(
    "--first-frame",
    type=int,
    default=None,
    metavar="F",
    help="First frame of the sequence; warm-up never reads before it "
    "[default: the first frame of --frames].",
)
@click.option(
    "--format",
    "output_format",
    type=click.Choice(["json", "commands"]),
    default="json",
    show_default=True,
    help="A JSON list, or one command per chunk.",
)
@click.argument("denoise_args", nargs=-1, type=click.UNPROCESSED, metavar="[-- DENOISE_ARGS...]")
def command(
    frames_spec: str,
    chunk_size: int,
    warmup: int | None,
    first_frame: int | None,
    output_format: str,
    denoise_args: tuple[str, ...],
) -> None:
    """Split FRAMES into chunks with a causal warm-up, for farm submission.

    Each chunk reads [first - W, last] and writes [first, last]. With --format commands,
    the arguments after `--` (inputs, -o, options) are put into one `svgf denoise` command
    per chunk.
    """
    try:
        frames = parse_frame_spec(frames_spec)
    except ValueError as exc:
        raise UsageError(f"--frames: {exc}") from None
    start = frames[0] if first_frame is None else first_frame
    if start > frames[0]:
        raise UsageError(f"--first-frame {start} is after the first requested frame {frames[0]}")
    clashes = [a for a in denoise_args if a.split("=")[0] in _PLANNED_OPTIONS]
    if clashes:
        raise UsageError(f"{clashes[0]} is set by the plan; remove it from the denoise arguments")
    warmup_frames = warmup
    # The timeline is every frame from the sequence start; the plan does not look at disk.
    timeline = list(range(start, frames[-1] + 1))
    chunks = plan_chunks(frames, timeline, chunk_size=chunk_size, warmup=warmup_frames)
    if output_format == "json":
        click.echo(json.dumps([c.to_json() for c in chunks], indent=None))
        return
    for chunk in chunks:
        warm = warmup_label(warmup_frames)
        words = [
            "svgf",
            "denoise",
            *denoise_args,
            "--frames",
            format_frame_spec(chunk.write),
            "--warmup",
            warm,
        ]
        click.echo(shlex.join(words))
