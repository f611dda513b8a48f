"""Temporal anti-aliasing of the output at outlines (``taa``; ``taa_jittered``: on the frames
whose samples are jittered)."""

from __future__ import annotations

import dataclasses

import numpy as np

from svgf_cli.filters.context import FrameContext, StageBase
from svgf_cli.filters.jitter import jittered_frame
from svgf_cli.filters.params import SVGFParams
from svgf_cli.filters.taa import taa_resolve

F32 = np.float32


class TAA(StageBase):
    """The previous output, Catmull-Rom resampled and clipped to the current 3x3, blended
    in at object outlines (``filters.taa``); the blend is kept as the TAA history. With
    ``taa_jittered`` (and not ``taa``) only on frames whose G-buffer shows jittered samples
    and whose header does not say centre-sampled (``filters.jitter``); another frame
    lets the history go. A frame given its colour (``Frame.final_colour``: the look-ahead
    warm start) is anti-aliased in its place: the warm frames start the history. In a
    bidirectional run's reverse pass (its output frames) the history is the frame after,
    the motion the motion to it: TAA backwards in time."""

    name = "taa"
    reads = ("output", "frame.final_colour", "taa_previous", "motion", "depth", "normal_in",
             "frame.mesh_id")
    writes = ("output", "frame.final_colour", "taa_previous", "taa")
    clock = "taa"

    def enabled(self, params: SVGFParams) -> bool:
        return params.taa or params.taa_jittered

    def run(self, ctx: FrameContext) -> bool:
        frame, resident = ctx.frame, ctx.resident
        if not (ctx.params.taa or frame_is_jittered(ctx)):
            resident.taa_previous = None
            return False
        current = ctx.output if frame.final_colour is None else frame.final_colour
        assert current is not None
        if resident.taa_previous is None:
            resident.taa_previous = current.copy()
        else:
            taa_resolve(current, resident.taa_previous, ctx.motion, ctx.depth,
                        np.array(ctx.weights, dtype=F32), F32(ctx.params.taa_alpha),
                        ctx.work["taa"])
            np.copyto(resident.taa_previous, ctx.work["taa"])
        if frame.final_colour is None:
            ctx.output = resident.taa_previous.copy()
        else:
            ctx.frame = dataclasses.replace(frame,
                                            final_colour=resident.taa_previous.copy())
        return True


def frame_is_jittered(ctx: FrameContext) -> bool:
    """``filters.jitter.jittered_frame`` of the frame in flight, worked out once per frame
    (the TAA and the emission mean both ask)."""
    if ctx.jittered is None:
        frame = ctx.frame
        ctx.jittered = jittered_frame(frame.centre_sampled, ctx.depth, ctx.normal_in,
                                      frame.mesh_id)
    return ctx.jittered
