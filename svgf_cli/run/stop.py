"""Stopping a run: SIGINT/SIGTERM as a stop flag polled between frames (`stop_on_signals`,
`StopFlag`), the error that ends the run (`Interrupted`, exit 130/143), and the blocking
of both signals on the I/O threads (`block_signals`).

SIGINT/SIGTERM finish the frame in flight and then stop; the I/O threads never receive
them.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType

from svgf_cli.errors import EXIT_SIGINT, EXIT_SIGTERM, SvgfError


class Interrupted(SvgfError):
    """SIGINT/SIGTERM arrived; the frame in flight was finished first."""

    def __init__(self, signum: int, detail: str) -> None:
        name = signal.Signals(signum).name
        super().__init__(f"interrupted by {name}; {detail}")
        self.signum = signum
        self.exit_code = EXIT_SIGINT if signum == signal.SIGINT else EXIT_SIGTERM

    def __reduce__(self) -> tuple[Callable[[int, str], Interrupted], tuple[int, str]]:
        return (_rebuild_interrupted, (self.signum, str(self)))


def _rebuild_interrupted(signum: int, message: str) -> Interrupted:
    exc = Interrupted.__new__(Interrupted)
    SvgfError.__init__(exc, message)
    exc.signum = signum
    exc.exit_code = EXIT_SIGINT if signum == signal.SIGINT else EXIT_SIGTERM
    return exc


class StopFlag:
    """Set by the signal handlers; polled between frames."""

    def __init__(self) -> None:
        self.signum: int | None = None

    def __bool__(self) -> bool:
        return self.signum is not None


def interrupted(stop: StopFlag, last_frame: int) -> Interrupted:
    """The error that ends a run stopped by ``stop`` after frame ``last_frame``."""
    assert stop.signum is not None
    return Interrupted(
        stop.signum,
        f"frame {last_frame} was the last one finished; rerun with --skip-existing to resume",
    )


@contextmanager
def stop_on_signals(immediate: bool = False) -> Iterator[StopFlag]:
    """Turn SIGINT/SIGTERM into a stop request for the duration of the block.

    The first signal only sets the flag (the runner finishes the frame in flight, then
    raises ``Interrupted``); a second one, or any signal with ``immediate``, raises at once.
    Outside the main thread (Dask workers) signals cannot be caught: the flag stays unset.
    """
    flag = StopFlag()
    if threading.current_thread() is not threading.main_thread():
        yield flag
        return

    def handler(signum: int, _frame: FrameType | None) -> None:
        if immediate or flag.signum is not None:
            raise Interrupted(signum, "stopped at once; rerun with --skip-existing to resume")
        flag.signum = signum

    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield flag
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


def block_signals() -> None:
    """Keep SIGINT/SIGTERM off the I/O threads: only the main thread may receive them
    (the initializer of every reader and writer thread).

    CPython installs its handlers without SA_RESTART, so a signal delivered to a thread
    that is inside OpenEXR's read() or write() interrupts the system call (EINTR), which the
    library does not retry: the frame in flight was read or written wrong. Measured: a
    SIGINT during a read-ahead made the next written frame differ from the uninterrupted run.
    """
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
