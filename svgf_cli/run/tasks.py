"""The frames of a chunk and the run's bookkeeping: `FrameTask`, `RunConfig`, `RunStats`,
the resume helpers (`pending_tasks`, `trim_tail`) and the warm-up count (`WarmupCount`).

Everything here is plain data (picklable: shipped to Dask workers), no I/O.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

from svgf_cli.filters.params import SVGFParams
from svgf_cli.progress import Progress

if TYPE_CHECKING:
    from svgf_cli.io.layers import LayerMapping


@dataclass(frozen=True)
class FrameTask:
    """One frame of a chunk. ``output`` None: processed for history only, never written."""

    frame: int
    input: Path
    output: Path | None
    reset_history: bool = False  # --allow-gaps: a frame before this one is missing
    # Read only by the look-ahead warm start (after the chunk's last output; run.warm_start).
    lookahead_only: bool = False


@dataclass(frozen=True)
class RunConfig:
    """Everything a chunk needs besides its frames; picklable (shipped to Dask workers)."""

    params: SVGFParams
    preset: str
    mapping: LayerMapping
    float_colour: bool = False  # --float; else the colour keeps the input's pixel type
    compression: str | None = None  # None: each part keeps the input's compression
    debug_aovs: bool = False
    warmup_label: str = "all"
    threads: int | None = None
    colour_only: bool = False  # --colour-only: only the colour layer and its alpha
    scratch_dir: Path | None = None  # --scratch-dir (bidirectional); None: the system's
    # --light-layers: "denoised" writes the light passes and groups denoised (run.light);
    # "as-read" passes them through. The CLI's default is "denoised".
    light_layers: str = "as-read"
    # --low-memory: a causal run reads a frame only once the one before is filtered.
    low_memory: bool = False
    # Freed frame-sized blocks kept for the next frame (svgf_cli.heap.keep_freed_blocks).
    keep_memory: bool = False


@dataclass
class RunStats:
    """What a run did and where its time went (seconds, summed over frames).

    Each part of the driver adds its own fields: `ReadAhead` the read seconds, `FrameFilter`
    the frames processed and compute seconds, `WriteBehind` the frames written.
    """

    frames_processed: int = 0
    frames_written: int = 0
    read_seconds: float = 0.0
    compute_seconds: float = 0.0
    write_seconds: float = 0.0
    wait_read_seconds: float = 0.0
    wall_seconds: float = 0.0
    last_frame: int | None = None
    written: list[int] = field(default_factory=list)

    def merge(self, other: RunStats) -> None:
        self.frames_processed += other.frames_processed
        self.frames_written += other.frames_written
        self.read_seconds += other.read_seconds
        self.compute_seconds += other.compute_seconds
        self.write_seconds += other.write_seconds
        self.wait_read_seconds += other.wait_read_seconds
        self.wall_seconds += other.wall_seconds
        self.written.extend(other.written)
        if other.last_frame is not None:
            self.last_frame = other.last_frame


def pending_tasks(tasks: Sequence[FrameTask], overwrite: bool) -> list[FrameTask]:
    """Retry-safe view of a chunk: outputs that already exist are not written again.

    Writes are atomic, so an existing output is a complete one; with ``overwrite`` every
    output is written (deterministic, so a retry rewrites identical bytes).
    """
    if overwrite:
        return list(tasks)
    return [
        t
        if t.output is None or not t.output.exists()
        else replace(t, output=None)
        for t in tasks
    ]


def trim_tail(tasks: Sequence[FrameTask]) -> list[FrameTask]:
    """Drop history-only frames after the last written one (nothing depends on them; the
    look-ahead frames of a warm start are kept: its outputs depend on them)."""
    last = max((i for i, t in enumerate(tasks) if t.output is not None or t.lookahead_only),
               default=-1)
    return list(tasks[: last + 1])


class WarmupCount:
    """Warm-up frames processed so far, reported as ``Warmup: n/total``."""

    def __init__(self, progress: Progress, total: int) -> None:
        self._progress = progress
        self.total = total
        self.seen = 0

    def frame_done(self, frame: int) -> None:
        self.seen += 1
        self._progress.warmup(frame, self.seen, self.total)
