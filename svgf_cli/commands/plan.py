"""`svgf plan`: the chunk list of a farm submission: JSON, one command per chunk, the job
parameters of the OpenJD template, or a Deadline 10 job info / plugin info pair."""

from __future__ import annotations

import contextlib
import json
import shlex
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import click

from svgf_cli.commands.options import frame_options, warmup_label
from svgf_cli.errors import UsageError
from svgf_cli.farm.plan import plan_chunks
from svgf_cli.farm.submit import (
    OPENJD_TEMPLATE,
    FarmJob,
    deadline_files,
    openjd_job_parameters,
    write_key_values,
)
from svgf_cli.filters.params import DEFAULT_PRESET, PRESETS
from svgf_cli.io.patterns import format_frame_spec, parse_frame_spec

# Options `plan` sets on every chunk's command line; passing them after `--` would conflict.
_PLANNED_OPTIONS = ("-f", "--frames", "--warmup", "--chunk-size", "--workers", "--scheduler")


@click.command(
    "plan",
    short_help="Print the chunk list (JSON or commands) for farm submission.",
    context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100}
)
@frame_options(plan=True)
@click.option(
    "--first-frame",
    type=int,
    default=None,
    metavar="F",
    help="First frame of the sequence; warm-up never reads before it "
    "[default: the first frame of --frames].",
)
@click.option(
    "--last-frame",
    type=int,
    default=None,
    metavar="L",
    help="Last frame of the sequence; a --bidirectional run's warm-up after a chunk never "
    "reads past it [default: the last frame of --frames].",
)
@click.option(
    "--format",
    "output_format",
    type=click.Choice(["json", "commands", "openjd", "deadline"]),
    default="json",
    show_default=True,
    help="A JSON list, one command per chunk, the OpenJD template's job parameters (JSON), "
    "or Deadline 10 job info / plugin info files (written to --out).",
)
@click.option(
    "--executable",
    default="svgf",
    show_default=True,
    help="The svgf command on the farm workers (openjd, deadline).",
)
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    help="Folder for the Deadline submission files (--format deadline).",
)
@click.argument("denoise_args", nargs=-1, type=click.UNPROCESSED, metavar="[-- DENOISE_ARGS...]")
def command(
    frames_spec: str,
    chunk_size: int,
    warmup: int | None,
    first_frame: int | None,
    last_frame: int | None,
    output_format: str,
    executable: str,
    out_dir: Path | None,
    denoise_args: tuple[str, ...],
) -> None:
    """Split FRAMES into chunks with a causal warm-up, for farm submission.

    Each chunk reads [first - W, last] and writes [first, last] ([first - W, last + W] with
    --bidirectional among the denoise arguments: its reverse pass warms up after the
    chunk; a chunk that starts cold also reads 2N frames from its start for the warm start
    N of the denoise arguments or their preset). The arguments after `--`
    (inputs, -o, options) go into every chunk's `svgf denoise` command (--format commands,
    deadline) or into the OpenJD template's job parameters (--format openjd).
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
    end = frames[-1] if last_frame is None else last_frame
    if end < frames[-1]:
        raise UsageError(f"--last-frame {end} is before the last requested frame {frames[-1]}")
    bidirectional = _bidirectional(denoise_args)
    warmup_frames = warmup
    # The timeline is every frame of the sequence; the plan does not look at disk.
    timeline = list(range(start, end + 1))
    chunks = plan_chunks(frames, timeline, chunk_size=chunk_size, warmup=warmup_frames,
                         bidirectional=bidirectional, warm_start=_warm_start(denoise_args))
    if output_format == "json":
        click.echo(json.dumps([c.to_json() for c in chunks], indent=None))
        return
    if output_format in ("openjd", "deadline"):
        job = _farm_job(frames, chunk_size, warmup_label(warmup), executable, denoise_args)
        if output_format == "openjd":
            unmapped = _openjd_unmapped(denoise_args)
            if unmapped:
                option = unmapped[0]
                raise UsageError(
                    f"{OPENJD_TEMPLATE} has no job parameter for {option}; add it to the "
                    "template's args, or use --format deadline or commands"
                )
            click.echo(json.dumps(openjd_job_parameters(job), indent=2))
        else:
            _write_deadline(job, denoise_args, frames, out_dir)
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


def _denoise_setting(denoise_args: Sequence[str], name: str, convert: click.ParamType
                     ) -> Any:
    """The value the denoise arguments give parameter ``name`` (``--NAME V``, ``--NAME=V``,
    ``--set NAME=V``, and ``--NAME``/``--no-NAME`` for a flag), the last one winning; None
    when they give none. A value `denoise` would refuse is ignored (it refuses it itself)."""
    flag = "--" + name.replace("_", "-")
    found = None
    for i, arg in enumerate(denoise_args):
        text = None
        if convert is click.BOOL and arg in (flag, "--no-" + flag[2:]):
            found = arg == flag
        elif arg == flag and i + 1 < len(denoise_args):
            text = denoise_args[i + 1]
        elif arg.startswith(flag + "="):
            text = arg.removeprefix(flag + "=")
        setting = arg.removeprefix("--set=") if arg.startswith("--set=") else None
        if arg == "--set" and i + 1 < len(denoise_args):
            setting = denoise_args[i + 1]
        key, sep, value = (setting or "").partition("=")
        if sep and key.strip().replace("-", "_") == name:
            text = value
        if text is not None:
            with contextlib.suppress(click.BadParameter):
                found = convert.convert(text, None, None)
    return found


def _bidirectional(denoise_args: Sequence[str]) -> bool:
    """Whether the denoise arguments ask for a bidirectional run."""
    return bool(_denoise_setting(denoise_args, "bidirectional", click.BOOL))


def _warm_start(denoise_args: Sequence[str]) -> int:
    """The look-ahead warm start the denoise arguments run with: theirs, else their
    preset's (``--preset``, else the default one)."""
    given = _denoise_setting(denoise_args, "warm_start", click.INT)
    if given is not None:
        return int(given)
    preset = _denoise_setting(denoise_args, "preset", click.STRING) or DEFAULT_PRESET
    return PRESETS[preset].warm_start if preset in PRESETS else 0


# The denoise options the OpenJD template has a job parameter for (the rest must be added to
# the template's args by whoever needs them).
_OPENJD_OPTIONS = {"inputs", "output", "preset", "preset_aovs"}


def _farm_job(
    frames: list[int],
    chunk_size: int,
    warmup: str,
    executable: str,
    denoise_args: Sequence[str],
) -> FarmJob:
    """The job a farm repeats per chunk, from the denoise arguments (parsed by `denoise`)."""
    from svgf_cli.commands.denoise import command as denoise

    if not denoise_args:
        raise UsageError("give the denoise arguments after `--` (the input pattern and -o)")
    ctx = denoise.make_context("denoise", list(denoise_args))
    inputs = ctx.params["inputs"]
    if len(inputs) != 1:
        raise UsageError("a farm job needs one input pattern (e.g. in.####.exr), not a list")
    return FarmJob(
        input_pattern=inputs[0],
        output=ctx.params["output"],
        frames=format_frame_spec(frames).replace("x", ":"),  # OpenJD's step syntax
        chunk_size=chunk_size,
        warmup=warmup,
        preset=ctx.params["preset"],
        preset_aovs=ctx.params["preset_aovs"],
        executable=executable,
    )


def _openjd_unmapped(denoise_args: Sequence[str]) -> list[str]:
    from svgf_cli.commands.denoise import command as denoise

    ctx = denoise.make_context("denoise", list(denoise_args))
    given = [
        name
        for name in ctx.params
        if ctx.get_parameter_source(name) is click.core.ParameterSource.COMMANDLINE
    ]
    flags = {p.name: max(p.opts, key=len) for p in denoise.params}
    return [flags[name] for name in given if name not in _OPENJD_OPTIONS]


def _write_deadline(
    job: FarmJob, denoise_args: Sequence[str], frames: list[int], out_dir: Path | None
) -> None:
    if out_dir is None:
        raise UsageError("--format deadline writes two files: give the folder with --out DIR")
    if frames != list(range(frames[0], frames[-1] + 1)):
        raise UsageError(
            "--format deadline: Deadline passes each task as <STARTFRAME>-<ENDFRAME>, so the "
            "frames must be one contiguous range (use --format openjd or commands for steps)"
        )
    files = deadline_files(job, denoise_args, name=f"svgf denoise {job.input_pattern}")
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = {kind: out_dir / f"svgf_{kind}.job" for kind in files}
    for kind, values in files.items():
        write_key_values(paths[kind], values)
    click.echo(f"deadlinecommand {shlex.join(str(p) for p in paths.values())}")
