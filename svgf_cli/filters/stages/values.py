"""Input values: the geometry obeying the value policy (``filters.values``)."""

from __future__ import annotations

from svgf_cli.filters import values
from svgf_cli.filters.context import FrameContext, StageBase, add_count


class CleanGeometry(StageBase):
    """Depth, normal and motion with non-finite and beyond-1e15 values replaced and
    counted: the frame's own planes when they are clean (a read-only scan), cleaned copies
    otherwise."""

    name = "values"
    reads = ("frame.depth", "frame.normal", "frame.motion")
    writes = ("depth", "normal_in", "motion")
    clock = "values"

    def run(self, ctx: FrameContext) -> None:
        frame, counts = ctx.frame, ctx.counts
        cleaners = (("depth", frame.depth, values.cleaned_depth),
                    ("normal", frame.normal, values.cleaned_normal),
                    ("motion", frame.motion, values.cleaned_motion))
        found = values.count_geometry(frame.depth, frame.normal, frame.motion)
        planes = []
        for name, plane, cleaned in cleaners:
            nonfinite, extreme = found[name]
            if name == "motion":
                extreme = 0  # far-away motion only means "no history": nothing overflows
            add_count(counts, "nonfinite", name, nonfinite)
            add_count(counts, "extreme", name, extreme)
            planes.append(cleaned(plane) if nonfinite or extreme else plane)
        ctx.depth, ctx.normal_in, ctx.motion = planes[0], planes[1], planes[2]
