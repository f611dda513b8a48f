"""`python -m svgf_cli ARGS` as the signal and kill tests start it (`svgf_subprocess`).

* SIGINT and SIGTERM start with their default dispositions, whatever the test run inherited:
  a run started as a background job of a non-interactive shell has SIGINT ignored, and an
  ignored disposition survives exec.
* ``--pause-before N`` (before ARGS): the Denoiser stops before filtering its frame N
  (0-based), prints ``{"event": "paused"}`` on stdout and waits for SIGINT, SIGTERM or
  SIGKILL. SIGINT/SIGTERM are then raised again, so the run's own handler sees them while
  that frame is in flight. A test signals a run at a known frame however fast or loaded the
  machine is, instead of racing it.
"""

from __future__ import annotations

import json
import os
import runpy
import signal
import sys
import time
from typing import Any

STOP_SIGNALS = {signal.SIGINT, signal.SIGTERM}


def pause_before(index: int) -> None:
    from svgf_cli.filters.denoiser import Denoiser

    process = Denoiser.process

    def paused_process(self: Any, frame: Any) -> Any:
        if self.frames_processed == index:
            received: list[int] = []
            # Caught before the line is printed, so a signal sent at once is not missed;
            # Python runs the handler in this (the main) thread whichever thread got it.
            runs = {s: signal.signal(s, lambda n, _: received.append(n)) for s in STOP_SIGNALS}
            # One write(2) to the descriptor, past sys.stdout: the writer thread may be
            # printing a frame_done line through it now (svgf_cli.progress's lock).
            os.write(1, (json.dumps({"event": "paused"}) + "\n").encode())
            while not received:
                time.sleep(0.01)
            for s, handler in runs.items():
                signal.signal(s, handler)
            signal.raise_signal(received[0])  # now to the run's own handler
        return process(self, frame)

    Denoiser.process = paused_process  # type: ignore[method-assign]


def main(argv: list[str]) -> None:
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if argv and argv[0] == "--pause-before":
        pause_before(int(argv[1]))
        argv = argv[2:]
    sys.argv = ["svgf", *argv]
    runpy.run_module("svgf_cli", run_name="__main__", alter_sys=True)


if __name__ == "__main__":
    main(sys.argv[1:])
