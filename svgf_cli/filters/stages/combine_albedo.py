"""Colour-mean combination (a reverse pass with ``temporal_albedo``)."""

from __future__ import annotations

import dataclasses

from svgf_cli.filters.albedo_history import combine_albedo
from svgf_cli.filters.context import FrameContext, StageBase
from svgf_cli.filters.params import SVGFParams


class CombineAlbedo(StageBase):
    """An output frame remodulates by both passes' colour means weighted by their effective
    sample counts (``albedo_history.combine_albedo``), written over the forward pass's
    (dead after this frame). A forward history with another set of colours (it cannot
    happen with one reader) is not combined."""

    name = "combine_albedo"
    reads = ("albedo_history", "forward.albedo")
    writes = ("forward.albedo",)

    def enabled(self, params: SVGFParams) -> bool:
        return params.temporal_albedo

    def run(self, ctx: FrameContext) -> bool:
        forward = ctx.into
        if forward is None or ctx.forward is None or ctx.forward.albedo is None:
            return False
        resident = ctx.resident
        assert resident.albedo is not None
        assert forward.albedo is not None and forward.albedo_length is not None
        reverse, reverse_length = resident.albedo
        if forward.albedo.shape != reverse.shape:
            return False
        frame = ctx.frame
        # The signals already hold views of the reverse means: the slots are the pass's.
        slots = resident.albedo_slots
        for slot in range(reverse.shape[0]):
            signal = frame.signals[slots.index(slot)]
            combine_albedo(
                forward.albedo[slot], forward.albedo_length[slot], reverse[slot],
                reverse_length[slot], signal.albedo, ctx.setup.albedo_counts,
                *ctx.setup.rules[signal.guide_albedo], forward.albedo[slot],
            )
        signals = [signal if slot < 0 else dataclasses.replace(signal, albedo=forward.albedo[slot])
                   for signal, slot in zip(frame.signals, slots, strict=True)]
        ctx.frame = dataclasses.replace(frame, signals=signals)
        return True
