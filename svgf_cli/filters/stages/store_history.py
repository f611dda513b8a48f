"""History store: this frame's buffers become the history, with the history guard."""

from __future__ import annotations

import numpy as np

from svgf_cli.filters import values
from svgf_cli.filters.context import FrameContext, StageBase


class StoreHistory(StageBase):
    """This frame's colour history (``ctx.history_name``: the feedback iteration's output,
    or a pass's), moments, length, modes and normals handed to the history by swapping (no
    copies; the workspace takes the stale history arrays and overwrites them next frame);
    depth and mesh id copied (the frame's planes belong to the caller). Then the history
    guard: non-finite history values are reset (counted as ``history_resets``)."""

    name = "store_history"
    reads = ("history_colour", "moments", "history_length", "mode", "normal", "depth")
    writes = ("history",)
    clock = "history"

    def run(self, ctx: FrameContext) -> None:
        work, frame, counts, resident = ctx.work, ctx.frame, ctx.counts, ctx.resident
        history = resident.history_buffers(work)
        resident.history = history
        resident.fresh = None
        illumination_name = ctx.history_name
        colour = ctx.plane(illumination_name)
        for key, name in (
            ("history_illumination", illumination_name),
            ("history_moments", "moments"),
            ("history_length", "history_length"),
            ("history_mode", "mode"),
            ("prev_normal", "normal"),
        ):
            if key == "history_illumination" and colour is history[key]:
                continue  # the feedback iteration wrote into the stale history itself
            history[key], work.planes[name] = work.planes[name], history[key]
        np.copyto(history["prev_depth"], ctx.depth)
        np.copyto(history["prev_mesh_id"], frame.mesh_id)
        counts["history_resets"] += values.reset_nonfinite_history(
            history["history_illumination"], history["history_moments"],
            history["history_length"], history["history_mode"],
        )
