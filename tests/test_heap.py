"""The process's heap policies (``svgf_cli.heap``): freed frame-sized blocks given back to
the system by default, kept with ``--keep-memory``. Each runs in a child process, whose
heap settings are its own."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

# A child that applies one policy, then frees a 16 MiB array and prints whether its resident
# size fell by most of it.
_CHILD = """
import sys
import numpy as np
from svgf_cli.heap import keep_freed_blocks, map_large_blocks

def resident() -> int:
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * 4096

applied = map_large_blocks()
if sys.argv[1].startswith("keep"):
    applied = keep_freed_blocks()
if sys.argv[1] == "keep-then-map":  # a Dask worker's next chunk without the option
    applied = map_large_blocks()
block = np.ones(16 << 20, dtype=np.uint8)
before = resident()
del block
print(applied, before - resident() > 12 << 20)
"""


def _child(policy: str, **env: str) -> tuple[str, str]:
    result = subprocess.run([sys.executable, "-c", _CHILD, policy], capture_output=True,
                            text=True, check=True, env={**os.environ, **env})
    applied, given_back = result.stdout.split()
    return applied, given_back


@pytest.mark.skipif(not sys.platform.startswith("linux")
                    or not (os.confstr("CS_GNU_LIBC_VERSION") or "").startswith("glibc"),
                    reason="glibc's malloc only")
def test_freed_blocks_go_back_by_default_and_stay_with_keep_memory() -> None:
    assert _child("map") == ("True", "True")
    assert _child("keep") == ("True", "False")
    assert _child("keep-then-map") == ("True", "True")
    # The environment's setting wins over either policy.
    env = {"MALLOC_MMAP_THRESHOLD_": str(1 << 20)}
    assert _child("keep", **env) == ("False", "True")
