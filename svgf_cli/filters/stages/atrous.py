"""Edge-avoiding a-trous wavelet iterations (+ the feedback iteration as colour history)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from svgf_cli.filters.atrous import atrous_iteration, luminance_stop_guides, zero_signals
from svgf_cli.filters.bidirectional import STATIC_MOTION
from svgf_cli.filters.buffers import free_scratch
from svgf_cli.filters.context import FrameContext, Spatial, StageBase
from svgf_cli.filters.feedback import blend_history
from svgf_cli.filters.params import SVGFParams, luminance_stop_scale_for
from svgf_cli.frame import Signal

F32 = np.float32


class Atrous(StageBase):
    """The variance-guided a-trous iterations 0 .. N - 1 (Schied et al. 2017, sec. 4.3,
    eq. 1-5: step 2^i, depth, normal and luminance edge-stopping against the filtered
    variance). The output of ``feedback_iteration`` becomes the colour history (where
    pixels move, ``moving_feedback_share`` of it: ``filters.feedback``). Outputs take free
    ``ILLUMINATION_SCRATCH`` buffers in order (``filters.buffers``)."""

    name = "atrous"
    reads = ("variance", "guide_luminance", "guide_inverse_scale", "depth", "ddx", "ddy",
             "normal", "mode")
    writes = ("atrous_output", "variance_a", "variance_b")

    def run(self, ctx: FrameContext) -> None:
        spatial = ctx.spatial
        assert spatial is not None
        iterate(ctx, spatial)
        if spatial.feeds_back:
            ctx.history_name = spatial.history_name


def iterate(ctx: FrameContext, spatial: Spatial) -> None:
    """A-trous iterations 0 .. ``spatial.iterations - 1`` of ``spatial.entering``. The
    feedback iteration's output (clamped to the configured iterations; -1: the colour
    entering the a-trous) is recorded as ``spatial.history_name`` and never overwritten, nor
    are the ``protected`` buffers; without ``feeds_back`` nothing is kept (a combined
    accumulation, which is no pass's history, or a pass history: ``filters.stages.
    pass_history``). The last iteration's propagated variance is never read: not computed.
    A signal whose colour and variance entering the a-trous are +0 on every pixel is not
    filtered: every iteration's output of it is +0 (``filters.atrous.zero_signals``)."""
    p, iterations = ctx.params, spatial.iterations
    feedback = min(p.feedback_iteration, ctx.iterations - 1) if spatial.feeds_back else -1
    # Where pixels move the history keeps only a share of the feedback output: the blend
    # goes into the colour entering the a-trous, kept until that iteration has run.
    keep_unfiltered = feedback >= 0 and p.moving_feedback_share < 1.0
    unfiltered_name = history_name = filtered_name = spatial.entering
    filtered = ctx.plane(filtered_name)
    filtered_variance = spatial.variance
    # "variance" itself is reported as a debug layer; otherwise it is scratch after use.
    variance_names = ("variance_a", "variance_b")
    if not ctx.setup.debug_layers:
        variance_names = ("variance_a", "variance", "variance_b")
    zero = zero_signals(filtered, filtered_variance)
    for iteration in range(iterations):
        out_name = free_scratch(spatial.protected, filtered_name,
                                history_name if spatial.feeds_back else "",
                                unfiltered_name if keep_unfiltered else "")
        if iteration == feedback and not keep_unfiltered:
            history_name = out_name
        propagate = iteration + 1 < iterations
        out_variance = filtered_variance  # not written when not propagated
        if propagate:
            out_variance = next(
                ctx.plane(v) for v in variance_names if ctx.plane(v) is not filtered_variance
            )
        out_illumination = ctx.plane(out_name)
        atrous_step(ctx, filtered, filtered_variance, iteration, propagate, out_illumination,
                    out_variance, zero)
        if iteration == feedback and keep_unfiltered:
            blend_history(ctx.plane(unfiltered_name), out_illumination, ctx.motion,
                          F32(STATIC_MOTION), F32(1.0), F32(p.moving_feedback_share))
            history_name, keep_unfiltered = unfiltered_name, False
        filtered, filtered_variance = out_illumination, out_variance
        filtered_name = out_name
    ctx.lap("atrous")
    spatial.illumination, spatial.name, spatial.history_name = (
        filtered, filtered_name, history_name)


def atrous_step(ctx: FrameContext, filtered: np.ndarray, filtered_variance: np.ndarray,
                iteration: int, propagate: bool, out_illumination: np.ndarray,
                out_variance: np.ndarray, zero: Sequence[bool]) -> None:
    """One a-trous iteration over every signal. Signals in groups of two or three: the
    kernel is register-blocked for them, sharing the geometric weights (each signal keeps
    its own sigma_l). ``zero`` signals (colour and variance +0 everywhere) before the first
    and after the last other one are not filtered: their output, +0, is written as such."""
    p, work, mode, depth = ctx.params, ctx.work, ctx.mode, ctx.depth
    guide_luminance = ctx.plane("guide_luminance")
    guide_inverse_scale = ctx.plane("guide_inverse_scale")
    scale = luminance_stop_scale_for(p, ctx.frame.height, ctx.frame.width)
    sigmas = [scale * signal_sigma_luminance(p, signal) for signal in ctx.frame.signals]
    symmetric = [symmetric_stop(p, signal) for signal in ctx.frame.signals]
    span = filtered_span(zero)
    for part_of_span in signal_groups(span.stop - span.start):
        group = slice(span.start + part_of_span.start, span.start + part_of_span.stop)
        luminance_stop_guides(
            filtered[group], filtered_variance[group], mode, group.start, depth,
            sigmas[group], ctx.weights, guide_luminance[group], guide_inverse_scale[group],
            p.luminance_guide_blur, symmetric[group],
        )
        atrous_iteration(
            filtered[group], filtered_variance[group], guide_luminance[group],
            guide_inverse_scale[group], depth, work["ddx"], work["ddy"], ctx.normal,
            1 << iteration, p.sigma_depth, p.sigma_normal, propagate,
            out_illumination[group], out_variance[group],
        )
    for skipped in (slice(0, span.start), slice(span.stop, len(ctx.names))):
        out_illumination[skipped] = 0.0
        if propagate:
            out_variance[skipped] = 0.0


def signal_sigma_luminance(params: SVGFParams, signal: Signal) -> float:
    """The a-trous luminance stop of ``signal``: glossy signals' own, else mixed signals'
    own (direct and indirect light together), else ``sigma_luminance``."""
    if signal.glossy:
        return params.glossy_sigma_luminance or params.sigma_luminance
    if signal.mixed:
        return params.mixed_sigma_luminance or params.sigma_luminance
    return params.sigma_luminance


def symmetric_stop(params: SVGFParams, signal: Signal) -> bool:
    """Whether ``signal``'s luminance stop is symmetric (``mixed_symmetric_stop``): mixed
    signals' (direct and indirect light together, not glossy)."""
    return params.mixed_symmetric_stop and signal.mixed and not signal.glossy


def signal_groups(num_signals: int) -> list[slice]:
    """The a-trous filters signals in groups sharing the geometric weights: threes, but
    4 as 2 + 2 (a lone signal costs nearly as much as a pair), and 1 or 2 as they are."""
    sizes: list[int] = []
    left = num_signals
    while left > 0:
        size = 2 if left in (2, 4) else min(left, 3)
        sizes.append(size)
        left -= size
    starts = np.cumsum([0, *sizes])
    return [slice(int(a), int(b)) for a, b in zip(starts[:-1], starts[1:], strict=True)]


def filtered_span(zero: Sequence[bool]) -> slice:
    """The signals from the first to the last one that is not ``zero`` (empty if all are).
    A zero signal between two others is filtered with them (its output is +0 either way):
    splitting the group would cost more than it saves (a lone signal costs nearly a pair)."""
    kept = [s for s, z in enumerate(zero) if not z]
    return slice(kept[0], kept[-1] + 1) if kept else slice(0, 0)
