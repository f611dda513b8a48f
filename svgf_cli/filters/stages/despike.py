"""Despike (optional): isolated spikes the a-trous kept, bounded by their neighbours."""

from __future__ import annotations

import numpy as np

from svgf_cli.filters.context import FrameContext, StageBase
from svgf_cli.filters.despike import despike
from svgf_cli.filters.params import SVGFParams

F32 = np.float32


class Despike(StageBase):
    """A filtered pixel brighter than ``despike`` times its second-brightest same-mode
    neighbour brought down to that bound (``filters.despike``), counted per signal. In
    place unless the output is the colour history (no a-trous iteration after the feedback
    one): the history keeps the samples."""

    name = "despike"
    reads = ("atrous_output", "mode", "depth")
    writes = ("atrous_output", "despike_luminance")
    clock = "despike"

    def enabled(self, params: SVGFParams) -> bool:
        return params.despike > 0.0

    def run(self, ctx: FrameContext) -> None:
        filtered = ctx.spatial
        assert filtered is not None
        illumination = filtered.illumination
        if filtered.name == filtered.history_name:
            illumination = illumination.copy()
        clamped = np.zeros((ctx.depth.shape[0], len(ctx.names)), dtype=np.int64)
        despike(illumination, ctx.mode, ctx.depth, F32(ctx.params.despike), ctx.weights,
                ctx.work["despike_luminance"], clamped)
        for name, total in zip(ctx.names, clamped.sum(axis=0), strict=True):
            ctx.counts[f"despiked.{name}"] = int(total)
        filtered.illumination = illumination
