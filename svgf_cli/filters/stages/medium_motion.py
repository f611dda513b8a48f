"""The medium pixels' motion: the surface behind's or none, whichever their light follows
(``filters.medium.medium_motion``)."""

from __future__ import annotations

from svgf_cli.filters.context import FrameContext, StageBase
from svgf_cli.filters.medium import medium_motion
from svgf_cli.filters.params import SVGFParams


class MediumMotion(StageBase):
    """Each medium pixel (``fill_medium``) reprojects its history with the motion of the
    surface behind it, which it took with that surface's G-buffer, or with none, whichever
    brings last frame's medium light (its demodulated history) closer to this frame's around
    it: a fog in front of a far wall does not move as the wall does when the camera moves.
    After the demodulation, so both lights are in the filter's units; every later stage
    (reprojection, the colour means, the shares) uses the motion chosen. Frames without
    medium pixels or history skip it (docs/algorithm.md#the-mediums-motion)."""

    name = "medium_motion"
    reads = ("medium_pixels", "medium_signal", "motion", "demodulated", "history")
    writes = ("motion",)
    clock = "medium"

    def enabled(self, params: SVGFParams) -> bool:
        return params.medium_motion and params.medium_fill_radius > 0 and params.temporal

    def run(self, ctx: FrameContext) -> bool | None:
        history = ctx.resident.history
        medium = ctx.medium_signal
        if ctx.medium_pixels is None or medium is None or history is None:
            return False
        previous = history["history_illumination"]
        if previous.shape[0] != len(ctx.frame.signals) or previous.shape[2:] != ctx.depth.shape:
            return False
        ctx.motion, ctx.counts["medium_still"] = medium_motion(
            ctx.work["demodulated"][medium], previous[medium], ctx.motion, ctx.medium_pixels)
        return None
