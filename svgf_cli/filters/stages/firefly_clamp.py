"""Firefly clamp of the input (optional)."""

from __future__ import annotations

import numpy as np

from svgf_cli.filters.clamp import firefly_clamp
from svgf_cli.filters.context import FrameContext, StageBase
from svgf_cli.filters.params import SVGFParams

F32 = np.float32


class FireflyClamp(StageBase):
    """The demodulated frame's luminance clamped to mean + k sigma of its 8 neighbours
    (``filters.clamp.firefly_clamp``), into ``spare_a``."""

    name = "firefly_clamp"
    reads = ("demodulated", "depth")
    writes = ("spare_a",)
    clock = "demodulate"

    def enabled(self, params: SVGFParams) -> bool:
        return params.firefly_clamp > 0.0

    def run(self, ctx: FrameContext) -> None:
        work = ctx.work
        firefly_clamp(work[ctx.illumination_name], ctx.depth, F32(ctx.params.firefly_clamp),
                      ctx.weights, work["spare_a"])
        ctx.illumination_name = "spare_a"
