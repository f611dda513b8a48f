"""What is written for one denoised frame: the colour converted by the output value policy,
where it goes in the input's layout, the debug channels and the ``svgf/*`` provenance
(`build_output` -> `OutputFrame`, `output_attributes`). The writer thread
(`workers.WriteBehind`) writes it.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from svgf_cli import __version__
from svgf_cli.frame import DenoisedFrame, LightLayers
from svgf_cli.run.stages import run_stages
from svgf_cli.run.tasks import FrameTask, RunConfig

if TYPE_CHECKING:
    from svgf_cli.io.exr import ReadResult
    from svgf_cli.io.source import SourceFile, SourcePart

# Prefix of the debug channels (--debug-aovs): a layer name no renderer writes, so they
# never collide with an input layer that is passed through.
DEBUG_PREFIX = "svgf."


def output_attributes(config: RunConfig, task: FrameTask) -> dict[str, str | int]:
    """The ``svgf/*`` provenance added to the colour's part (every input attribute is kept
    by the writer as it is).

    Everything here is a function of the options and the frame, never of the run (no
    timestamps, no host names), so a resumed or retried frame is byte-identical.
    """
    attributes: dict[str, str | int] = {
        "svgf/version": __version__,
        "svgf/preset": config.preset,
        "svgf/params": config.params.to_json(),
        "svgf/frame": int(task.frame),
        "svgf/input": str(task.input),
        "svgf/warmup": config.warmup_label,
        "svgf/kind": "denoised",  # an input's svgf/kind ("input") would mislabel it
    }
    stages = run_stages(config.params)
    if stages:
        attributes["svgf/stages"] = ",".join(stages)
    return attributes


@dataclass
class OutputFrame:
    """One frame ready for the writer thread: the file layout and the new planes."""

    source: SourceFile
    part_index: int
    channels: dict[str, np.ndarray]
    attributes: dict[str, str | int]
    keep_only: set[str] | None
    warnings: list[str]


def colour_layout(
    result: ReadResult, frame_shape: tuple[int, int], input_path: Path
) -> tuple[SourceFile, int, tuple[str, ...]]:
    """(source, part index, channel names) the denoised colour is written to.

    The input's colour layer when it has one (``colour_channels``), else ``R,G,B`` added to
    the part holding the filtered signals. A reader without a decoded file (stand-ins in
    tests, which may also lack the optional fields: hence ``getattr``) gets a one-part
    layout with its alpha.
    """
    from svgf_cli.io.output import synthetic_source

    source = getattr(result, "source", None)
    if source is None:
        info = result.info
        source = synthetic_source(
            input_path,
            frame_shape,
            getattr(info, "attributes", None),
            getattr(info, "compression", None) or "zip",
            getattr(result, "alpha", None),
        )
    names = getattr(result, "colour_channels", None)
    anchor: str | None = names[0] if names else None
    if anchor is None:
        resolved = getattr(result, "resolved", None)
        signal = resolved[resolved.signal_roles[0]] if resolved is not None else None
        anchor = signal[0] if signal else None
    part = source.part_holding(anchor) if anchor else None
    return source, (part.index if part is not None else 0), tuple(names or ("R", "G", "B"))


def layer_alpha(name: str) -> str:
    """``ViewLayer.Combined.R`` -> ``ViewLayer.Combined.A``; ``R`` -> ``A``."""
    layer, dot, _ = name.rpartition(".")
    return f"{layer}{dot}A"


def release_replaced(part: SourcePart, channels: Collection[str]) -> int:
    """Let go of the input pixels of ``part``'s channels that the output writes anew
    (the denoised colour, the light layers): the writer never reads them, and the frame's
    file is held until its write is done. Returns the bytes let go."""
    released = 0
    for name in channels:
        held = part.channels.get(name)
        if held is not None and held.pixels is not None:
            released += held.pixels.nbytes
            held.pixels = None
    return released


def light_replaced(light: LightLayers) -> list[str]:
    """The input channels a layered filter (``filters.composable.LayeredDenoiser``) writes
    anew for the light layers ``light`` attached to a frame: every light pass, the emission
    passes beside them (they take the light no pass carries) and every light group. (The
    colour passes it remodulates depend on the signals: they are not counted here.)"""
    layers = [*light.passes, *(light.emission if light.passes else ()), *light.groups]
    return [name for layer in layers for name in layer.channels]


def release_light_inputs(result: ReadResult, task: FrameTask,
                         light: LightLayers | None) -> int:
    """Let go of the input pixels that the frame's light layers ``light`` will replace in
    the output (`light_replaced`), in the part the output's colour and light layers are
    written to (channels of other parts pass through as read): the filter has its float32
    copies, and the frame's file is held while it is filtered and written. For a layered
    filter only. Returns the bytes let go."""
    frame = getattr(result, "frame", None)
    if light is None or frame is None or getattr(result, "source", None) is None:
        return 0
    source, part_index, _ = colour_layout(result, (frame.height, frame.width), task.input)
    return release_replaced(source.parts[part_index], light_replaced(light))


def build_output(
    result: ReadResult, denoised: DenoisedFrame, config: RunConfig, task: FrameTask
) -> OutputFrame:
    """Everything the writer needs for one frame, converted by the output value policy
    (non-finite -> 0, then half clamped to +-65504; each counted for a warning)."""
    from svgf_cli.io.output import prepare_colour

    color = denoised.color
    source, part_index, names = colour_layout(result, color.shape[1:], task.input)
    part = source.parts[part_index]
    stored = part.channels.get(names[0])
    half = not config.float_colour and (stored is None or stored.type_name == "half")
    prepared = prepare_colour(color, half)
    warnings = []
    if prepared.nonfinite:
        warnings.append(f"{prepared.nonfinite} non-finite output value(s) set to 0")
    if prepared.clamped:
        warnings.append(
            f"{prepared.clamped} output value(s) beyond the half-float range clamped to "
            "+-65504 (--float keeps them)"
        )
    channels = dict(zip(names, prepared.planes, strict=True))
    if denoised.light:
        light, fixed = light_channels(part, denoised.light)
        channels.update(light)
        if fixed:
            warnings.append(f"{fixed} non-finite light-layer value(s) set to 0")
    if config.debug_aovs:
        for name, plane in denoised.layers.items():
            channels[f"{DEBUG_PREFIX}{name}"] = np.ascontiguousarray(plane, dtype=np.float32)
    keep_only = None
    if config.colour_only:
        keep_only = {layer_alpha(names[0])} & set(part.channels)
    release_replaced(part, channels)
    return OutputFrame(
        source, part_index, channels, output_attributes(config, task), keep_only, warnings
    )


def light_channels(part: SourcePart, planes: dict[str, np.ndarray]
                   ) -> tuple[dict[str, np.ndarray], int]:
    """The denoised light channels of ``part`` in their stored pixel types (half clamped to
    +-65504, non-finite -> 0) and how many values were fixed. Channels of other parts stay
    as read."""
    from svgf_cli.halfconv import storable

    out: dict[str, np.ndarray] = {}
    fixed = 0
    for name, plane in planes.items():
        channel = part.channels.get(name)
        if channel is None:
            continue
        out[name], nonfinite, _clamped = storable(plane, channel.type_name == "half")
        fixed += nonfinite
    return out, fixed
