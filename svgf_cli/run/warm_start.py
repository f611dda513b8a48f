"""The look-ahead warm start of a chunk that starts cold (``warm_start`` N; the default
preset's 4; docs/stability.md#warm-start).

A causal run starts every shot with one, two, three frames of history: its first frames are
the noisiest, and on the bundled sequences that cold start was the largest part of svgf's
loss in video quality against per-frame OIDN. Here the first N output frames of a chunk that
starts cold take their colour from a bidirectional run (`bidirectional.run_bidirectional`)
over the chunk's first ``2 N`` frames, where each of them has the history of the frames
after it too. The causal filter still runs over every frame from the first (`causal`): it
builds its history as always, and composes the light layers of a warm frame to the warm
colour (`Frame.final_colour`), so from frame N on the output is the causal run's, bit for
bit, and the look-ahead frames after the chunk's last output (`FrameTask.lookahead_only`)
are read by the bidirectional run alone.

Cost per cold start: a forward pass over N frames and a reverse pass over ``2 N``, and their
reads; memory: the bidirectional run's (one filter, two frames, a scratch folder) while it
runs, then N colour planes (float32) until their frames are written.
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from svgf_cli.errors import InputError
from svgf_cli.filters.warm_start import lookahead_params
from svgf_cli.progress import Progress
from svgf_cli.run.output import OutputFrame
from svgf_cli.run.stop import StopFlag
from svgf_cli.run.tasks import FrameTask, RunConfig, RunStats
from svgf_cli.run.workers import Reader, default_reader


def warm_head(tasks: Sequence[FrameTask], warm: int) -> list[FrameTask]:
    """The bidirectional run's frames for a chunk: its first ``2 warm`` frames, writing
    those of the first ``warm`` that the chunk writes; empty when it writes none of them
    (the chunk starts with warm-up frames: it is not a cold start)."""
    if warm <= 0 or not any(t.output is not None for t in tasks[:warm]):
        return []
    return [replace(t, output=t.output if i < warm else None, lookahead_only=False)
            for i, t in enumerate(tasks[: 2 * warm])]


def warm_colours(
    head: Sequence[FrameTask],
    config: RunConfig,
    *,
    stop: StopFlag | None = None,
    read: Reader = default_reader,
) -> tuple[dict[int, np.ndarray], RunStats]:
    """The colour of each output frame of ``head`` from a bidirectional run over it,
    (3, H, W) float32 by frame number, kept in memory (nothing is written), and the run's
    stats; none when a frame of ``head`` cannot be read (InputError: the causal run meets
    it too). Warnings are the causal run's to report: it reads the same frames."""
    from svgf_cli.run.bidirectional import run_bidirectional

    colours: dict[int, np.ndarray] = {}

    def keep_colour(task: FrameTask, output: OutputFrame) -> list[str]:
        planes = list(output.channels.values())[:3]  # the colour's R, G, B come first
        colours[task.frame] = np.stack(planes).astype(np.float32, copy=False)
        return []

    lean = replace(config, params=lookahead_params(config.params), colour_only=True,
                   float_colour=True, light_layers="as-read", debug_aovs=False)
    silent = Progress("lines", 0, quiet=True, out=io.StringIO(), err=io.StringIO())
    try:
        stats = run_bidirectional(head, lean, silent, stop=stop, read=read, write=keep_colour)
    except InputError:
        # A bad frame among the look-ahead: no warm start. The causal run writes the frames
        # before it and stops at it with the error, as without a warm start.
        return {}, RunStats()
    return colours, stats
