"""A shot's first frames warmed from the frames after them (look-ahead warm-up; off unless
called; docs/stability.md).

A causal run starts every shot cold: its first frames have one, two, three samples of
history, and on the bundled 10-16-frame sequences that cold start is the largest single
part of svgf's loss in video JOD against per-frame OIDN (docs/stability.md#summary). Here
the first ``warm`` output frames come from a bidirectional run (``two_pass``) over the first
``lookahead`` frames held in memory, where every frame has the history of the frames after
it too; the causal ``Denoiser`` still filters every frame from the first (its outputs of
the warmed frames are dropped), so from frame ``warm`` on the output is the causal run's,
bit for bit. Cost: one bidirectional run over ``lookahead`` frames per shot (about twice
that many causal frames), memory: ``lookahead`` input frames and their forward histories.

The file driver does the same over files (``svgf_cli.run.warm_start``, ``--warm-start``),
spilling the forward histories instead of holding the frames: this one is for tests and
evaluation over frames in memory.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Iterator
from itertools import islice

from svgf_cli.filters.denoiser import Denoiser
from svgf_cli.filters.params import PRESETS, SVGFParams
from svgf_cli.filters.two_pass import denoise_bidirectional
from svgf_cli.frame import DenoisedFrame, Frame

# The `default` preset's (docs/stability.md#warm-start): its first warm_start output frames
# from a bidirectional run over twice as many.
WARM_FRAMES = PRESETS["default"].warm_start
LOOKAHEAD_FRAMES = 2 * WARM_FRAMES


def lookahead_params(params: SVGFParams) -> SVGFParams:
    """The look-ahead's bidirectional run's settings: the causal run's, bidirectional. Its
    TAA (where the causal run has one) anti-aliases the warm colours backwards in time, so
    the first frame, which the causal TAA only takes as its history, is anti-aliased too;
    the causal TAA then blends the next warm colours with it
    (docs/stability.md#the-first-frame-anti-aliased)."""
    return params.replace(bidirectional=True)


def denoise_warm_start(
    frames: Iterable[Frame], params: SVGFParams, *, warm: int = WARM_FRAMES,
    lookahead: int = LOOKAHEAD_FRAMES,
) -> Iterator[DenoisedFrame]:
    """The outputs of ``frames`` in order: the first ``warm`` from a bidirectional run over
    the first ``lookahead`` frames, the rest from a causal ``Denoiser`` over every frame.

    ``warm`` 0 is the causal run itself. A sequence shorter than ``lookahead`` is looked
    ahead over whole."""
    if not 0 <= warm <= lookahead:
        raise ValueError(f"warm ({warm}) must be in 0 .. lookahead ({lookahead})")
    remaining = iter(frames)
    head = list(islice(remaining, lookahead))
    warmed = denoise_bidirectional(head, lookahead_params(params))[:warm] if warm and head else []
    causal = Denoiser(params)
    for index, frame in enumerate(head):
        if index >= len(warmed):
            yield causal.process(frame)
            continue
        # The warm colour as the causal run's final colour: its TAA (jittered frames)
        # anti-aliases it and starts its history there, as the file driver's run does.
        output = causal.process(dataclasses.replace(frame, final_colour=warmed[index].color))
        yield dataclasses.replace(warmed[index], color=output.color)
    for frame in remaining:
        yield causal.process(frame)
