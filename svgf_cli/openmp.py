"""The process's OpenMP wait policy: threads that wait for work sleep instead of spinning.

numba's parallel kernels run on the OpenMP runtime (GNU libgomp here), whose worker threads
by default spin for a while (libgomp: up to 300,000 polls) before sleeping, whenever a
parallel region ends or a partner is late. `svgf denoise` runs a reader and a writer
thread (OpenEXR decoding and encoding, with their own pool threads) beside the filter on
the same cores, so a spinning worker burns a core that the I/O threads need, and a worker
waits longest exactly when an I/O thread has taken its partner's core. Measured at 1080p on
2 shared cores (docs/performance.md): about 0.3 CPU-seconds per frame, end to end, with
bit-identical outputs (the policy only changes how idle threads wait).

`wait_passively` must run before the first parallel kernel: the runtime reads the setting
once, when it is loaded. A user's own ``OMP_WAIT_POLICY`` or ``GOMP_SPINCOUNT`` wins.
"""

from __future__ import annotations

import os

_USER_SETTINGS = ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT")


def wait_passively() -> bool:
    """Set ``OMP_WAIT_POLICY=passive`` for this process unless the user chose a policy.
    Returns whether it was set here (False: the user's setting stands)."""
    if any(name in os.environ for name in _USER_SETTINGS):
        return False
    os.environ["OMP_WAIT_POLICY"] = "passive"
    return True
