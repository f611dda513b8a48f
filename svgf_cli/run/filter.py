"""The filter of one pass and the checks each frame passes before it is filtered
(`FrameFilter`), over any filter with a state (`PassFilter`: the causal ``Denoiser``, a
bidirectional run's ``ForwardPass`` and ``ReversePass``).
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Concatenate, Generic, ParamSpec, Protocol, TypeVar

import numpy as np

from svgf_cli.errors import InputError, UsageError
from svgf_cli.filters import id_stability
from svgf_cli.filters.params import SVGFParams
from svgf_cli.frame import DenoisedFrame, Frame
from svgf_cli.progress import Progress
from svgf_cli.run.history import HistoryFile, check_history_params, save_history
from svgf_cli.run.tasks import FrameTask, RunConfig, RunStats

if TYPE_CHECKING:
    from svgf_cli.io.exr import ReadResult


def stage_line(pass_filter: object, clocks: str = "stage_seconds") -> str:
    """The wall milliseconds of the last frame by clock (a pipeline filter's ``clocks``
    attribute, in pipeline order: ``stage_seconds``, the clocks that group stages, or
    ``stage_detail_seconds``, every stage that ran) as ``name ms, ...``; a filter made of
    pipeline filters (its attributes) as ``attribute: name ms, ...; ...``; empty for other
    filters."""
    seconds = getattr(pass_filter, clocks, None)
    if isinstance(seconds, dict):
        return ", ".join(f"{name} {1000 * value:.0f}" for name, value in seconds.items())
    parts = [f"{name}: {line}" for name, inner in getattr(pass_filter, "__dict__", {}).items()
             if isinstance(getattr(inner, clocks, None), dict)
             and (line := stage_line(inner, clocks))]
    return "; ".join(parts)


class PassFilter(Protocol):
    """What `FrameFilter` needs of a pass's filter; each pass's own ``process`` is called
    by its driver through :meth:`FrameFilter.process`."""

    def reset(self) -> None: ...
    def state(self) -> dict[str, np.ndarray]: ...
    def load_state(self, state: dict[str, np.ndarray]) -> None: ...


F = TypeVar("F", bound=PassFilter)
P = ParamSpec("P")
R = TypeVar("R")


class IdCheck:
    """Object ids that are renumbered from frame to frame (`filters.id_stability`) are let
    go: from the first frame whose ids changed where its surfaces did not, to the end of the
    pass, every frame is filtered as one without ids (one warning naming that frame)."""

    def __init__(self, progress: Progress) -> None:
        self._progress = progress
        self._previous: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self.unstable = False

    def admit(self, task: FrameTask, frame: Frame) -> None:
        if self.unstable:
            frame.mesh_id = id_stability.without_ids(frame.depth)
            return
        if task.reset_history:
            self._previous = None  # a new shot: its ids need not match the last one's
        previous = self._previous
        self._previous = id_stability.sampled_rows(frame.mesh_id, frame.depth, frame.normal)
        if previous is None:
            return
        changed, compared = id_stability.id_change_share(previous, frame.mesh_id, frame.depth,
                                                         frame.normal)
        if not id_stability.ids_unstable(changed, compared):
            return
        self.unstable = True
        self._previous = None
        frame.mesh_id = id_stability.without_ids(frame.depth)
        self._progress.warning(
            f"{task.input}: object ids changed on {100 * changed:.0f}% of the surfaces seen at "
            "the same depth and normal as in the frame before (ids renumbered from frame to "
            "frame, as Mitsuba's shape_index): ids ignored from this frame on")


class FrameFilter(Generic[F]):
    """The filter of one pass (``filter``), and the checks a frame passes before it is
    filtered.

    The first frame fixes the resolution, is checked against a loaded history file and then
    gets that history; every later frame must have the same resolution (InputError, exit 3,
    naming both sizes). Warnings of the reader and of the filter are reported against the
    frame's input. Frames processed, the last frame and compute seconds go to ``stats``.
    """

    def __init__(
        self,
        config: RunConfig,
        progress: Progress,
        stats: RunStats,
        make_filter: Callable[[SVGFParams, bool], F],
        *,
        history: HistoryFile | None = None,
        on_first_frame: Callable[[ReadResult], None] | None = None,
    ) -> None:
        try:
            self.filter: F = make_filter(config.params, config.debug_aovs)
        except ValueError as exc:
            raise UsageError(f"invalid SVGF parameters: {exc}") from None
        if history is not None:
            check_history_params(history, config.params)
        self._params = config.params
        self._progress = progress
        self._stats = stats
        self._history = history
        self._on_first_frame = on_first_frame
        self.size: tuple[int, int] | None = None  # (width, height) of the first frame
        self._size_source: Path | None = None
        self._ids = IdCheck(progress)

    def admit(self, task: FrameTask, result: ReadResult) -> None:
        """Report the read's warnings and check the frame's resolution."""
        for message in result.warnings:
            text = str(message)
            self._progress.warning(text if str(task.input) in text else f"{task.input}: {text}")
        frame_size = (result.frame.width, result.frame.height)
        if self.size is None:
            self._first_frame(task, result, frame_size)
        elif frame_size != self.size:
            raise InputError(
                f"resolution changed from {self.size[0]}x{self.size[1]} ({self._size_source}) "
                f"to {frame_size[0]}x{frame_size[1]}",
                str(task.input),
            )
        self._ids.admit(task, result.frame)

    def _first_frame(self, task: FrameTask, result: ReadResult, frame_size: tuple[int, int]
                     ) -> None:
        self.size, self._size_source = frame_size, task.input
        if self._on_first_frame is not None:
            self._on_first_frame(result)
        history = self._history
        if history is None:
            return
        if (history.width, history.height) != frame_size:
            raise InputError(
                f"resolution {frame_size[0]}x{frame_size[1]} does not match the "
                f"history in {history.path} ({history.width}x{history.height})",
                str(task.input),
            )
        try:
            self.filter.load_state(history.state)
        except ValueError as exc:
            raise InputError(f"cannot use history: {exc}", str(history.path)) from None

    def process(
        self,
        task: FrameTask,
        result: ReadResult,
        step: Callable[Concatenate[Frame, P], R],
        /,
        *args: P.args,
        **kwargs: P.kwargs,
    ) -> tuple[R, float]:
        """``step(frame, *args, **kwargs)`` (the pass's ``filter.process``) on an admitted
        frame, after a history reset when ``task`` asks for one; then let go of the frame's
        input planes and report the filter's warnings (of a `DenoisedFrame`). Returns what
        ``step`` returned and the seconds it took."""
        if task.reset_history:
            self.filter.reset()
        started = time.perf_counter()
        try:
            output = step(result.frame, *args, **kwargs)
        except ValueError as exc:
            raise InputError(str(exc), str(task.input)) from None
        seconds = time.perf_counter() - started
        self._stats.compute_seconds += seconds
        self._stats.frames_processed += 1
        self._stats.last_frame = task.frame
        # The filter has what it keeps: let this frame's planes go now rather than
        # while the next frame is read (memory holds fewer frames at once).
        with contextlib.suppress(AttributeError):
            result.frame = None  # type: ignore[assignment]  # let go: never read again
        if isinstance(output, DenoisedFrame):
            for message in output.warnings():
                self._progress.warning(f"{task.input}: {message}")
        line = stage_line(self.filter)
        if line:
            self._progress.detail(f"frame {task.frame} stages (ms): {line}")
        line = stage_line(self.filter, "stage_detail_seconds")
        if line:
            self._progress.detail(f"frame {task.frame} every stage (ms): {line}")
        return output, seconds

    def save_history(self, path: Path, last_input: Path) -> None:
        """Save the filter's state after the last frame processed (none: nothing)."""
        if self.size is None or self._stats.last_frame is None:
            return
        width, height = self.size
        state = self.filter.state()
        save_history(path, state, self._stats.last_frame, self._params, (height, width), last_input)
