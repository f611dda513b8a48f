"""`svgf denoise INPUTS... -o OUTPUT`: SVGF over an EXR sequence (wiring only).

The work lives elsewhere: `farm.job` resolves frames/outputs and checks them before anything
is written, `svgf_cli.run` (the file driver) runs the filter over the frames,
`farm.dask_backend` runs chunks on Dask.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import click

from svgf_cli import __version__
from svgf_cli.commands.options import (
    SectionedCommand,
    describe_params,
    frame_options,
    params_from_options,
    svgf_param_options,
    warmup_label,
)
from svgf_cli.errors import InputError, SvgfError, UsageError
from svgf_cli.farm.plan import DEFAULT_WARMUP, WARMUP_ERROR_NOTE
from svgf_cli.filters.params import (
    AUTO_ITERATIONS,
    AUTO_PIXEL_FILTER,
    AUTO_SAMPLES,
    SVGFParams,
    antilag_radius_for,
    atrous_iterations_for,
    colour_blend_for,
    params_for_samples,
    resolved_samples,
)
from svgf_cli.io.layers import AOV_PRESETS, MOTION_CONVENTIONS, SIGNAL_CHOICES
from svgf_cli.progress import PROGRESS_MODES, Progress

DEBUG_CHANNEL_EXAMPLE = ("variance", "history_length")  # data layers, for the codec check


def _check_combinations(o: dict[str, Any], bidirectional: bool) -> None:
    if bidirectional and (o["save_history"] or o["load_history"]):
        raise UsageError(
            "--save-history/--load-history continue a causal run; a bidirectional run "
            "replays warm-up on both sides instead (--warmup)"
        )
    if o["scratch_dir"] is not None and not bidirectional:
        raise UsageError("--scratch-dir is for --bidirectional runs")
    if o["workers"] is not None and o["scheduler"] is not None:
        raise UsageError("--workers and --scheduler contradict each other; give one")
    distributed = o["workers"] is not None or o["scheduler"] is not None
    if (o["save_history"] or o["load_history"]) and (distributed or o["chunk_size"]):
        raise UsageError(
            "--save-history/--load-history continue one sequential run; they cannot be "
            "combined with --chunk-size, --workers or --scheduler"
        )


# --help sections, everyday options first; an option named nowhere lands in "Other options",
# --set and --list-params in the filter section at the end. The per-parameter
# options (--alpha, --history-clamp, ...) are hidden aliases of --set.
SECTIONS = [
    ("Input and output", ["output", "colour_only", "float_output", "compression", "debug_aovs",
                          "light_layers"]),
    (
        "Frames, warm-up and resume",
        ["frames_spec", "warmup", "skip_existing", "overwrite", "allow_gaps", "save_history",
         "load_history"],
    ),  # fmt: skip
    ("Presets and layers", ["preset", "preset_aovs", "signals", "aovs", "motion_convention"]),
    (
        "Run and progress",
        ["bidirectional", "warm_start", "threads", "low_memory", "keep_memory", "scratch_dir",
         "progress_mode", "quiet", "verbose", "dry_run", "check_only"],
    ),
    ("Farm chunks and Dask", ["chunk_size", "workers", "scheduler"]),
]


@click.command(
    "denoise",
    cls=SectionedCommand,
    sections=SECTIONS,
    short_help="Denoise an EXR sequence with SVGF.",
    context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100},
)
@click.argument("inputs", nargs=-1, required=True, metavar="INPUTS...")
@click.option(
    "-o",
    "--output",
    required=True,
    metavar="PATTERN|DIR",
    help="Output pattern (den.####.exr, %04d, @, $F4) or a directory (same file names).",
)
@svgf_param_options
@click.option(
    "--preset-aovs",
    type=click.Choice(sorted(AOV_PRESETS)),
    default="svgf",
    show_default=True,
    help="Channel names of the renderer that wrote the inputs.",
)
@click.option(
    "--signals",
    type=click.Choice(SIGNAL_CHOICES),
    default="auto",
    show_default=True,
    help="Signals the light is filtered as: one per light lobe, lobes with diffuse direct "
    "and indirect apart, direct + indirect, or the combined colour; auto: the best set the "
    "first frame supports (docs/signals.md).",
)
@click.option(
    "--aov",
    "aovs",
    multiple=True,
    metavar="ROLE=CHANNELS",
    help="Override one role's channels, e.g. motion=Vector.X,Vector.Y (repeatable).",
)
@click.option(
    "--motion-convention",
    type=click.Choice(MOTION_CONVENTIONS),
    default=None,
    help="Meaning of the motion channels [default: the AOV preset's].",
)
@frame_options(plan=False)
@click.option("--allow-gaps", is_flag=True, help="A missing frame resets history (WARNING).")
@click.option(
    "--skip-existing",
    is_flag=True,
    help="Keep existing outputs; rebuild history for the first missing one by warm-up.",
)
@click.option("--overwrite", is_flag=True, help="Replace existing outputs.")
@click.option(
    "--float",
    "float_output",
    is_flag=True,
    help="Write the denoised colour as float [default: the input colour's pixel type].",
)
@click.option(
    "--colour-only",
    is_flag=True,
    help="Write only the colour layer and its alpha [default: every input channel too].",
)
@click.option(
    "--compression",
    metavar="CODEC",
    help="Output compression (zip, zips, piz, ...) [default: the input's]; lossy codecs are "
    "refused for data layers.",
)
@click.option(
    "--debug-aovs",
    is_flag=True,
    help="Also write variance, history length and the filtered direct/indirect (float).",
)
@click.option(
    "--light-layers",
    type=click.Choice(["denoised", "as-read"]),
    default="denoised",
    show_default=True,
    help="Light passes and light groups: denoised, adding up to the denoised colour, or as "
    "read.",
)
@click.option(
    "--save-history",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Save the filter history after the last frame (npz).",
)
@click.option(
    "--load-history",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Continue from a saved history (replaces warm-up).",
)
@click.option(
    "--scratch-dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    metavar="DIR",
    help="Where --bidirectional keeps the forward pass's state between the passes (about "
    "35 MB per 1080p output frame; removed when the run ends) [default: the system's "
    "temporary folder].",
)
@click.option(
    "--threads",
    type=click.IntRange(min=0),
    default=None,
    metavar="N",
    help="Compute and I/O threads (0 = all cores) [default: all].",
)
@click.option(
    "--low-memory",
    is_flag=True,
    help="Read each frame only once the frame before is filtered (while it is written): "
    "one decoded frame less in memory, reading no longer beside the filter (1080p "
    "80-channel Cycles frames: peak 2.7 against 3.4 GB, ~9 % slower).",
)
@click.option(
    "--keep-memory",
    is_flag=True,
    help="Keep the memory a frame frees for the next frame instead of giving it back to the "
    "system: faster where fresh memory is slow to touch (virtual machines), peak higher "
    "(1080p 80-channel Cycles frames: 0.7-0.8x the time, peak +0.5 to +1.8 GB).",
)
@click.option("-q", "--quiet", is_flag=True, help="No start-up log or automatic progress.")
@click.option("-v", "--verbose", is_flag=True, help="Per-frame timings and the chunk plan.")
@click.option(
    "--progress",
    "progress_mode",
    type=click.Choice(PROGRESS_MODES),
    default="auto",
    show_default=True,
    help="bar on a terminal, else one 'Progress: N%' line per frame.",
)
@click.option("--dry-run", is_flag=True, help="Check everything, print the plan, write nothing.")
@click.option(
    "--check-only",
    is_flag=True,
    help="Pre-flight: read every input frame in full (headers, channels, resolution, "
    "pixels); exit 3 if any is bad. Writes nothing.",
)
@click.option(
    "--workers",
    type=click.IntRange(min=1),
    default=None,
    metavar="N",
    help="Run chunks on a local Dask cluster of N worker processes.",
)
@click.option(
    "--scheduler",
    metavar="tcp://HOST:PORT",
    help="Run chunks on an existing Dask scheduler (shared storage).",
)
def command(**options: Any) -> None:
    """Denoise an EXR sequence with SVGF (Schied et al. 2017).

    INPUTS is one pattern (in.####.exr, in.%04d.exr, in.@.exr, in.$F4.exr, or a concrete
    frame such as in.1001.exr) or a list of files. Filter parameters: --preset and
    --set NAME=VALUE; `svgf params` lists them.
    """
    run = _start(options)
    signal_warning = _read_first_frame(run)
    for warning in run.job.warnings:
        run.progress.warning(warning)
    if signal_warning:
        run.progress.warning(signal_warning)
    if options["check_only"]:
        _check_inputs(run.job, run.mapping, run.progress)
        return
    if options["dry_run"]:
        for line in run.job.describe():
            click.echo(line)
        return
    if not _prepare_outputs(run):
        return
    stats = _execute(run)
    written = max(stats.frames_written, 1)
    run.progress.finish(
        f"Done: {stats.frames_written} frame(s) written, {stats.frames_processed} processed in "
        f"{stats.wall_seconds:.1f} s ({stats.wall_seconds / written:.2f} s/frame; read "
        f"{stats.read_seconds:.1f} s, compute {stats.compute_seconds:.1f} s, write "
        f"{stats.write_seconds:.1f} s)"
    )


@dataclass
class _Run:
    """What the steps of one `svgf denoise` share."""

    options: dict[str, Any]
    params: SVGFParams
    warmup: int | None
    warmup_note: str
    mapping: Any  # io.layers.LayerMapping; the signal set is fixed by _read_first_frame
    debug_names: list[str]
    history: Any  # the loaded --load-history, or None
    job: Any  # farm.job.Job
    progress: Progress
    threads: int
    # The first frame as _read_first_frame decoded it, for the run's reader to use once
    # (run.workers.FirstRead); None: read it again.
    first_read: Any = None

    @property
    def distributed(self) -> bool:
        return self.options["workers"] is not None or self.options["scheduler"] is not None


def _start(options: dict[str, Any]) -> _Run:
    """Everything checked before a frame is read: parameters, option combinations, layers,
    codec, history, the job (frames and outputs), progress and threads."""
    from svgf_cli.farm.job import build_job
    from svgf_cli.io.exr import check_compression, compression_name
    from svgf_cli.io.layers import build_mapping
    from svgf_cli.run.history import load_history

    params = params_from_options(options["preset"], options)
    warmup, warmup_note = _resolve_warmup(options)
    _check_combinations(options, params.bidirectional)
    mapping = build_mapping(
        options["preset_aovs"], options["aovs"], options["motion_convention"], options["signals"]
    )
    compression = options["compression"]
    debug_names = [f"svgf.{n}" for n in DEBUG_CHANNEL_EXAMPLE] if options["debug_aovs"] else []
    if compression is not None:
        compression_name(compression)
        check_compression(compression, ["R", "G", "B", "A", *debug_names])

    history = load_history(options["load_history"]) if options["load_history"] else None
    job = build_job(
        options["inputs"],
        options["output"],
        frames_spec=options["frames_spec"],
        warmup=warmup,
        allow_gaps=options["allow_gaps"],
        skip_existing=options["skip_existing"],
        overwrite=options["overwrite"],
        chunk_size=options["chunk_size"],
        history_last_frame=history.last_frame if history is not None else None,
        bidirectional=params.bidirectional,
        warm_start=params.warm_start,
    )
    progress = Progress(
        options["progress_mode"],
        job.frames_to_write,
        quiet=options["quiet"],
        verbose=options["verbose"],
    )
    threads = _apply_threads(options["threads"], options["workers"])
    return _Run(options, params, warmup, warmup_note, mapping, debug_names, history, job,
                progress, threads)


def _read_first_frame(run: _Run) -> str | None:
    """Resolve the layers and the signal set on the sequence's first frame, check the codec
    against its channels and log the start-up lines; return the signal set's warning."""
    from svgf_cli.io.exr import check_compression, fix_signal_set, read_info, refuse_multiview
    from svgf_cli.io.layers import resolve_layers, resolve_output_colour
    from svgf_cli.io.signals import plan_signals

    job, options = run.job, run.options
    first_input = job.chunk_tasks[0][0].input if job.chunk_tasks else job.timeline[0][1]
    info = read_info(first_input)
    refuse_multiview(info)
    resolved = resolve_layers(run.mapping, info.channels, str(first_input))
    # The signal set is decided once, on the sequence's first frame, so that every chunk and
    # farm task of a sequence filters the same signals (they cannot change mid-run).
    run.mapping, decided = fix_signal_set(job.timeline[0][1], run.mapping)
    if (decided.signal_warning is None and decided.plan is not None
            and decided.plan.set == run.mapping.signals):
        # The read with the fixed set would decode the same frame: the run reuses this one.
        run.first_read = (Path(job.timeline[0][1]), decided)
    resolved.plan = plan_signals(run.mapping, resolved, info.channels, str(first_input))
    resolved.requested_signals = options["signals"]
    colour = resolve_output_colour(run.mapping, info.channels)
    compression = options["compression"]
    if compression is not None and not options["colour_only"]:
        # Every input channel is written too: a lossy codec must not touch its data layers.
        check_compression(compression, [*info.channels, *run.debug_names])
    _log_start(run, info)
    run.progress.info(
        f"Layers ({options['preset_aovs']} AOVs, motion {run.mapping.motion_convention}, "
        f"from {first_input}):\n{resolved.describe()}\n  {info.luminance_weights.describe()}"
    )
    run.progress.info(
        f"Output: denoised colour as {', '.join(colour or ('R', 'G', 'B'))}"
        + ("" if colour else " (the input has no colour layer)")
        + ("; colour layer only" if options["colour_only"] else _light_text(run, options))
    )
    _log_frames(run)
    return decided.signal_warning


def _light_text(run: _Run, options: dict[str, Any]) -> str:
    if options["light_layers"] == "as-read":
        return "; every other channel as read"
    return ("; light layers (lobe passes, light groups) denoised, adding up to the colour; "
            "every other channel as read")


def _log_samples(run: _Run, header_samples: int, height: int, width: int) -> None:
    """What a frame of several samples per pixel changes (the header's count, or the
    setting's): the light's and the colours' blends and the anti-lag window."""
    params = run.params
    samples = resolved_samples(params, header_samples)
    if samples <= 1:
        return
    light = params_for_samples(params, samples).alpha
    radius = antilag_radius_for(params, height, width, samples)
    source = "the header's" if params.samples_per_pixel == AUTO_SAMPLES else "samples_per_pixel"
    run.progress.info(
        f"Samples: {samples} per pixel ({source}): the light blends at {light:.3g}, the colours'"
        f" means at {colour_blend_for(params, samples):.3g}, anti-lag window radius {radius}")


def _log_start(run: _Run, info: Any) -> None:
    """Version, threads, preset, every parameter, and what auto resolved to on ``info``."""
    from svgf_cli.filters.edge_filter import edge_filter_weight
    from svgf_cli.filters.pixel_filter import pixel_filter_weight
    from svgf_cli.io.exr import centre_sampled, samples_per_pixel

    params, progress = run.params, run.progress
    progress.info(f"svgf {__version__} denoise")
    progress.info(f"Threads: {run.threads}")
    if run.options["low_memory"]:
        progress.info("Memory: --low-memory (each frame read once the one before is filtered)")
    if run.options["keep_memory"]:
        progress.info("Memory: --keep-memory (freed frame memory kept for the next frame)")
    progress.info(f"Preset: {run.options['preset']}")
    progress.info(f"Parameters: {describe_params(params)}")
    if params.atrous_iterations == AUTO_ITERATIONS:
        samples = samples_per_pixel(info.attributes)
        count = atrous_iterations_for(params, info.height, info.width, samples)
        at = f" at {samples} samples per pixel" if samples > 1 else ""
        progress.info(f"A-trous: {count} iterations (auto, for {info.width}x{info.height}{at})")
    _log_samples(run, samples_per_pixel(info.attributes), info.height, info.width)
    if params.pixel_filter == AUTO_PIXEL_FILTER:
        centre = centre_sampled(info.attributes)
        weight = pixel_filter_weight(params.pixel_filter, centre)
        progress.info(f"Pixel filter: {weight:g} (auto: "
                      + ("the header says one sample through the pixel centre)" if centre
                         else "the header does not say the samples are pixel centres)"))
    if params.edge_filter == AUTO_PIXEL_FILTER:
        weight = edge_filter_weight(params.edge_filter, centre_sampled(info.attributes))
        progress.info(f"Edge filter: {weight:g} (auto, as the pixel filter)")
    if params.noisy_outline_weight > 0.0:
        progress.info(f"Noisy outlines: up to {params.noisy_outline_weight:g} more where over "
                      "30 % of a 5x5 window's pixel pairs change object (a defocused G-buffer)")


def _log_frames(run: _Run) -> None:
    """The frames line (to write, selected, on disk, warm-up, resume) and the bidirectional
    scratch folder."""
    job, history = run.job, run.history
    run.progress.info(
        f"Frames: {job.frames_to_write} to write of {len(job.selected)} selected, "
        f"{len(job.timeline)} on disk; warm-up {warmup_label(run.warmup)}"
        + (" before and after each chunk" if run.params.bidirectional else "")
        + run.warmup_note
        + (f"; {len(job.skipped_existing)} existing skipped" if job.skipped_existing else "")
        + (f"; history from {history.path} (frame {history.last_frame})" if history else "")
    )
    if run.params.bidirectional:
        from svgf_cli.run.bidirectional import scratch_note

        run.progress.info(
            "Bidirectional: a forward and a reverse pass, combined per pixel; forward "
            f"state kept in a scratch folder under {scratch_note(run.options['scratch_dir'])}"
        )


def _prepare_outputs(run: _Run) -> bool:
    """Remove dead runs' temporaries and create the output folders; False when every output
    exists already (nothing to do)."""
    from svgf_cli.io.atomic import remove_stale_temporaries

    job, progress = run.job, run.progress
    # Temporaries of these outputs left by dead runs (a SIGKILL inside a write); never
    # a live writer's, here or on another host (see svgf_cli.io.atomic).
    removed = remove_stale_temporaries(job.outputs.values())
    if removed:
        progress.info(f"Removed {len(removed)} temporary file(s) left by dead runs")
    if not job.chunks:
        progress.finish(f"Nothing to do: all {len(job.selected)} outputs exist")
        return False
    for path in sorted({p.parent for p in job.outputs.values()}):
        try:
            path.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            reason = "a file is in the way" if isinstance(exc, FileExistsError) else exc.strerror
            raise SvgfError(f"cannot create the output folder: {reason}", str(path)) from None
    for line in job.describe():
        progress.detail(line)
    return True


def _execute(run: _Run) -> Any:
    """Run every chunk, sequentially here or on Dask; return the runner's RunStats."""
    from svgf_cli.run.chunk import run_sequence
    from svgf_cli.run.stop import stop_on_signals
    from svgf_cli.run.tasks import RunConfig, RunStats
    from svgf_cli.run.workers import FirstRead, default_reader

    options = run.options
    config = RunConfig(
        params=run.params,
        preset=options["preset"],
        mapping=run.mapping,
        float_colour=options["float_output"],
        colour_only=options["colour_only"],
        light_layers=options["light_layers"],
        compression=options["compression"],
        debug_aovs=options["debug_aovs"],
        warmup_label=warmup_label(run.warmup),
        scratch_dir=options["scratch_dir"],
        low_memory=options["low_memory"],
        keep_memory=options["keep_memory"],
        # Dask workers set their own threads; a remote scheduler's workers keep theirs
        # unless --threads was given.
        threads=(run.threads if options["workers"] else options["threads"])
        if run.distributed else None,
    )
    if run.distributed:
        from svgf_cli.farm.dask_backend import run_chunks_dask

        with stop_on_signals(immediate=True):
            return run_chunks_dask(
                run.job.chunk_tasks,
                config,
                run.progress,
                workers=options["workers"],
                scheduler=options["scheduler"],
                overwrite=options["overwrite"],
            )
    stats = RunStats()
    # The first chunk's reader alone holds the first frame, and lets go of it when read.
    read = FirstRead(*run.first_read) if run.first_read is not None else default_reader
    run.first_read = None
    with stop_on_signals() as stop:
        for tasks in run.job.chunk_tasks:
            stats.merge(
                run_sequence(
                    tasks,
                    config,
                    run.progress,
                    stop=stop,
                    history=run.history,
                    save_history_to=options["save_history"],
                    read=read,
                )
            )
            read = default_reader
    return stats


def _resolve_warmup(options: dict[str, Any]) -> tuple[int | None, str]:
    """The warm-up and a note for the log: a frame range without --warmup gets the bounded
    default (a farm task must not replay the whole shot); the whole sequence stays exact."""
    source = click.get_current_context().get_parameter_source("warmup")
    if source is not click.core.ParameterSource.DEFAULT:
        return options["warmup"], ""
    if options["frames_spec"] is None:
        return None, ""
    return DEFAULT_WARMUP, f" (the default with --frames; {WARMUP_ERROR_NOTE})"


def _check_inputs(job: Any, mapping: Any, progress: Progress) -> None:
    """--check-only: read every input frame the job would read, in full, as the run would
    (header, channels, resolution, every pixel chunk). Each bad frame is one ``ERROR:``
    line; any bad frame makes the command exit 3 after all were checked."""
    from svgf_cli.io.exr import read_frame

    frames = sorted({(t.frame, t.input) for tasks in job.chunk_tasks for t in tasks})
    bad: list[SvgfError] = []
    size: tuple[int, int] | None = None
    size_source = None
    for _, path in frames:
        try:
            result = read_frame(path, mapping)
            shape = (result.frame.width, result.frame.height)
            if size is None:
                size, size_source = shape, path
            elif shape != size:
                raise InputError(
                    f"resolution {shape[0]}x{shape[1]} differs from {size[0]}x{size[1]} "
                    f"({size_source})",
                    str(path),
                )
            for message in result.warnings:
                progress.warning(str(message))
        except SvgfError as exc:
            bad.append(exc)
            click.echo(f"ERROR: {exc}", err=True)
    if bad:
        raise CheckFailed(f"check failed: {len(bad)} of {len(frames)} input frame(s) are bad")
    progress.finish(f"Check passed: {len(frames)} input frame(s) read in full")


class CheckFailed(InputError):
    """--check-only found bad frames (each already reported on its own line)."""


def _apply_threads(threads: int | None, workers: int | None) -> int:
    """Set numba/OpenImageIO threads for this process; return the per-process count."""
    import numba

    from svgf_cli.farm.dask_backend import set_compute_threads

    available = numba.config.NUMBA_NUM_THREADS
    if workers:
        # Each worker process gets its share unless --threads says otherwise.
        return threads or max(1, (os.cpu_count() or 1) // workers)
    count = threads or available
    set_compute_threads(count)
    return min(count, available)
