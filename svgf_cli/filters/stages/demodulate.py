"""Demodulation: every signal divided by its colour, or kept as radiance, per pixel."""

from __future__ import annotations

import numpy as np

from svgf_cli.filters import modulate
from svgf_cli.filters.context import FrameContext, StageBase, add_count


class Demodulate(StageBase):
    """Untextured illumination (Schied et al. 2017, sec. 4.1): each signal divided by its
    demodulation colour where that is a plausible reflectance, else filtered as radiance
    (the per-pixel mode mask, ``filters.modulate``); values clamped to +-1e15 and counted."""

    name = "demodulate"
    reads = ("frame.signals", "depth")
    writes = ("demodulated", "mode")
    clock = "demodulate"

    def run(self, ctx: FrameContext) -> None:
        work, counts, depth = ctx.work, ctx.counts, ctx.depth
        out, mode = work["demodulated"], work["mode"]
        rules = ctx.setup.rules
        rows = np.zeros((depth.shape[0], modulate.DEMODULATE_COUNTERS), dtype=np.int64)
        for index, signal in enumerate(ctx.frame.signals):
            modulate.demodulate(signal.radiance, signal.albedo, depth,
                                *rules[signal.guide_albedo],
                                index, out[index], mode, rows)
            total = rows.sum(axis=0)
            name = signal.name
            add_count(counts, "nonfinite", f"radiance.{name}",
                      int(total[modulate.NONFINITE_RADIANCE]))
            add_count(counts, "extreme", f"radiance.{name}",
                      int(total[modulate.EXTREME_RADIANCE]))
            add_count(counts, "nonfinite", f"albedo.{name}",
                      int(total[modulate.NONFINITE_ALBEDO]))
            counts[f"clamped.{name}"] = int(total[modulate.CLAMPED])
            counts[f"radiance_mode.{name}"] = int(total[modulate.RADIANCE_MODE])
            counts[f"implausible_albedo.{name}"] = int(total[modulate.IMPLAUSIBLE])
        for name, total in ctx.marked.items():
            # Their colour (the G-buffer albedo) is above 1 by construction: information,
            # not an implausible colour pass.
            counts[f"reflected_light.{name}"] = total
            counts[f"implausible_albedo.{name}"] -= total
        ctx.mode = mode
        ctx.illumination_name = "demodulated"
