"""Temporal albedo (optional): each demodulation colour's running mean over frames."""

from __future__ import annotations

import dataclasses

import numpy as np

from svgf_cli.filters.albedo_history import accumulate_albedo
from svgf_cli.filters.context import FrameContext, StageBase
from svgf_cli.filters.params import SVGFParams
from svgf_cli.frame import Signal

F32 = np.float32


class TemporalAlbedo(StageBase):
    """Each signal's demodulation colour replaced by its running mean over frames
    (``filters.albedo_history``), kept as history, one per distinct colour
    (:func:`colour_slots`); the composition remodulates by it. After demodulation (which
    used this frame's colour) and before the history is stored (last frame's depth and mesh
    id). Each frame's means go to fresh arrays and last frame's are let go."""

    name = "temporal_albedo"
    reads = ("frame.signals", "motion", "depth", "history")
    writes = ("albedo_history",)
    clock = "albedo"

    def enabled(self, params: SVGFParams) -> bool:
        return params.temporal_albedo

    def run(self, ctx: FrameContext) -> bool:
        p, frame, resident = ctx.params, ctx.frame, ctx.resident
        slots, sources = colour_slots(frame.signals)
        if not sources:
            return False  # only glossy signals: no colour to average
        count, h, w = len(sources), frame.height, frame.width
        shape = (count, 3, h, w)
        history, previous = resident.albedo, resident.history
        if (history is None or slots != resident.albedo_slots or previous is None
                or not p.temporal):
            # No history: a length-0 plane rejects every tap.
            history = (np.zeros(shape, dtype=F32), np.zeros((count, h, w), dtype=F32))
            prev_depth, prev_mesh_id = ctx.depth, frame.mesh_id
        else:
            prev_depth, prev_mesh_id = previous["prev_depth"], previous["prev_mesh_id"]
        # Fresh (a mapping of its own, given back when freed: svgf_cli.heap), so that last
        # frame's pair is not kept alive as the next frame's spare.
        colour, length = np.empty(shape, dtype=F32), np.empty((count, h, w), dtype=F32)
        for slot, source in enumerate(sources):
            signal = frame.signals[source]
            accumulate_albedo(
                signal.albedo, history[0][slot], history[1][slot], ctx.motion, ctx.depth,
                frame.mesh_id, prev_depth, prev_mesh_id, F32(ctx.setup.albedo_blend),
                F32(p.history_cap),
                *ctx.setup.rules[signal.guide_albedo], colour[slot], length[slot],
                catmull_rom=p.albedo_catmull_rom,
            )
        resident.albedo, resident.albedo_slots = (colour, length), slots
        signals = [signal if slot < 0 else dataclasses.replace(signal, albedo=colour[slot])
                   for signal, slot in zip(frame.signals, slots, strict=True)]
        ctx.frame = dataclasses.replace(frame, signals=signals)
        return True


def colour_slots(signals: list[Signal]) -> tuple[tuple[int, ...], list[int]]:
    """Which running mean each signal's demodulation colour has (-1: none), and the first
    signal of each: signals that share one colour array (a reader gives direct and indirect
    light the same colour pass) and its demodulation rule (``guide_albedo``) share a mean.
    Glossy signals keep this frame's colour: their light follows reflections, not the
    texture under it, and a specular colour is smooth (measured: no gain on the Blender
    fixtures, where averaging it cost a third of the stage)."""
    slots: list[int] = []
    sources: list[int] = []
    keys: list[tuple[int, bool]] = []
    for index, signal in enumerate(signals):
        if signal.glossy:
            slots.append(-1)
            continue
        key = (id(signal.albedo), signal.guide_albedo)
        if key not in keys:
            keys.append(key)
            sources.append(index)
        slots.append(keys.index(key))
    return tuple(slots), sources


def colour_count(slots: tuple[int, ...]) -> int:
    """How many running means ``slots`` (:func:`colour_slots`) name."""
    return len(set(slots) - {-1})
