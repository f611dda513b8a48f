"""A still light's jittered outline: its emission averaged over time (``still_emission_mean``)."""

from __future__ import annotations

import dataclasses

import numpy as np

from svgf_cli.filters.context import FrameContext, StageBase
from svgf_cli.filters.emission_mean import emission_mean
from svgf_cli.filters.params import SVGFParams
from svgf_cli.filters.stages.taa import frame_is_jittered

F32 = np.float32


class EmissionMean(StageBase):
    """On a frame with an emission pass whose samples are jittered (``filters.jitter``), the
    emission added back is its running mean where the pixel and its light keep still
    (``filters.emission_mean``): a still light's outline shows its coverage, not a flip. The
    means are kept from frame to frame (``Resident.emission_mean``); another frame lets
    them go. In a bidirectional run's reverse pass, backwards in time."""

    name = "emission_mean"
    reads = ("frame.emission", "motion", "depth", "normal_in", "frame.mesh_id")
    writes = ("frame.emission", "emission_averaged")
    clock = "taa"

    def enabled(self, params: SVGFParams) -> bool:
        return params.still_emission_mean

    def run(self, ctx: FrameContext) -> bool:
        frame, resident = ctx.frame, ctx.resident
        if frame.emission is None or not frame_is_jittered(ctx):
            resident.emission_mean = None
            return False
        planes = resident.emission_mean
        height, width = ctx.depth.shape
        if planes is None:
            planes = resident.emission_mean = {
                "mean": np.zeros((3, height, width), F32),
                "length": np.zeros((height, width), F32),
                "still": np.zeros((height, width), np.uint8),
                "level": np.zeros((height, width), F32),
            }
        emission_mean(frame.emission, ctx.motion, planes["mean"], planes["length"],
                      planes["still"], planes["level"], F32(ctx.params.alpha),
                      F32(ctx.params.history_cap))
        averaged = np.any(planes["mean"] != frame.emission, axis=0)
        ctx.emission_averaged = averaged if averaged.any() else None
        ctx.frame = dataclasses.replace(frame, emission=planes["mean"].copy())
        return True
