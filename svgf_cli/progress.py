"""Progress and log output in the formats render-farm managers parse.

Below both the runner and ``farm/``: `svgf denoise`, `svgf trace` and the Dask backend all
report through ``Progress``.

* ``bar``: a tqdm progress bar on a terminal (one rewritten line).
* ``lines``: one flushed line per written frame, ``Progress: 37% (frame 1037, 37/100,
  0.4 s/frame)``, which Deadline's stock ``.*Progress: (\\d+)%.*`` handler understands;
  warm-up frames print ``Warmup: 3/16`` and do not count towards the percentage.
* ``json``: one JSON object per line (``{"event": "frame_done", ...}``) for scripts.

The ``lines`` and ``json`` formats are written here by hand: their exact text is a contract
with farm parsers, which no progress library keeps. ``auto`` picks ``bar`` when stdout is a
terminal and ``lines`` otherwise. Start-up information goes to stdout, except in ``json``
mode where stdout carries only JSON and information goes to stderr. Warnings always go to
stderr prefixed ``WARNING:``.
"""

from __future__ import annotations

import functools
import json
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any, Concatenate, ParamSpec, TextIO, TypeVar

PROGRESS_MODES = ("auto", "bar", "lines", "json")
RATE_WINDOW = 10

# One lock for every report of every Progress: the writer thread reports written frames
# while the main and reader threads report the rest, all on the same sys.stdout/stderr.
# Two threads inside one TextIOWrapper.write interleave their lines, and on CPython 3.11
# can crash the process (python/cpython#119506: the wrapper's pending text is not
# guarded while the buffer's write releases the GIL). Measured: a SIGTERM test's child
# died of SIGSEGV in 3 of 45 runs, its main thread in print() while the writer thread
# printed a frame_done line.
_REPORT_LOCK = threading.RLock()

_P = ParamSpec("_P")
_R = TypeVar("_R")


def _serialised(method: Callable[Concatenate[Progress, _P], _R]
                ) -> Callable[Concatenate[Progress, _P], _R]:
    """Run ``method`` holding the report lock (its counters and its lines together)."""

    @functools.wraps(method)
    def locked(self: Progress, *args: _P.args, **kwargs: _P.kwargs) -> _R:
        with _REPORT_LOCK:
            return method(self, *args, **kwargs)

    return locked


def resolve_mode(mode: str, stream: TextIO) -> str:
    if mode not in PROGRESS_MODES:
        raise ValueError(f"unknown progress mode {mode!r}")
    if mode != "auto":
        return mode
    isatty = getattr(stream, "isatty", None)
    return "bar" if isatty is not None and isatty() else "lines"


class Progress:
    """Reports start-up information, warm-up frames, written frames and warnings."""

    def __init__(
        self,
        mode: str = "auto",
        total: int = 0,
        *,
        quiet: bool = False,
        verbose: bool = False,
        out: TextIO | None = None,
        err: TextIO | None = None,
    ) -> None:
        self.out = out if out is not None else sys.stdout
        self.err = err if err is not None else sys.stderr
        self.mode = resolve_mode(mode, self.out)
        # -q silences the start-up log and the automatic progress display; an explicitly
        # requested format (a farm parser depends on it) is still honoured.
        self.show_progress = not (quiet and mode == "auto")
        self.quiet = quiet
        self.verbose = verbose
        self.total = total
        self.done = 0
        # A bidirectional run makes two passes over its output frames (set by the caller):
        # the percentage counts forward-pass frames (``forward``) and written ones.
        self.passes = 1
        self.forward = 0
        self.seconds_written = 0.0
        # s/frame over the most recent frames: the first ones pay for JIT compilation.
        self.recent: deque[float] = deque(maxlen=RATE_WINDOW)
        self.started = time.perf_counter()
        self._bar: Any = None  # tqdm bar, opened on the first frame in bar mode

    # -- plain messages ----------------------------------------------------------------
    @_serialised
    def info(self, message: str) -> None:
        """A start-up / summary line (suppressed by -q)."""
        if self.quiet:
            return
        self._print(message, self.err if self.mode == "json" else self.out)

    @_serialised
    def detail(self, message: str) -> None:
        """A -v line (timings, per-frame details); never on stdout in json mode."""
        if not self.verbose:
            return
        self._print(message, self.err if self.mode == "json" else self.out)

    @_serialised
    def warning(self, message: str) -> None:
        self._print(f"WARNING: {message}", self.err)

    # -- progress -----------------------------------------------------------------------
    @_serialised
    def warmup(self, frame: int, index: int, total: int) -> None:
        """Warm-up frame ``index`` (1-based) of ``total`` was processed (not written)."""
        if not self.show_progress:
            return
        if self.mode == "json":
            self._json({"event": "warmup", "frame": frame, "index": index, "total": total})
        elif self.mode == "bar":
            self._open_bar().set_description_str(f"Warmup: {index}/{total} (frame {frame})")
        else:
            print(f"Warmup: {index}/{total} (frame {frame})", file=self.out, flush=True)

    @_serialised
    def forward_done(self, frame: int) -> None:
        """A bidirectional run's forward pass processed output frame ``frame`` (half of its
        work: the percentage counts both passes once ``passes`` is 2)."""
        self.forward += 1
        if not self.show_progress:
            return
        total = max(self.total, self.forward)
        percent = self._percent()
        if self.mode == "json":
            self._json({"event": "forward", "frame": frame, "index": self.forward,
                        "total": total, "percent": percent})
        elif self.mode == "bar":
            bar = self._open_bar()
            bar.set_description_str(f"forward pass, frame {frame}", refresh=False)
            bar.total = total * self.passes
            bar.update(self.forward + self.done - bar.n)
        else:
            print(f"Progress: {percent}% (forward pass, frame {frame}, "
                  f"{self.forward}/{total})", file=self.out, flush=True)

    def _percent(self) -> int:
        """Work done: written frames, plus forward-pass frames in a bidirectional run."""
        total = max(self.total, self.done) * self.passes
        return int(100 * (self.done + self.forward) / total) if total else 100

    @_serialised
    def frame_done(self, frame: int, seconds: float) -> None:
        """An output frame was written; ``seconds`` is its wall time."""
        self.done += 1
        self.seconds_written += seconds
        self.recent.append(seconds)
        if not self.show_progress:
            return
        total = max(self.total, self.done)
        percent = self._percent()
        mean = sum(self.recent) / len(self.recent)
        if self.mode == "json":
            self._json(
                {
                    "event": "frame_done",
                    "frame": frame,
                    "index": self.done,
                    "total": total,
                    "seconds": round(seconds, 4),
                    "percent": percent,
                }
            )
        elif self.mode == "bar":
            bar = self._open_bar()
            bar.set_description_str(f"frame {frame}", refresh=False)
            bar.total = total * self.passes
            bar.update(self.done + self.forward - bar.n)
        else:
            print(
                f"Progress: {percent}% (frame {frame}, {self.done}/{total}, {mean:.2f} s/frame)",
                file=self.out,
                flush=True,
            )

    @_serialised
    def finish(self, message: str | None = None) -> None:
        """End of the run: close the bar, print the summary (or a json ``done`` event)."""
        self._end_bar()
        elapsed = time.perf_counter() - self.started
        if self.mode == "json" and self.show_progress:
            self._json({"event": "done", "frames": self.done, "seconds": round(elapsed, 3)})
        if message:
            self.info(message)

    # -- helpers ------------------------------------------------------------------------
    def _json(self, record: dict[str, object]) -> None:
        print(json.dumps(record), file=self.out, flush=True)

    def _print(self, message: str, stream: TextIO) -> None:
        """A whole line; while a bar is drawn, tqdm clears it, prints, and redraws it."""
        if self._bar is not None:
            self._bar.write(message, file=stream)
            stream.flush()
        else:
            print(message, file=stream, flush=True)

    def _open_bar(self) -> Any:
        if self._bar is None:
            from tqdm import tqdm

            self._bar = tqdm(
                total=self.total,
                unit="frame",
                file=self.out,
                dynamic_ncols=True,
                leave=True,
                smoothing=0.3,  # the first frames pay for JIT compilation
            )
        return self._bar

    def _end_bar(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None
