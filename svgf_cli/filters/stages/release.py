"""Release (a reverse pass's output frame): the combination buffers let go."""

from __future__ import annotations

from svgf_cli.filters.buffers import combined_role
from svgf_cli.filters.context import FrameContext, StageBase


class ReleaseCombination(StageBase):
    """The combination buffers (``ReversePass.forward_buffers``) let go once the output
    frame is composed: dead until the next output frame's forward state is unpacked, they
    are not held between frames, where a file run holds the most (the frame being written,
    the one being read and the next packed state). Allocated again by the next
    ``forward_buffers``: a mapping of its own each (``svgf_cli.heap``)."""

    name = "release_combination"
    reads = ()
    writes = ("combined", "combined_moments", "combined_length", "forward.albedo")

    def run(self, ctx: FrameContext) -> None:
        for name in (combined_role(ctx.params.firefly_clamp), "combined_moments",
                     "combined_length"):
            ctx.work.planes.pop(name, None)
        ctx.resident.forward_albedo = None
