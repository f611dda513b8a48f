"""Progress and log output in the formats render-farm managers parse.

* ``bar``: a single rewritten line on a terminal.
* ``lines``: one flushed line per written frame, ``Progress: 37% (frame 1037, 37/100,
  0.4 s/frame)``, which Deadline's stock ``.*Progress: (\\d+)%.*`` handler understands;
  warm-up frames print ``Warmup: 3/16`` and do not count towards the percentage.
* ``json``: one JSON object per line (``{"event": "frame_done", ...}``) for scripts.

``auto`` picks ``bar`` when stdout is a terminal and ``lines`` otherwise. Start-up information
goes to stdout, except in ``json`` mode where stdout carries only JSON and information goes to
stderr. Warnings always go to stderr prefixed ``WARNING:``.
"""

from __future__ import annotations

import json
import sys
import time
from collections import deque
from typing import TextIO

PROGRESS_MODES = ("auto", "bar", "lines", "json")
RATE_WINDOW = 10


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
        self.seconds_written = 0.0
        # s/frame over the most recent frames: the first ones pay for JIT compilation.
        self.recent: deque[float] = deque(maxlen=RATE_WINDOW)
        self.started = time.perf_counter()
        self._bar_open = False

    # -- plain messages ----------------------------------------------------------------
    def info(self, message: str) -> None:
        """A start-up / summary line (suppressed by -q)."""
        if self.quiet:
            return
        self._end_bar()
        stream = self.err if self.mode == "json" else self.out
        print(message, file=stream, flush=True)

    def detail(self, message: str) -> None:
        """A -v line (timings, per-frame details); never on stdout in json mode."""
        if not self.verbose:
            return
        self._end_bar()
        stream = self.err if self.mode == "json" else self.out
        print(message, file=stream, flush=True)

    def warning(self, message: str) -> None:
        self._end_bar()
        print(f"WARNING: {message}", file=self.err, flush=True)

    # -- progress -----------------------------------------------------------------------
    def warmup(self, frame: int, index: int, total: int) -> None:
        """Warm-up frame ``index`` (1-based) of ``total`` was processed (not written)."""
        if not self.show_progress:
            return
        if self.mode == "json":
            self._json({"event": "warmup", "frame": frame, "index": index, "total": total})
        elif self.mode == "bar":
            self._bar(f"Warmup: {index}/{total} (frame {frame})")
        else:
            print(f"Warmup: {index}/{total} (frame {frame})", file=self.out, flush=True)

    def frame_done(self, frame: int, seconds: float) -> None:
        """An output frame was written; ``seconds`` is its wall time."""
        self.done += 1
        self.seconds_written += seconds
        self.recent.append(seconds)
        if not self.show_progress:
            return
        total = max(self.total, self.done)
        percent = int(100 * self.done / total) if total else 100
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
            width = 30
            filled = int(width * self.done / total) if total else width
            eta = mean * (total - self.done)
            self._bar(
                f"[{'#' * filled}{'-' * (width - filled)}] {percent:3d}% frame {frame} "
                f"{self.done}/{total} {mean:.2f} s/frame ETA {eta:.0f} s"
            )
        else:
            print(
                f"Progress: {percent}% (frame {frame}, {self.done}/{total}, {mean:.2f} s/frame)",
                file=self.out,
                flush=True,
            )

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

    def _bar(self, text: str) -> None:
        self.out.write("\r" + text + "\x1b[K")
        self.out.flush()
        self._bar_open = True

    def _end_bar(self) -> None:
        if self._bar_open:
            self.out.write("\n")
            self.out.flush()
            self._bar_open = False
