"""`svgf inspect FILE...`: what is in an EXR and which channels each role would use."""

from __future__ import annotations

import json
from typing import Any

import click
import numpy as np

from svgf_cli.errors import InputError
from svgf_cli.io.exr import (
    ExrInfo,
    TypedAttribute,
    centre_sampled,
    io_threads,
    read_frame,
    read_info,
    refuse_multiview,
    samples_per_pixel,
)
from svgf_cli.io.layers import (
    AOV_PRESETS,
    MOTION_CONVENTIONS,
    ROLES,
    SIGNAL_CHOICES,
    LayerMapping,
    ResolvedLayers,
    build_mapping,
    resolve_layers,
    resolve_output_colour,
)
from svgf_cli.io.signals import SignalPlan, SumCheck, plan_signals
from svgf_cli.io.source import decode_source


def _json_value(value: Any) -> Any:
    if isinstance(value, TypedAttribute):
        return _json_value(value.value)
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (tuple, list)):
        return [_json_value(v) for v in value]
    if isinstance(value, (str, int, float, bool)) or value is None:
        return value
    return str(value)


def _plan_report(plan: SignalPlan | None, check: SumCheck | None) -> dict[str, Any]:
    if plan is None:
        return {"signal_set": None, "signal_sets_offered": [], "signal_plan": []}
    channels = dict(plan.gradient_channels)
    report: dict[str, Any] = {
        "signal_set": plan.set,
        "signal_sets_offered": list(plan.offered),
        "signal_plan": [
            {
                "name": recipe.name,
                "terms": [{"light": list(t.light), "colour": t.colour} for t in recipe.terms],
                "albedo": list(recipe.albedo),
                "minus_emission": recipe.minus_emission,
                "gradient": {n: list(channels[n]) for n in recipe.gradient},
            }
            for recipe in plan.signals
        ],
        "emission_roles": list(plan.emission),
        "light_pass_check": plan.checked,
    }
    if check is not None:
        report["light_pass_check_result"] = {
            "pixels": check.pixels, "failing": check.failing, "share": check.share,
            "worst": check.worst, "passed": check.passed,
        }  # fmt: skip
    return report


def noisy_outline_pixels(frame: Any) -> float:
    """The share of the frame's pixels the default preset's noisy-outline exchange reaches
    (``filters.edge_filter``: over ``DENSE_FROM`` of the pixel pairs around them change
    object)."""
    from svgf_cli.filters.edge_filter import DENSE_FROM, outline_share

    return float(np.mean(outline_share(frame.mesh_id, frame.depth) > DENSE_FROM))


def frame_jittered(frame: Any) -> bool:
    """Whether the default preset's TAA runs on the frame (``taa_jittered``;
    ``filters.jitter.jittered_frame`` on the G-buffer as the filter cleans it)."""
    from svgf_cli.filters.jitter import jittered_frame
    from svgf_cli.filters.values import cleaned_depth, cleaned_normal

    return jittered_frame(frame.centre_sampled, cleaned_depth(frame.depth),
                          cleaned_normal(frame.normal), frame.mesh_id)


def _frame_lines(groups: list[str], noisy: float | None, jittered: bool,
                 additivity: list[Any]) -> list[str]:
    """The text report's lines after the header's: light groups, and what ``--check`` read
    in the frame."""
    lines = []
    if groups:
        lines.append(f"  light groups: {', '.join(groups)} (svgf denoise writes them "
                     "denoised, adding up to the colour)")
    if noisy is not None and noisy >= 0.0005:  # 0.05 %: a region, not a corner
        lines.append(f"  noisy outlines: {100 * noisy:.1f} % of the pixels (the G-buffer "
                     "changes object from pixel to pixel, as in a defocused region): the "
                     "default preset blurs them (noisy_outline_weight)")
    if jittered:
        lines.append("  jittered samples: the planes' depth is off the line of pixel centres "
                     "(each pixel's sample at a random point of it): the default preset "
                     "anti-aliases the outlines over time (taa_jittered)")
    lines.extend(f"  light-layer check: {result.describe()}" for result in additivity)
    return lines


def _report(
    info: ExrInfo,
    mapping: LayerMapping,
    resolved: ResolvedLayers,
    check: SumCheck | None = None,
) -> dict[str, Any]:
    return {
        "path": str(info.path),
        "width": info.width,
        "height": info.height,
        "compression": info.compression,
        "parts": [
            {
                "index": part.index,
                "name": part.name,
                "compression": part.compression,
                "tiled": part.tiled,
                "data_window": list(part.data_window),
                "channels": [
                    {"name": name, "type": kind}
                    for name, kind in zip(part.channels, part.channel_types, strict=True)
                ],
            }
            for part in info.part_info
        ],
        "display_window": list(info.display_window),
        "views": list(info.views),
        "luminance_weights": list(info.luminance_weights.weights),
        "luminance_weights_source": info.luminance_weights.source,
        "output_colour": list(resolve_output_colour(mapping, info.channels) or ("R", "G", "B")),
        "preset": mapping.preset,
        "motion_convention": mapping.motion_convention,
        "roles": {role: list(resolved[role] or ()) or None for role in ROLES},
        "signals": list(resolved.plan.names) if resolved.plan is not None else [],
        **_plan_report(resolved.plan, check),
        "missing": dict(resolved.missing),
        "notes": list(resolved.notes),
        "attributes": {k: _json_value(v) for k, v in sorted(info.attributes.items())},
    }


def _text(
    info: ExrInfo,
    mapping: LayerMapping,
    resolved: ResolvedLayers,
    check: SumCheck | None = None,
) -> str:
    dx, dy, dw, dh = info.display_window
    lines = [
        f"{info.path}",
        f"  resolution {info.width}x{info.height}, {len(info.part_info)} part(s), "
        f"compression {info.compression}, display window {dw}x{dh}+{dx}+{dy}",
    ]
    if info.views:
        lines.append(f"  views: {', '.join(info.views)} (multi-view: svgf denoise refuses it)")
    for part in info.part_info:
        label = f"part {part.index}" + (f" ({part.name})" if part.name else "")
        x, y, w, h = part.data_window
        lines.append(
            f"  {label}: {len(part.channels)} channel(s), {part.compression}, "
            f"{'tiled' if part.tiled else 'scanline'}, data window {w}x{h}+{x}+{y}"
        )
        for name, kind in zip(part.channels, part.channel_types, strict=True):
            lines.append(f"    {name:<28} {kind}")
    lines.append(f"  roles ({mapping.preset} preset, motion {mapping.motion_convention}):")
    lines.extend(f"  {line}" for line in resolved.describe().splitlines())
    if check is not None:
        verdict = "passed" if check.passed else "FAILED: svgf denoise filters the combined colour"
        lines.append(f"  light-pass check ({verdict}): {check.describe()}")
    lines.append(f"  {info.luminance_weights.describe()}")
    if centre_sampled(info.attributes):
        lines.append("  samples: one through the pixel centre (header): the default preset "
                     "applies the renderer's pixel filter (--pixel-filter auto)")
    elif (samples := samples_per_pixel(info.attributes)) > 1:
        lines.append(f"  samples: {samples} per pixel (header): the default preset blends each "
                     f"frame as {samples} one-sample frames (--set samples_per_pixel=auto)")
    colour = resolve_output_colour(mapping, info.channels)
    lines.append(
        f"  denoised colour written as: {', '.join(colour or ('R', 'G', 'B'))}"
        + ("" if colour else " (added: the file has no colour layer)")
    )
    if resolved.missing:
        lines.append(f"  missing: {', '.join(resolved.missing)}")
    else:
        lines.append("  missing: nothing; ready for svgf denoise")
    if info.attributes:
        lines.append(f"  attributes: {', '.join(sorted(info.attributes))}")
    return "\n".join(lines)


def _light_groups(info: ExrInfo, mapping: LayerMapping) -> list[str]:
    from svgf_cli.io.lightlayers import find_light_groups

    colour = resolve_output_colour(mapping, info.channels)
    return [name for name, _ in find_light_groups(info.channels, colour)]


def _additivity(name: str, mapping: LayerMapping, info: ExrInfo) -> list[Any]:
    """The light groups' sum and the light passes' rebuild against the colour (`svgf
    denoise` output or input alike)."""
    from svgf_cli.io.lightlayers import file_additivity

    if len(info.part_info) != 1:
        return []  # the light layers are composed within the colour's part
    return file_additivity(name, mapping)


def _denoised(info: ExrInfo) -> bool:
    return str(info.attributes.get("svgf/kind", "")) == "denoised"


@click.command("inspect", short_help="Show an EXR's parts, channels and resolved layer roles.")
@click.argument("files", nargs=-1, required=True, type=click.Path(dir_okay=False))
@click.option(
    "--preset-aovs",
    type=click.Choice(sorted(AOV_PRESETS)),
    default="svgf",
    show_default=True,
    help="Renderer layer-name preset used to resolve the roles.",
)
@click.option(
    "--aov",
    "aovs",
    multiple=True,
    metavar="ROLE=CHANNELS",
    help="Override a role's channels, e.g. motion=Vector.X,Vector.Y (repeatable).",
)
@click.option(
    "--motion-convention",
    type=click.Choice(MOTION_CONVENTIONS),
    default=None,
    help="How the motion layer is encoded (default: the preset's).",
)
@click.option(
    "--signals",
    type=click.Choice(SIGNAL_CHOICES),
    default="auto",
    show_default=True,
    help="Signal set to show (as `svgf denoise --signals`); --check also checks its light "
    "passes against the colour.",
)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON document for scripts.")
@click.option(
    "--check",
    is_flag=True,
    help="Pre-flight for farm jobs: also decode every pixel chunk; exit 3 when a file is "
    "truncated or corrupt, lacks a required role, or is multi-view.",
)
def command(
    files: tuple[str, ...],
    preset_aovs: str,
    aovs: tuple[str, ...],
    motion_convention: str | None,
    signals: str,
    as_json: bool,
    check: bool,
) -> None:
    """Show the parts, channels, compression and role mapping of EXR FILES."""
    mapping = build_mapping(preset_aovs, aovs, motion_convention=motion_convention,
                            signals=signals)
    reports: list[dict[str, Any]] = []
    failures: list[InputError] = []

    def fail(exc: InputError) -> None:
        failures.append(exc)
        if len(files) > 1:  # one line per bad file, then a summary
            click.echo(f"ERROR: {exc}", err=True)

    for index, name in enumerate(files):
        if check:
            try:
                info = read_info(name)
                refuse_multiview(info)
                # Every pixel chunk, as the denoiser will read it: truncation and corruption
                # show here, with the decoder's reason, not on the farm.
                decode_source(name, threads=io_threads(), expected_parts=len(info.parts))
            except InputError as exc:
                if len(files) == 1:
                    raise
                fail(exc)
                continue
        info = read_info(name)
        resolved = resolve_layers(mapping, info.channels, name, strict=False)
        resolved.plan = plan_signals(mapping, resolved, info.channels, name, strict=False)
        resolved.requested_signals = signals
        if check and resolved.missing:
            fail(InputError(f"missing channel(s) for {', '.join(resolved.missing)}", name))
        sum_check = noisy = is_jittered = None
        if check and not resolved.missing and resolved.plan is None:
            fail(InputError(f"no signal set possible ({'; '.join(resolved.notes)})", name))
        elif check and not resolved.missing:
            read = read_frame(name, mapping)
            # The light passes against the colour, as `svgf denoise` checks them on read.
            sum_check = read.sum_check if resolved.plan.checked else None
            noisy = noisy_outline_pixels(read.frame)
            is_jittered = frame_jittered(read.frame)
        additivity = _additivity(name, mapping, info) if check and not resolved.missing else []
        if as_json:
            report = _report(info, mapping, resolved, sum_check)
            report["light_groups"] = _light_groups(info, mapping)
            if noisy is not None:
                report["noisy_outline_pixels"] = noisy
                report["jittered_samples"] = is_jittered
            report["additivity"] = [
                {"what": a.what, "values": a.values, "failing": a.failing,
                 "worst_relative": a.worst_relative, "passed": a.passed} for a in additivity]
            reports.append(report)
        else:
            if index:
                click.echo("")
            click.echo(_text(info, mapping, resolved, sum_check))
            for line in _frame_lines(_light_groups(info, mapping), noisy, bool(is_jittered),
                                     additivity):
                click.echo(line)
        if _denoised(info) and any(not a.passed for a in additivity):
            fail(InputError("the denoised light layers do not add up to the colour", name))
    if as_json:
        click.echo(json.dumps({"files": reports}, indent=2))
    if failures:
        if len(files) == 1:
            raise failures[0]
        raise InputError(f"check failed: {len(failures)} of {len(files)} file(s) are not ready")
