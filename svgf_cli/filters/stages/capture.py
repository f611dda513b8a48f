"""Capture (a forward pass): the resampled history handed back for the reverse pass."""

from __future__ import annotations

import enum

from svgf_cli.filters.bidirectional import SideHistory, pack_history
from svgf_cli.filters.context import FrameContext, StageBase


class Keep(enum.Enum):
    """What a forward pass hands back of the history it resampled."""

    NOTHING = "nothing"  # a warm-up frame: no output frame needs it
    COPY = "copy"  # a float32 SideHistory of its own
    PACKED = "packed"  # pack_history's half-float planes (what a file run spills)


class Capture(StageBase):
    """The history this frame resampled (after anti-lag, before the blend: the
    bidirectional combination's forward side, ``filters.bidirectional``) and, with
    ``temporal_albedo``, the colour means, kept as ``ctx.keep`` asks (a :class:`Keep`)
    into ``ctx.kept``."""

    name = "capture"
    reads = ("accumulated", "moments", "history_length", "albedo_history")
    writes = ("kept",)
    clock = "reproject"

    def run(self, ctx: FrameContext) -> None:
        temporal = ctx.temporal
        assert temporal is not None
        albedo = albedo_length = None
        if ctx.params.temporal_albedo:
            albedo, albedo_length = ctx.resident.albedo or (None, None)
        side = SideHistory(temporal.history_illumination, temporal.history_moments,
                           temporal.history_length, albedo, albedo_length)
        if ctx.keep is Keep.NOTHING:
            ctx.kept = None
        elif ctx.keep is Keep.PACKED:
            ctx.kept = pack_history(ctx.names, side)
        else:
            ctx.kept = SideHistory(
                side.colour.copy(), side.moments.copy(), side.length.copy(),
                None if albedo is None else albedo.copy(),
                None if albedo_length is None else albedo_length.copy())
