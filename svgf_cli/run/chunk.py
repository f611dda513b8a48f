"""The entry point of a chunk (`run_sequence`): the causal driver (`causal`), after the
look-ahead warm start of a chunk that starts cold (`warm_start`), or both passes of a
bidirectional run (`bidirectional`, imported only then: it brings the two-pass filter in).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from svgf_cli.filters.params import SVGFParams
from svgf_cli.heap import keep_freed_blocks, map_large_blocks
from svgf_cli.progress import Progress
from svgf_cli.run.causal import CausalFilter, default_denoiser, run_causal
from svgf_cli.run.history import HistoryFile
from svgf_cli.run.stages import describe_stages
from svgf_cli.run.stop import StopFlag
from svgf_cli.run.tasks import FrameTask, RunConfig, RunStats
from svgf_cli.run.warm_start import warm_head
from svgf_cli.run.workers import Reader, default_reader

if TYPE_CHECKING:
    from svgf_cli.io.exr import ReadResult


def run_sequence(
    tasks: Sequence[FrameTask],
    config: RunConfig,
    progress: Progress,
    *,
    stop: StopFlag | None = None,
    history: HistoryFile | None = None,
    save_history_to: Path | None = None,
    warmup_total: int | None = None,
    on_first_frame: Callable[[ReadResult], None] | None = None,
    make_denoiser: Callable[[SVGFParams, bool], CausalFilter] = default_denoiser,
    read: Reader = default_reader,
) -> RunStats:
    """Run the filter over ``tasks`` in order, writing the frames that have an output.

    Raises InputError (exit 3) for an unreadable frame or a resolution change (the frames
    before it are written, nothing for it), UsageError for a history file from other
    parameters, Interrupted after a SIGINT/SIGTERM once the frame in flight is written.
    A bidirectional run (``config.params.bidirectional``) uses neither a history file nor
    ``make_denoiser``.
    """
    # Frame-sized arrays go back to the system when freed: without this the peak memory
    # grows with the frames run (svgf_cli.heap); --keep-memory keeps them instead.
    map_large_blocks()
    if config.keep_memory:
        keep_freed_blocks()
    for line in describe_stages(config.params):
        progress.detail(line)
    if config.params.bidirectional:
        from svgf_cli.run.bidirectional import run_bidirectional

        return run_bidirectional(tasks, config, progress, stop=stop,
                                 on_first_frame=on_first_frame, read=read)
    warm_start = 0 if history is not None else config.params.warm_start
    head = warm_head(tasks, warm_start)
    warm: dict[int, np.ndarray] = {}
    head_stats = RunStats()
    if head:
        from svgf_cli.run.warm_start import warm_colours

        written = [t.frame for t in head if t.output is not None]
        progress.detail(f"warm start: frame(s) {written[0]}-{written[-1]} from a "
                        f"bidirectional run over frames {head[0].frame}-{head[-1].frame}")
        warm, head_stats = warm_colours(head, config, stop=stop, read=read)
    stats = run_causal(
        [t for t in tasks if not t.lookahead_only], config, progress, stop=stop,
        history=history, save_history_to=save_history_to, warmup_total=warmup_total,
        on_first_frame=on_first_frame, make_denoiser=make_denoiser, read=read,
        warm_colours=warm,
    )
    stats.read_seconds += head_stats.read_seconds
    stats.compute_seconds += head_stats.compute_seconds
    stats.wall_seconds += head_stats.wall_seconds
    return stats
