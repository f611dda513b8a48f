"""Combination (a reverse pass): both passes' histories and this frame, per pixel."""

from __future__ import annotations

import numpy as np

from svgf_cli.filters.bidirectional import (
    CONSISTENCY_SIGMA,
    GLOSSY_REFERENCE_COUNT,
    combine_histories,
    consistent_lengths,
)
from svgf_cli.filters.context import FrameContext, StageBase

F32 = np.float32


class Combine(StageBase):
    """On an output frame of the reverse pass: the consistency test between the forward
    history (``ctx.into``) and this pass's own, then their combination with this frame
    weighted by effective sample counts (``filters.bidirectional``), written over the
    forward history. The reverse pass blends with its own length, so its shortened one goes
    to ``variance_b`` (dead until the variance is estimated)."""

    name = "combine"
    reads = ("demodulated", "accumulated", "moments", "history_length", "combined")
    writes = ("combined", "combined_moments", "combined_length", "variance_b")
    clock = "reproject"

    def run(self, ctx: FrameContext) -> bool:
        temporal, into, setup = ctx.temporal, ctx.into, ctx.setup
        if into is None or temporal is None:
            return False
        # n_ref per signal: a long causal history's count, GLOSSY_REFERENCE_COUNT for
        # glossy signals (filters.bidirectional).
        reference_counts = np.array(
            [GLOSSY_REFERENCE_COUNT if signal.glossy else setup.moment_counts[-1]
             for signal in ctx.frame.signals], dtype=F32)
        reverse_length = ctx.work["variance_b"]
        consistent_lengths(
            temporal.current, into.moments, into.length, temporal.history_moments,
            temporal.history_length, temporal.depth, setup.colour_counts,
            ctx.weights, F32(CONSISTENCY_SIGMA), into.length, reverse_length,
        )
        combine_histories(
            temporal.current, temporal.history_illumination, temporal.history_moments,
            reverse_length, temporal.depth, setup.colour_counts,
            setup.moment_counts, ctx.weights, reference_counts,
            into.colour, into.moments, into.length,
        )
        return True
