"""Resolve a `svgf denoise` invocation into chunks of frame tasks, checking everything first.

Every check that can fail without reading pixels happens here, before anything is written:
missing frames, outputs that would overwrite inputs, existing outputs, history continuity.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from svgf_cli.errors import InputError, OutputExistsError, UsageError
from svgf_cli.farm.plan import Chunk, plan_chunks
from svgf_cli.io.patterns import (
    SequencePattern,
    expand_inputs,
    format_frame_spec,
    has_frame_token,
    parse_frame_spec,
)
from svgf_cli.run.tasks import FrameTask


@dataclass
class DenoiseJob:
    """The resolved work: the input timeline, the output of each frame, and the chunks."""

    timeline: list[tuple[int, Path]]
    outputs: dict[int, Path]
    selected: list[int]
    chunks: list[Chunk]
    chunk_tasks: list[list[FrameTask]]
    skipped_existing: list[int] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    @property
    def frames_to_write(self) -> int:
        return sum(len(c.write) for c in self.chunks)

    def describe(self) -> list[str]:
        """Human-readable plan, one line per chunk (for --dry-run and -v)."""
        lines = []
        for chunk, tasks in zip(self.chunks, self.chunk_tasks, strict=True):
            history = [t.frame for t in tasks if t.output is None and not t.lookahead_only]
            first, last = tasks[0], tasks[-1]
            look = (f"; warm start looks ahead to {chunk.lookahead_end}"
                    if chunk.lookahead_end is not None else "")
            lines.append(
                f"chunk {chunk.index}: process {chunk.read_start}-{chunk.read_end} "
                f"({len(tasks) - sum(t.lookahead_only for t in tasks)} frames, "
                f"{len(history)} history-only), "
                f"write {format_frame_spec(chunk.write)} ({len(chunk.write)} frames){look}"
            )
            lines.append(f"  read  {first.input} .. {last.input}")
            outs = [t.output for t in tasks if t.output is not None]
            lines.append(f"  write {outs[0]} .. {outs[-1]}")
        return lines


def _is_directory_target(text: str) -> bool:
    return text.endswith(("/", os.sep)) or Path(text).is_dir()


def resolve_outputs(output: str, frames: Sequence[int], inputs: dict[int, Path]) -> dict[int, Path]:
    """Output path per frame: a pattern, a directory (same file names), or one file."""
    if _is_directory_target(output):
        return {f: Path(output) / inputs[f].name for f in frames}
    pattern = SequencePattern.parse(output)
    if not has_frame_token(output) and len(frames) == 1:
        return {frames[0]: Path(output)}
    if not pattern.is_sequence:
        raise UsageError(
            f"writing {len(frames)} frames needs an output pattern (e.g. out.####.exr) "
            "or a directory",
            output,
        )
    return {f: pattern.path(f) for f in frames}


def _check_not_inputs(outputs: dict[int, Path], timeline: list[tuple[int, Path]]) -> None:
    input_paths = {os.path.realpath(p): p for _, p in timeline}
    seen: dict[str, int] = {}
    for frame, out in outputs.items():
        real = os.path.realpath(out)
        if real in input_paths:
            raise UsageError(f"output is the input file {input_paths[real]}; refusing", str(out))
        if real in seen:
            raise UsageError(f"frames {seen[real]} and {frame} both write this file", str(out))
        seen[real] = frame


def _missing_path(pattern: SequencePattern | None, frame: int) -> str:
    """What an error about missing ``frame`` names: its file when the input is a sequence."""
    return (
        str(pattern.path(frame))
        if pattern is not None and pattern.is_sequence
        else (f"frame {frame}")
    )


def _select_frames(
    frames_spec: str | None,
    inputs: Sequence[str],
    timeline: list[tuple[int, Path]],
    pattern: SequencePattern | None,
    allow_gaps: bool,
    warnings: list[str],
) -> list[int]:
    """The frames ``--frames`` selects (all frames on disk without it); requested frames
    missing on disk are an InputError, or skipped with a warning under ``allow_gaps``."""
    if frames_spec is None:
        return [f for f, _ in timeline]
    by_frame = dict(timeline)
    try:
        selected = parse_frame_spec(frames_spec)
    except ValueError as exc:
        raise UsageError(f"--frames: {exc}") from None
    absent = [f for f in selected if f not in by_frame]
    if absent:
        if not allow_gaps:
            raise InputError(
                f"requested frame {absent[0]} not found on disk ({len(absent)} of "
                f"{len(selected)} requested frames missing; --allow-gaps skips them)",
                _missing_path(pattern, absent[0]),
            )
        warnings.append(
            f"{len(absent)} requested frame(s) missing on disk, skipped: "
            f"{format_frame_spec(absent)}"
        )
        selected = [f for f in selected if f in by_frame]
    if not selected:
        raise InputError(f"none of the frames {frames_spec} exist", inputs[0])
    return selected


def _existing_outputs(
    outputs: dict[int, Path], selected: list[int], overwrite: bool, skip_existing: bool
) -> list[int]:
    """The selected frames whose output exists; OutputExistsError unless the run may
    overwrite or skip them."""
    existing = [f for f in selected if outputs[f].exists()]
    if existing and not (overwrite or skip_existing):
        raise OutputExistsError(
            f"output exists ({len(existing)} of {len(selected)} outputs exist; "
            "use --overwrite or --skip-existing)",
            str(outputs[existing[0]]),
        )
    return existing


def _chunk_tasks(
    chunk: Chunk,
    usable: list[tuple[int, Path]],
    outputs: dict[int, Path],
    *,
    contiguous: bool,
    allow_gaps: bool,
    history_last_frame: int | None,
    pattern: SequencePattern | None,
    warnings: list[str],
) -> list[FrameTask]:
    """One chunk's frame tasks in order; a gap in a contiguous sequence is an InputError, or
    resets the history with a warning under ``allow_gaps``."""
    write = set(chunk.write)
    last_read = max(chunk.read_end, chunk.lookahead_end or chunk.read_end)
    frames = [(f, p) for f, p in usable if chunk.read_start <= f <= last_read]
    expected_previous = (
        history_last_frame if history_last_frame is not None and chunk.index == 0 else None
    )
    tasks: list[FrameTask] = []
    previous = expected_previous
    for f, p in frames:
        reset = False
        if contiguous and previous is not None and f != previous + 1:
            gap = f"{previous + 1}" if f == previous + 2 else f"{previous + 1}-{f - 1}"
            if not allow_gaps:
                raise InputError(
                    f"frame {previous + 1} is missing on disk (frames {gap}; needed for the "
                    f"history of frame {f}; --allow-gaps resets history instead)",
                    _missing_path(pattern, previous + 1),
                )
            reset = True
            warnings.append(f"frame(s) {gap} missing on disk: history reset at frame {f}")
        tasks.append(FrameTask(f, p, outputs[f] if f in write else None, reset,
                               lookahead_only=f > chunk.read_end))
        previous = f
    return tasks


def build_job(
    inputs: Sequence[str],
    output: str,
    *,
    frames_spec: str | None = None,
    warmup: int | None = None,
    allow_gaps: bool = False,
    skip_existing: bool = False,
    overwrite: bool = False,
    chunk_size: int | None = None,
    history_last_frame: int | None = None,
    bidirectional: bool = False,
    warm_start: int = 0,
) -> DenoiseJob:
    """Resolve inputs, outputs, frames, warm-up and chunks; raise before anything is written.

    ``warmup`` None means "all" (replay from the first frame of the sequence, or from the
    frame after ``history_last_frame`` when a history file is loaded); ``bidirectional``
    adds the same warm-up after each chunk (the reverse pass's); ``warm_start`` the
    look-ahead frames of a chunk that starts cold (`plan.plan_chunks`; none with a loaded
    history, which is not a cold start).
    """
    if skip_existing and overwrite:
        raise UsageError("--skip-existing and --overwrite contradict each other")
    timeline = expand_inputs(list(inputs))
    pattern = SequencePattern.parse(inputs[0]) if len(inputs) == 1 else None
    contiguous = pattern is not None and pattern.is_sequence
    warnings: list[str] = []
    selected = _select_frames(frames_spec, inputs, timeline, pattern, allow_gaps, warnings)

    usable = timeline
    if history_last_frame is not None:
        early = [f for f in selected if f <= history_last_frame]
        if early:
            raise UsageError(
                f"the loaded history ends at frame {history_last_frame}; cannot write frame "
                f"{early[0]} (select later frames with --frames)"
            )
        usable = [(f, p) for f, p in timeline if f > history_last_frame]
        warmup = None  # continue from the frame after the saved one: exact

    outputs = resolve_outputs(output, selected, dict(timeline))
    _check_not_inputs(outputs, timeline)
    existing = _existing_outputs(outputs, selected, overwrite, skip_existing)
    write_frames = [f for f in selected if not (skip_existing and f in existing)]

    chunks = plan_chunks(write_frames, [f for f, _ in usable], chunk_size=chunk_size,
                         warmup=warmup, bidirectional=bidirectional,
                         warm_start=0 if history_last_frame is not None else warm_start)
    chunk_tasks = [
        _chunk_tasks(chunk, usable, outputs, contiguous=contiguous, allow_gaps=allow_gaps,
                     history_last_frame=history_last_frame, pattern=pattern,
                     warnings=warnings)
        for chunk in chunks
    ]  # fmt: skip
    return DenoiseJob(
        timeline=timeline,
        outputs=outputs,
        selected=selected,
        chunks=chunks,
        chunk_tasks=chunk_tasks,
        skipped_existing=[f for f in existing if skip_existing],
        warnings=list(dict.fromkeys(warnings)),
    )
