"""The scratch I/O threads of a bidirectional run: packed forward states written to the
scratch folder by one thread (`SpillWrites`) and read back by another (`StateReads`), one
operation in flight each, both started with SIGINT/SIGTERM blocked (`stop.block_signals`).
"""

from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from typing import TYPE_CHECKING

from svgf_cli.run.stop import block_signals

if TYPE_CHECKING:
    from svgf_cli.filters.two_pass import PackedHistory
    from svgf_cli.io.spill import ScratchFolder


class SpillWrites:
    """Packed forward states written by one thread, one write in flight (the next frame is
    filtered meanwhile). Leaving the ``with`` block waits for the write in flight."""

    def __init__(self, scratch: ScratchFolder) -> None:
        self._scratch = scratch
        self._executor = ThreadPoolExecutor(
            1, thread_name_prefix="svgf-spill", initializer=block_signals
        )
        self._pending: Future[None] | None = None

    def submit(self, frame: int, packed: PackedHistory) -> None:
        self.finish()
        self._pending = self._executor.submit(self._scratch.write, frame, *packed)

    def finish(self) -> None:
        if self._pending is not None:
            pending, self._pending = self._pending, None
            pending.result()

    def __enter__(self) -> SpillWrites:
        return self

    def __exit__(self, *exc_info: object) -> None:
        try:
            if self._pending is not None:
                self._pending.exception()  # wait; the error being unwound is the one to report
        finally:
            self._executor.shutdown(wait=True)


class StateReads:
    """Packed forward states read back by one thread, one read in flight. The read of the
    next output frame's state starts when :meth:`prefetch` is called (after the frame before
    it is filtered), never while a frame is combined and filtered: at most one packed state
    is held at the memory peak, none beside an unpacked one."""

    def __init__(self, scratch: ScratchFolder, frames: Sequence[int]) -> None:
        self._scratch = scratch
        self._frames = list(frames)
        self._position = 0
        self._executor = ThreadPoolExecutor(
            1, thread_name_prefix="svgf-state", initializer=block_signals
        )
        self._pending: Future[PackedHistory] | None = None

    def prefetch(self) -> None:
        """Start reading the next state, if any and not started yet."""
        if self._pending is None and self._position < len(self._frames):
            self._pending = self._executor.submit(self._scratch.read,
                                                  self._frames[self._position])

    def take(self, frame: int) -> PackedHistory:
        """Frame ``frame``'s state (the next one in order), waiting for its read."""
        assert self._frames[self._position] == frame, (frame, self._frames[self._position])
        self.prefetch()
        assert self._pending is not None
        pending, self._pending = self._pending, None
        self._position += 1
        return pending.result()

    def __enter__(self) -> StateReads:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self._pending = None
        self._executor.shutdown(wait=True, cancel_futures=True)
