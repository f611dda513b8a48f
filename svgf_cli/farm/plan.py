"""Chunk plans: which frames a chunk replays for history and which it writes.

SVGF is recursive, so a chunk that starts mid-sequence replays a warm-up window of earlier
frames (processed, never written) before its first output frame; a bidirectional run's
reverse pass likewise replays the frames after its last output frame. The plan is independent of
any execution engine: the local runner, `svgf plan` and the Dask backend all consume it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from svgf_cli.io.patterns import format_frame_spec

# Warm-up frames per chunk when none is given (svgf plan; svgf denoise with --frames).
DEFAULT_WARMUP = 16
# The measured seam of that default (bench/warmup_error.py, docs/farm.md), for the log.
WARMUP_ERROR_NOTE = (
    "on a 48-frame test shot the first output frame was within 0.06 % mean absolute "
    "difference of --warmup all, largest pixel 0.005; --warmup all is bit-exact"
)


@dataclass(frozen=True)
class Chunk:
    """One independent unit of work.

    ``read`` is the inclusive range of timeline frames processed (warm-up plus written
    frames); ``write`` the frames written, sorted. Frames in ``read`` that are not in
    ``write`` are processed only to build history.
    """

    index: int
    read_start: int
    read_end: int
    write: tuple[int, ...]
    # The last frame read only for the look-ahead warm start of the chunk's first outputs
    # (``--warm-start``: a bidirectional run over the frames from ``read_start``); None: none.
    lookahead_end: int | None = None

    @property
    def write_start(self) -> int:
        return self.write[0]

    @property
    def write_end(self) -> int:
        return self.write[-1]

    def to_json(self) -> dict[str, object]:
        return {
            "chunk": self.index,
            "read": [self.read_start, max(self.read_end, self.lookahead_end or self.read_end)],
            "write": [self.write_start, self.write_end],
            "frames": format_frame_spec(self.write),
        }


def plan_chunks(
    write_frames: Sequence[int],
    timeline: Sequence[int],
    *,
    chunk_size: int | None,
    warmup: int | None,
    bidirectional: bool = False,
    warm_start: int = 0,
) -> list[Chunk]:
    """Split ``write_frames`` into chunks of at most ``chunk_size`` output frames.

    ``timeline`` lists every frame that can be processed, in processing order; each written
    frame must be in it. ``warmup`` counts timeline frames replayed before a chunk's first
    output (clamped at the timeline start); None means "all": replay from the first frame of
    the timeline, which reproduces the sequential run exactly. ``bidirectional``: the
    reverse pass needs the same warm-up after the chunk's last output (clamped at the
    timeline end; "all": to the last frame of the timeline). ``warm_start`` N (causal runs):
    a chunk that writes any of its first N frames (it starts cold) also reads up to its
    ``2 N``-th frame, for the look-ahead warm start of those outputs (``lookahead_end``).
    """
    if chunk_size is not None and chunk_size < 1:
        raise ValueError(f"chunk size must be at least 1, got {chunk_size}")
    if warmup is not None and warmup < 0:
        raise ValueError(f"warm-up must be >= 0 or 'all', got {warmup}")
    position = {frame: i for i, frame in enumerate(timeline)}
    missing = [f for f in write_frames if f not in position]
    if missing:
        raise ValueError(f"frame {missing[0]} is not in the sequence")
    ordered = sorted(set(write_frames), key=position.__getitem__)
    if not ordered:
        return []
    size = chunk_size or len(ordered)
    chunks: list[Chunk] = []
    for index, begin in enumerate(range(0, len(ordered), size)):
        group = tuple(ordered[begin : begin + size])
        first, last = position[group[0]], position[group[-1]]
        start = 0 if warmup is None else max(0, first - warmup)
        end = last
        if bidirectional:
            end = len(timeline) - 1 if warmup is None else min(len(timeline) - 1, last + warmup)
        look = None
        if warm_start and not bidirectional and first - start < warm_start:
            look = timeline[min(len(timeline) - 1, start + 2 * warm_start - 1)]
        chunks.append(Chunk(index, timeline[start], timeline[end], group, look))
    return chunks
