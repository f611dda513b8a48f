"""`svgf evaluate`: score a denoised sequence (and baselines) against a reference.

Wiring only: options -> EvaluationRequest -> run_evaluation -> table / JSON / plot / sheet.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from svgf_cli.commands.options import (
    SectionedCommand,
    params_from_options,
    svgf_param_options,
)
from svgf_cli.errors import InputError, SvgfError, UsageError
from svgf_cli.evaluate.baselines import BASELINES
from svgf_cli.io.layers import AOV_PRESETS, SIGNAL_CHOICES


def _frames(spec: str | None, option: str) -> list[int] | None:
    if spec is None:
        return None
    from svgf_cli.io.patterns import parse_frame_spec

    try:
        return parse_frame_spec(spec)
    except ValueError as exc:
        raise UsageError(f"{option}: {exc}") from exc


def _compare(values: tuple[str, ...]) -> list[tuple[str, str]]:
    pairs = []
    for value in values:
        name, sep, pattern = value.partition("=")
        if not sep or not name or not pattern:
            raise UsageError(f"--compare {value!r}: expected NAME=PATTERN")
        pairs.append((name, pattern))
    return pairs


def _jod_selection(jod: bool, methods: str | None, heat: str | None) -> list[str] | None:
    """``EvaluationRequest.jod``: None = every method, [] = none, else the named ones."""
    if methods is not None:
        names = [n.strip() for n in methods.split(",") if n.strip()]
        if not names:
            raise UsageError("--jod-methods names no method")
        return names if heat is None or "svgf" in names else [*names, "svgf"]
    return None if jod else (["svgf"] if heat is not None else [])


def _write_outputs(report: Any, contacts: Any, json_path: str | None, plot_path: str | None,
                   sheet_path: str | None, jod_map: str | None) -> None:
    """The JSON report, the plot, the contact sheet and the JOD heat map that were asked for."""
    if json_path:
        _write_text(json_path, report.to_json())
    if plot_path:
        from svgf_cli.evaluate.plot import write_plot

        write_plot(report, plot_path)
    if sheet_path:
        from svgf_cli.evaluate.contact import write_contact_sheet

        write_contact_sheet(report, contacts, sheet_path)
    if jod_map:
        from svgf_cli.evaluate.animation import write_heatmap

        write_heatmap(report, jod_map)


def _write_text(path: str, text: str) -> None:
    """Atomically (hidden unique temporary, then rename; see svgf_cli.io.atomic)."""
    from svgf_cli.io.atomic import write_atomically

    try:
        write_atomically(Path(path), lambda tmp: tmp.write_text(text, encoding="utf-8"))
    except OSError as exc:
        raise SvgfError(f"cannot write: {exc.strerror or exc}", path) from None


@click.command(
    "evaluate",
    cls=SectionedCommand,
    default_section="Options",
    short_help="Score denoised frames against references and baselines.",
    context_settings={"max_content_width": 100},
)
@click.argument("denoised", metavar="DENOISED_PATTERN")
@click.option(
    "--reference", "-r", required=True, metavar="PATTERN", help="Converged reference frames."
)
@click.option(
    "--input",
    "-i",
    "input_pattern",
    metavar="PATTERN",
    help="Noisy input frames (with G-buffer): adds an 'input' row; needed by --baseline.",
)
@click.option(
    "--baseline",
    "baselines",
    multiple=True,
    type=click.Choice(BASELINES),
    help="Also produce and score this method from --input (repeatable).",
)
@click.option(
    "--compare",
    "compare",
    multiple=True,
    metavar="NAME=PATTERN",
    help="Also score this denoised sequence (e.g. another preset's output) as method NAME "
    "(repeatable).",
)
@click.option("--frames", metavar="SPEC", help="Frames to evaluate, e.g. 1-10 or 1,5,9.")
@click.option("--json", "json_path", metavar="FILE", help="Write the full report as JSON.")
@click.option("--plot", "plot_path", metavar="FILE.png", help="Write per-frame error plots.")
@click.option(
    "--contact-sheet", "sheet_path", metavar="FILE.png", help="Write a labelled contact sheet."
)
@click.option(
    "--contact-frames",
    metavar="SPEC",
    help="Frames shown on the contact sheet [default: first, middle, last].",
)
@click.option(
    "--preset-aovs",
    "layers",
    type=click.Choice(sorted(AOV_PRESETS)),
    default="svgf",
    show_default=True,
    help="AOV channel-name preset used to read --input (as in `svgf denoise`).",
)
@click.option(
    "--signals",
    type=click.Choice(SIGNAL_CHOICES),
    default="auto",
    show_default=True,
    help="Signal set the --input frames are read as (as in `svgf denoise`).",
)
@click.option(
    "--jod",
    is_flag=True,
    help="Also score ColorVideoVDP video and still JOD (needs: pip install 'svgf[perceptual]').",
)
@click.option(
    "--jod-methods",
    metavar="A,B",
    help="Only these methods get a JOD (e.g. svgf,oidn) [default: every method]; implies --jod.",
)
@click.option(
    "--jod-map",
    "jod_map",
    metavar="FILE.png",
    help="Write where svgf's output differs visibly: ColorVideoVDP's heat map, mean over "
    "frames; implies --jod.",
)
@click.option("--per-frame", is_flag=True, help="Also print every method's per-frame table.")
@click.option("--quiet", "-q", is_flag=True, help="No progress lines on stderr.")
@svgf_param_options
def command(
    denoised: str,
    reference: str,
    input_pattern: str | None,
    baselines: tuple[str, ...],
    compare: tuple[str, ...],
    frames: str | None,
    json_path: str | None,
    plot_path: str | None,
    sheet_path: str | None,
    contact_frames: str | None,
    layers: str,
    signals: str,
    jod: bool,
    jod_methods: str | None,
    jod_map: str | None,
    per_frame: bool,
    quiet: bool,
    preset: str,
    **param_options: Any,
) -> None:
    """Score DENOISED_PATTERN (e.g. 'out/den.####.exr') against --reference.

    Per frame and as a mean: RMSE, relMSE, trimmed relMSE and hot pixels on linear
    radiance; PSNR, SSIM, FLIP and the temporal (flicker) error on tone-mapped images.
    With --input and --baseline the raw input, Intel OIDN, plain temporal accumulation and
    a-trous without temporal reuse are produced in memory and ranked alongside; --compare
    adds more denoised sequences (e.g. other presets). The SVGF parameter options set the
    parameters of the accumulate/atrous/forward/bidirectional baselines (use the ones the
    sequence was denoised with); --baseline forward --baseline bidirectional compares the
    causal filter with the bidirectional one (docs/bidirectional.md).
    """
    from svgf_cli.evaluate.contact import default_contact_frames
    from svgf_cli.evaluate.engine import EvaluationRequest, run_evaluation

    params = params_from_options(preset, param_options)
    frame_list = _frames(frames, "--frames")
    contact_list = _frames(contact_frames, "--contact-frames")
    if contact_list is not None and sheet_path is None:
        raise UsageError("--contact-frames needs --contact-sheet")
    if contact_list is None and sheet_path is not None:
        from svgf_cli.evaluate.engine import resolve_frames
        from svgf_cli.io.patterns import SequencePattern

        evaluated = resolve_frames(SequencePattern.parse(denoised), denoised, frame_list)
        contact_list = default_contact_frames(evaluated)

    request = EvaluationRequest(
        output=denoised,
        reference=reference,
        input=input_pattern,
        frames=frame_list,
        baselines=baselines,
        params=params,
        preset=preset,
        layers=layers,
        signals=signals,
        contact_frames=contact_list or (),
        compare=_compare(compare),
        jod=_jod_selection(jod, jod_methods, jod_map),
        jod_map=jod_map is not None,
    )
    log = None if quiet else (lambda msg: click.echo(f"evaluate: {msg}", err=True))
    report, contacts = run_evaluation(request, log=log)

    click.echo(report.format_table(per_frame=per_frame))
    _write_outputs(report, contacts, json_path, plot_path, sheet_path, jod_map)

    flagged = report.flagged
    if flagged:
        name, first = flagged[0]
        raise InputError(
            f"{len(flagged)} output frame(s) hold NaN or infinite pixels (first: {name} frame "
            f"{first.frame}, {first.nonfinite_pixels} pixel(s)); their scores are undefined",
            first.file,
        )
