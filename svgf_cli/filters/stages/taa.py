"""Temporal anti-aliasing of the output (optional; the paper's last step)."""

from __future__ import annotations

import numpy as np

from svgf_cli.filters.context import FrameContext, StageBase
from svgf_cli.filters.params import SVGFParams
from svgf_cli.filters.taa import taa_resolve

F32 = np.float32


class TAA(StageBase):
    """The previous output, Catmull-Rom resampled and clipped to the current 3x3, blended
    in at object outlines (``filters.taa``); the blend is kept as the TAA history."""

    name = "taa"
    reads = ("output", "taa_previous", "motion", "depth")
    writes = ("output", "taa_previous", "taa")
    clock = "taa"

    def enabled(self, params: SVGFParams) -> bool:
        return params.taa

    def run(self, ctx: FrameContext) -> None:
        output, resident = ctx.output, ctx.resident
        assert output is not None
        if resident.taa_previous is None:
            resident.taa_previous = output.copy()
        else:
            taa_resolve(output, resident.taa_previous, ctx.motion, ctx.depth,
                        np.array(ctx.weights, dtype=F32), F32(ctx.params.taa_alpha),
                        ctx.work["taa"])
            np.copyto(resident.taa_previous, ctx.work["taa"])
        ctx.output = resident.taa_previous.copy()
