"""The SVGF denoiser (Schied et al. 2017): the causal pipeline run frame by frame.

Per frame, the stages of ``filters.pipeline.causal`` (one module each under
``filters.stages``; ``Denoiser.stages`` names those the settings enable): input values ->
geometry gradients -> (mark reflected lights) -> demodulate -> (firefly clamp) -> reproject
-> (history clamp) -> (anti-lag) -> (spread fireflies) -> accumulate -> (temporal albedo)
-> variance -> a-trous, whose ``feedback_iteration`` output becomes the colour history ->
store history (with the history guard) -> (despike) -> remodulate (sum the signals, add
emission, restore background) -> (lone despike) -> (TAA) -> (pixel filter).

The buffers and which of them share memory, and when, are declared in ``filters.buffers``;
the arrays kept between frames (history, workspace, colour means, TAA) in
``filters.resident``, whose ``state()`` layout is :data:`STATE_FORMAT`.
"""

from __future__ import annotations

import dataclasses

from svgf_cli.filters.context import (
    MAX_REFLECTANCE,
    RELATIVE_ALBEDO_FLOOR,
    FrameContext,
    TemporalState,
)
from svgf_cli.filters.engine import PipelineFilter
from svgf_cli.filters.resident import STATE_FORMAT
from svgf_cli.filters.stages.atrous import signal_groups, signal_sigma_luminance
from svgf_cli.frame import DenoisedFrame, Frame

__all__ = ["MAX_REFLECTANCE", "RELATIVE_ALBEDO_FLOOR", "STATE_FORMAT", "Denoiser",
           "TemporalState", "signal_groups", "signal_sigma_luminance"]


class Denoiser(PipelineFilter):
    """Spatiotemporal variance-guided filtering of a frame sequence (Schied et al. 2017).

    Feed frames in sequence order to :meth:`process`; the history persists between calls.
    A frame carries any number of named signals (``Frame.signals``); each is filtered on
    its own, with its own history (illumination, luminance moments, history length,
    demodulation mode per pixel) and variance, and the filtered signals are summed with the
    emission added back. The signal names must stay the same for the whole sequence.

    Per signal and pixel, a mode (``filters.modulate``): demodulated by the signal's colour
    where that is a plausible reflectance (brightest channel in ``[albedo_epsilon,
    MAX_REFLECTANCE]``, per-channel floor ``max(albedo_epsilon, RELATIVE_ALBEDO_FLOOR *
    brightest)``; for a signal with ``guide_albedo`` the floor ``albedo_epsilon`` is raised
    to ``guide_albedo_floor``), else filtered as radiance. Modes never exchange weight
    (a-trous, spatial variance) nor history (reprojection).

    Values (``filters.values``): non-finite and beyond-1e15 inputs are replaced and counted,
    demodulated values are clamped to +-1e15, the history can never hold a non-finite value.
    :attr:`DenoisedFrame.counts` reports all of it per frame (``frame.COUNT_KEYS``).

    The stages between reprojection and the blend (history clamp, anti-lag, firefly
    spreading) see a :class:`TemporalState`; the blend derives each signal's factor from its
    own history length, ``alpha = max(alpha, 1/h)`` with ``h = min(cap, h_prev + 1)``, so
    an anti-lag stage only lowers ``history_length[s]`` per pixel. A stage of one's own goes
    in with ``denoiser.pipeline.insert_after(name, stage)``.
    """

    kind = "causal"

    # Also hand back each frame's G-buffer as the stages used it (`DenoisedFrame.gbuffer`):
    # another filter of the same frame takes it instead of filling the medium pixels again
    # (``filters.composable.LayeredDenoiser``).
    gbuffer_output = False

    def process(self, frame: Frame) -> DenoisedFrame:
        """Denoise the next frame of the sequence."""
        ctx = self._run(frame)
        assert ctx.output is not None
        # A colour decided elsewhere (the warm start) as the stages left it (TAA's).
        final = ctx.frame.final_colour
        colour = ctx.output if final is None else final
        return DenoisedFrame(color=colour, layers=ctx.layers, counts=ctx.counts,
                             emission=ctx.frame.emission, medium=ctx.medium_pixels,
                             emission_averaged=ctx.emission_averaged,
                             outline_spill=ctx.outline_spill,
                             gbuffer=used_gbuffer(ctx) if self.gbuffer_output else None)


def used_gbuffer(ctx: FrameContext) -> Frame:
    """The frame's G-buffer as the stages used it: depth, normal and motion after the value
    policy, every plane with the medium pixels filled (``filters.stages.fill_medium``); a
    frame with no signals and no medium left to fill (what a filter with the same value and
    medium settings would make of the frame's own)."""
    return dataclasses.replace(
        ctx.frame, signals=[], depth=ctx.depth, normal=ctx.normal_in, motion=ctx.motion,
        emission=None, medium=None, light=None, final_colour=None)
