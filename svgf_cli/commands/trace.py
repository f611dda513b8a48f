"""`svgf trace`: render an animated OBJ scene into SVGF input frames (and references)."""

from __future__ import annotations

import os
import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import click

from svgf_cli.errors import OutputExistsError, UsageError
from svgf_cli.io.patterns import SequencePattern, parse_frame_spec
from svgf_cli.progress import Progress

if TYPE_CHECKING:
    from svgf_trace.animation import Animation
    from svgf_trace.render import TraceStats
    from svgf_trace.scene import Scene

_RESOLUTION = re.compile(r"^\s*(\d+)\s*[xX]\s*(\d+)\s*$")


def parse_resolution(text: str) -> tuple[int, int]:
    match = _RESOLUTION.match(text)
    if match is None:
        raise UsageError(f"--resolution {text!r}: expected WIDTHxHEIGHT, e.g. 640x360")
    width, height = int(match.group(1)), int(match.group(2))
    if width < 1 or height < 1 or width * height > 1 << 26:
        raise UsageError(f"--resolution {text!r}: width and height must be positive")
    return width, height


def _output_paths(pattern_text: str, frames: list[int], option: str) -> list[Path]:
    pattern = SequencePattern.parse(pattern_text)
    if not pattern.is_sequence and len(frames) > 1:
        raise UsageError(
            f"{option} {pattern_text!r} has no frame token (####, @, %04d, $F4) but "
            f"{len(frames)} frames are requested"
        )
    return [pattern.path(frame) for frame in frames]


def resolve_threads(threads: int) -> int:
    """Worker threads for Embree queries and shading kernels; 0 means every core."""
    return max(1, (os.cpu_count() or 1) if threads <= 0 else threads)


@click.command(name="trace", short_help="Path-trace an OBJ scene into SVGF input frames.")
@click.argument("scene", type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "-o", "--output", "output", required=True, metavar="PATTERN",
    help="Output frame pattern, e.g. 'seq/in.####.exr' (also @, %04d, $F4).",
)  # fmt: skip
@click.option("-f", "--frames", default="1", show_default=True, metavar="SPEC",
              help="Frames to render: 1-48, 1,5,7-9, 1-10x2.")
@click.option("--resolution", default="640x360", show_default=True, metavar="WxH",
              help="Image size in pixels.")
@click.option("--spp", type=click.IntRange(min=1), default=1, show_default=True,
              help="Samples per pixel.")
@click.option("--max-depth", type=click.IntRange(min=0), default=5, show_default=True,
              help="Maximum bounces (1 = direct lighting only; pbrt's convention).")
@click.option("--seed", type=int, default=0, show_default=True,
              help="Base seed; each frame's seed derives from (seed, frame).")
@click.option("--animation", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Camera/object keyframes (JSON); default: a static camera framing the scene.")
@click.option("--reference", default=None, metavar="PATTERN",
              help="Also write converged reference frames (R,G,B + direct/indirect, float).")
@click.option("--reference-spp", type=click.IntRange(min=1), default=512, show_default=True,
              help="Samples per pixel of the references (traced in memory-bounded batches).")
@click.option("--reference-supersample", type=click.IntRange(1, 16), default=1,
              show_default=True, metavar="K",
              help="Average each reference pixel over a KxK grid of positions (a box pixel "
                   "filter, --reference-spp / K^2 samples each), as a production renderer's "
                   "converged frame does; 1: the pixel centre, as the input.")
@click.option("--jitter", is_flag=True,
              help="Trace each input pixel's primary ray through a random position in the "
                   "pixel, a new one every frame (a box pixel filter, as Mitsuba's and most "
                   "renderers' one-sample frames), so the G-buffer is that sample's; pair it "
                   "with --reference-supersample.")
@click.option("--overwrite", is_flag=True, help="Replace existing output files.")
@click.option("--float", "float_radiance", is_flag=True,
              help="Write radiance layers as float instead of half.")
@click.option("--lobes", is_flag=True,
              help="Also write Cycles-style light passes: DiffDir/DiffInd/DiffCol, "
                   "GlossDir/GlossInd/GlossCol.")
@click.option("--motion-next", is_flag=True,
              help="Also write motion_next.X/Y: forward motion to the next frame, pixels.")
@click.option("--gradient-samples", is_flag=True,
              help="Also write A-SVGF temporal gradient samples against the previous frame "
                   "(gradient.*).")
@click.option("--skip-layer", "skip_layers", multiple=True,
              type=click.Choice(["P", "emission", "id"]),
              help="Leave this layer out of the input frames (repeatable); none is read by "
                   "svgf denoise.")
@click.option("--compression", default="piz", show_default=True,
              type=click.Choice(["piz", "zip", "zips", "rle", "none"]),
              help="EXR compression of all written files (lossless codecs only).")
@click.option("--reference-channels", "reference_layers", type=click.Choice(["full", "rgb"]),
              default="full",
              show_default=True,
              help="Reference layers: R,G,B + direct.* + indirect.* (full) or R,G,B only.")
@click.option("--reference-half", is_flag=True, help="Write references as half instead of float.")
@click.option("--threads", type=click.IntRange(min=0), default=0, show_default=True,
              help="Threads (0 = all cores).")
@click.option("-q", "--quiet", is_flag=True, help="No progress output.")
def command(
    scene: Path,
    output: str,
    frames: str,
    resolution: str,
    spp: int,
    max_depth: int,
    seed: int,
    animation: Path | None,
    reference: str | None,
    reference_spp: int,
    reference_supersample: int,
    jitter: bool,
    overwrite: bool,
    float_radiance: bool,
    lobes: bool,
    motion_next: bool,
    gradient_samples: bool,
    skip_layers: tuple[str, ...],
    compression: str,
    reference_layers: str,
    reference_half: bool,
    threads: int,
    quiet: bool,
) -> None:
    """Path-trace SCENE (OBJ + MTL) into SVGF input frames.

    Each frame holds R,G,B = direct + indirect, direct.*, indirect.*, emission.*, albedo.*,
    N.*, Z, P.*, motion.X/Y (backward, pixels) and id; primary rays go through pixel centres
    so the G-buffer is noise-free (--jitter: through a random position in each pixel).
    Optional: lobe passes (--lobes), motion to the next frame (--motion-next), A-SVGF
    gradient samples (--gradient-samples). See docs/trace.md.
    """
    width, height = parse_resolution(resolution)
    try:
        frame_list = parse_frame_spec(frames)
    except ValueError as exc:
        raise UsageError(f"--frames: {exc}") from exc
    _check_combinations(reference is not None, reference_half or reference_layers != "full",
                        jitter, gradient_samples)
    out_paths, ref_paths = _claim_outputs(output, reference, frame_list, overwrite)

    # Heavy imports only once the arguments are known to be good.
    from svgf_trace.animation import Animation, load_animation
    from svgf_trace.render import TraceStats
    from svgf_trace.scene import load_obj

    loaded = load_obj(scene)
    anim = (
        load_animation(animation, [o.name for o in loaded.objects]) if animation else Animation()
    )
    settings = _TraceSettings(
        width=width, height=height, spp=spp, max_depth=max_depth, seed=seed,
        reference_spp=reference_spp if reference else 0,
        reference_supersample=reference_supersample, jitter=jitter,
        float_radiance=float_radiance, lobes=lobes, motion_next=motion_next,
        gradient_samples=gradient_samples,
        skip_layers=skip_layers, compression=compression, reference_layers=reference_layers,
        reference_half=reference_half, threads=resolve_threads(threads),
    )  # fmt: skip
    for path in out_paths + ref_paths:
        path.parent.mkdir(parents=True, exist_ok=True)

    progress = Progress("auto", len(frame_list), quiet=quiet)
    progress.info(_summary(scene, loaded, settings))
    stats = TraceStats()
    started = time.perf_counter()
    for index, frame in enumerate(frame_list):
        frame_started = time.perf_counter()
        ref_path = ref_paths[index] if ref_paths else None
        _trace_frame(loaded, anim, frame, out_paths[index], ref_path, settings, stats)
        progress.frame_done(frame, time.perf_counter() - frame_started)
    elapsed = time.perf_counter() - started
    progress.finish(
        f"Wrote {len(frame_list)} frame(s) to {output}"
        + (f" and references to {reference}" if reference else "")
        + f" in {elapsed:.1f} s ({stats.rays / max(elapsed, 1e-9) / 1e6:.2f} Mrays/s)"
    )


def _check_combinations(reference: bool, reference_options: bool, jitter: bool,
                        gradient_samples: bool) -> None:
    """UsageError for options that need another or exclude one another."""
    if not reference and reference_options:
        raise UsageError("--reference-half and --reference-channels need --reference")
    if jitter and gradient_samples:
        raise UsageError("--gradient-samples re-traces the previous frame's pixel centres: "
                         "not with --jitter")


def _claim_outputs(
    output: str, reference: str | None, frame_list: list[int], overwrite: bool
) -> tuple[list[Path], list[Path]]:
    """The input and reference files to write; UsageError where they clash,
    OutputExistsError for an existing one without ``overwrite``."""
    out_paths = _output_paths(output, frame_list, "--output")
    ref_paths = _output_paths(reference, frame_list, "--reference") if reference else []
    clash = set(out_paths) & set(ref_paths)
    if clash:
        raise UsageError(f"--output and --reference name the same file {sorted(clash)[0]}")
    if not overwrite:
        for path in out_paths + ref_paths:
            if path.exists():
                raise OutputExistsError("output exists (use --overwrite to replace it)", str(path))
    return out_paths, ref_paths


@dataclass(frozen=True)
class _TraceSettings:
    """How every frame is traced and written (the command's options, checked)."""

    width: int
    height: int
    spp: int
    max_depth: int
    seed: int
    reference_spp: int  # 0: no reference
    reference_supersample: int
    jitter: bool
    float_radiance: bool
    lobes: bool
    motion_next: bool
    gradient_samples: bool
    skip_layers: tuple[str, ...]
    compression: str
    reference_layers: str
    reference_half: bool
    threads: int


def _summary(scene: Path, loaded: Scene, settings: _TraceSettings) -> str:
    """The line announcing what is traced."""
    s = settings
    return (
        f"Tracing {scene} ({loaded.triangle_count} triangles, {len(loaded.objects)} objects) "
        f"at {s.width}x{s.height}, {s.spp} spp, max depth {s.max_depth}, seed {s.seed}"
        + (f", reference {s.reference_spp} spp" if s.reference_spp else "")
        + "".join(f", {name}" for name, on in (("jittered samples", s.jitter),
                                                ("lobe passes", s.lobes),
                  ("motion_next", s.motion_next), ("gradient samples", s.gradient_samples))
                  if on)
        + f"; using {s.threads} threads on cpu"
    )  # fmt: skip


def _trace_frame(
    loaded: Scene,
    anim: Animation,
    frame: int,
    out_path: Path,
    ref_path: Path | None,
    settings: _TraceSettings,
    stats: TraceStats,
) -> None:
    """Render one frame (and its reference when ``ref_path`` is given) and write them."""
    from svgf_cli.io.exr import write_exr
    from svgf_trace.output import (
        frame_attributes,
        input_attributes,
        input_channels,
        reference_channels,
    )
    from svgf_trace.render import render_frame

    s = settings
    result, ref = render_frame(
        loaded, anim, frame, s.width, s.height, s.spp, s.max_depth, s.seed,
        reference_spp=s.reference_spp, threads=s.threads, stats=stats, lobes=s.lobes,
        motion_next=s.motion_next, gradient_samples=s.gradient_samples,
        reference_supersample=s.reference_supersample, jitter=s.jitter,
    )  # fmt: skip
    channels, half = input_channels(result, half_radiance=not s.float_radiance,
                                    skip=s.skip_layers)  # fmt: skip
    extra = input_attributes(lobes=s.lobes, motion_next=s.motion_next,
                             gradient_samples=s.gradient_samples)  # fmt: skip
    if s.jitter:
        extra["svgf/jitter"] = "box"
    attrs = frame_attributes(
        result, frame=frame, spp=s.spp, seed=s.seed, max_depth=s.max_depth, kind="input",
        extra=extra,
    )
    write_exr(out_path, channels, attributes=attrs, half=half, compression=s.compression)
    if ref is not None:
        assert ref_path is not None
        ref_attrs = frame_attributes(
            ref, frame=frame, spp=s.reference_spp, seed=s.seed, max_depth=s.max_depth,
            kind="reference",
            extra={"svgf/reference/supersample": s.reference_supersample}
            if s.reference_supersample > 1 else None,
        )
        write_exr(ref_path,
                  reference_channels(ref, rgb_only=s.reference_layers == "rgb"),
                  attributes=ref_attrs, half=s.reference_half,
                  compression=s.compression)  # fmt: skip
