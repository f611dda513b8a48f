"""Composition: remodulate, sum the signals, add the emission, restore the background."""

from __future__ import annotations

import numpy as np

from svgf_cli.filters import modulate
from svgf_cli.filters.context import FrameContext, StageBase, add_count

F32 = np.float32


class Remodulate(StageBase):
    """The filtered illumination multiplied back by each signal's colour (Schied et al.
    2017, sec. 4.1; radiance-mode pixels as they are), the signals summed and the emission
    added, straight into a fresh output array handed to the caller (nothing full-frame
    stays resident); the debug layers when asked."""

    name = "remodulate"
    reads = ("atrous_output", "variance", "history_length", "mode", "depth", "frame.signals")
    writes = ("output",)
    clock = "modulate"

    def run(self, ctx: FrameContext) -> None:
        spatial = ctx.spatial
        assert spatial is not None
        frame, depth, counts, rules = ctx.frame, ctx.depth, ctx.counts, ctx.setup.rules
        height, width = depth.shape
        radiance = np.zeros((3, height, width), dtype=F32)
        emission = frame.emission
        has_emission = emission is not None
        # Without emission any (3, H, W) float32 plane will do: the kernel never reads it.
        emission_plane = emission if emission is not None else radiance
        rows = np.zeros((height, 2), dtype=np.int64)
        # Each signal's own radiance, when wanted, side by side in one block: the light
        # layers take them all as one (S, 3, H, W) array without a copy.
        alone_all = (np.zeros((len(frame.signals), 3, height, width), dtype=F32)
                     if ctx.setup.debug_layers or ctx.setup.signal_outputs else None)
        for index, signal in enumerate(frame.signals):
            add_emission = has_emission and index == 0
            if alone_all is not None:
                # Each signal's own radiance is wanted too: remodulated once, then summed
                # (the same sum, bit for bit).
                alone = alone_all[index]
                if ctx.setup.debug_layers:
                    debug_layers(ctx, index, emission_plane, rows, alone)
                else:
                    signal_output(ctx, index, emission_plane, rows, alone, albedo=True)
                modulate.add_remodulated(alone, emission_plane, add_emission, radiance, rows)
            else:
                modulate.remodulate_add(spatial.illumination[index], signal.radiance,
                                        signal.albedo, depth, emission_plane, add_emission,
                                        *rules[signal.guide_albedo], radiance, rows)
            if add_emission:
                total = rows.sum(axis=0)
                add_count(counts, "nonfinite", "emission", int(total[0]))
                add_count(counts, "extreme", "emission", int(total[1]))
        ctx.output = radiance


def signal_output(ctx: FrameContext, index: int, emission_plane: np.ndarray,
                  rows: np.ndarray, alone: np.ndarray, albedo: bool = False) -> np.ndarray:
    """Signal ``index``'s own remodulated radiance (no emission) into ``alone`` ((3, H, W)
    zeros), also as the layers ``<signal>.R/G/B``; with ``albedo`` also the colour it was
    remodulated by (the temporal albedo's running mean when that stage runs) as
    ``<signal>.albedo.R/G/B`` and its history length as ``<signal>.history_length``."""
    spatial, signal = ctx.spatial, ctx.frame.signals[index]
    assert spatial is not None
    modulate.remodulate_add(spatial.illumination[index], signal.radiance, signal.albedo,
                            ctx.depth, emission_plane, False,
                            *ctx.setup.rules[signal.guide_albedo], alone, rows)
    for c, channel in enumerate("RGB"):
        ctx.layers[f"{signal.name}.{channel}"] = alone[c]
        if albedo:
            ctx.layers[f"{signal.name}.albedo.{channel}"] = signal.albedo[c]
    if albedo:  # and the history length its blend used (the light passes' shares blend so)
        ctx.layers[f"{signal.name}.history_length"] = spatial.history_length[index]
    return alone


def debug_layers(ctx: FrameContext, index: int, emission_plane: np.ndarray,
                 rows: np.ndarray, alone: np.ndarray) -> np.ndarray:
    """Signal ``index``'s own remodulated radiance (into ``alone``), variance, history
    length, mode and anti-lag weight as debug layers; returns that radiance."""
    spatial, signal, mode = ctx.spatial, ctx.frame.signals[index], ctx.mode
    assert spatial is not None
    height, width = ctx.depth.shape
    name, layers = signal.name, ctx.layers
    signal_output(ctx, index, emission_plane, rows, alone, albedo=ctx.setup.signal_outputs)
    layers[f"variance.{name}"] = spatial.variance[index].copy()
    layers[f"history_length.{name}"] = spatial.history_length[index].copy()
    layers[f"radiance_mode.{name}"] = ((mode >> index) & 1).astype(F32)
    if ctx.params.antilag:
        # Anti-lag's response where it ran this frame (it counts then), else none: 0.
        layers[f"antilag.{name}"] = (
            cells_to_pixels(ctx.work["antilag_lambda"][index], height, width)
            if "antilag" in ctx.counts else np.zeros((height, width), F32))
    return alone


def cells_to_pixels(cells: np.ndarray, height: int, width: int) -> np.ndarray:
    """A per-cell (2x2 pixels) plane at pixel resolution (for the debug layers)."""
    return np.ascontiguousarray(np.repeat(np.repeat(cells, 2, 0), 2, 1)[:height, :width])
