"""The process's heap policy for frame-sized arrays: give freed blocks back to the system.

glibc's malloc serves a block below its mmap threshold from a heap arena, and raises that
threshold (up to 32 MB, and the trim threshold to twice that) each time a larger block
mapped on its own is freed. After the first frame, every float32 plane of a 1080p frame
(8 MB) and its half-float copies (4 MB) are therefore carved from the arenas, of which each
I/O thread (and each of the OpenEXR library's threads) has its own. A plane freed by one
thread cannot serve another's next allocation, and a free block between live ones is never
returned, so the resident size grows with the frames run well beyond what is alive:
measured at 1080p, a bidirectional run's peak RSS 1.8-2.2 GB, and 1.50-1.53 GB with
this policy (docs/bidirectional.md#cost).

:func:`map_large_blocks` fixes the mmap threshold at 1 MiB (which also stops the
adjustment) and the trim threshold at glibc's default, and trims what the arenas hold
free. It must run before the first frame is read (the CLI calls it first thing; the runner
again, for other callers): blocks already in an arena stay there.

:func:`keep_freed_blocks` is the other policy, for ``svgf denoise --keep-memory``: blocks up
to glibc's largest threshold (32 MiB: every 1080p plane up to (4, H, W)) come from one arena
and stay there when freed, below a trim threshold of 1 GiB. On machines that hand free
memory back to their host (these VMs: docs/performance.md "fresh pages"), a plane written
into memory freed a frame before costs a tenth of one written into fresh pages: 0.7-0.8x
the time on 1080p production frames, for a peak 0.5-1.8 GB higher (docs/farm.md).
"""

from __future__ import annotations

import ctypes
import os

# mallopt's parameter numbers (glibc <malloc.h>).
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
_M_ARENA_MAX = -8
# Blocks at least this large are mapped on their own: a 540p float32 plane (2 MB) and up,
# never a Python object.
MMAP_THRESHOLD = 1 << 20
# glibc's own default: free memory above this at the top of a heap is given back.
TRIM_THRESHOLD = 128 << 10

# keep_freed_blocks: glibc's largest mmap threshold on 64-bit systems (HEAP_MAX_SIZE / 2),
# and free heap memory kept up to this much before it is given back.
KEEP_MMAP_THRESHOLD = 32 << 20
KEEP_TRIM_THRESHOLD = 1 << 30

_libc: ctypes.CDLL | None = None


def map_large_blocks() -> bool:
    """Make glibc map every block of ``MMAP_THRESHOLD`` or more on its own and give free
    heap memory back, and trim what the heap holds free (``MALLOC_MMAP_THRESHOLD_`` in the
    environment wins). Undoes :func:`keep_freed_blocks` but for its single arena (a later
    run in the same process, say a Dask worker's next chunk, gets this policy again).
    False where it does not apply (not glibc) or failed."""
    libc = _mallopt((_M_MMAP_THRESHOLD, MMAP_THRESHOLD), (_M_TRIM_THRESHOLD, TRIM_THRESHOLD))
    if libc is None:
        return False
    try:
        libc.malloc_trim(0)
    except AttributeError:
        return False
    return True


def keep_freed_blocks() -> bool:
    """Keep freed frame-sized blocks in the process for the next frame (module docstring):
    one arena, blocks up to ``KEEP_MMAP_THRESHOLD`` from it, free memory kept up to
    ``KEEP_TRIM_THRESHOLD`` (``MALLOC_MMAP_THRESHOLD_`` in the environment wins). False
    where it does not apply."""
    return _mallopt((_M_MMAP_THRESHOLD, KEEP_MMAP_THRESHOLD),
                    (_M_TRIM_THRESHOLD, KEEP_TRIM_THRESHOLD), (_M_ARENA_MAX, 1)) is not None


def _mallopt(*settings: tuple[int, int]) -> ctypes.CDLL | None:
    """The C library with each ``(parameter, value)`` set by ``mallopt``; None where the
    environment sets the policy, the library is not glibc, or a setting failed."""
    global _libc
    if "MALLOC_MMAP_THRESHOLD_" in os.environ or not _glibc():
        return None
    try:
        libc = _libc if _libc is not None else ctypes.CDLL(None)
        if not all(libc.mallopt(parameter, value) for parameter, value in settings):
            return None
    except (OSError, AttributeError):
        return None
    _libc = libc
    return libc


def _glibc() -> bool:
    try:
        return (os.confstr("CS_GNU_LIBC_VERSION") or "").startswith("glibc")
    except (ValueError, OSError, AttributeError):
        return False
