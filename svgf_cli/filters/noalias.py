"""``noalias_njit``: numba's ``njit`` plus LLVM ``noalias`` on every array argument.

A register-blocked kernel reads ~30 row planes and writes ~10 accumulator rows in one loop.
LLVM vectorizes such a loop only after proving, at run time, that no written row overlaps a
read one; with this many arrays it needs hundreds of overlap checks, exceeds its budget and
leaves the loop scalar (remark "too many memory checks needed"). C would say ``restrict``.
numba has the flag (``Flags.noalias``, which it sets on its own parfor kernels when it finds
no aliases) but no decorator option, so this sets it through the dispatcher's documented
per-dispatcher hook ``_customize_flags``.

The promise is the caller's to keep: no array written by such a function may share memory
with any other array argument. :func:`check_disjoint` verifies it before each call.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numba import njit
from numba.core.compiler import Flags


def noalias_njit(**options: Any) -> Callable[[Callable[..., Any]], Any]:
    """``njit(**options)`` whose compiled code marks all pointer arguments ``noalias``."""

    def decorate(function: Callable[..., Any]) -> Any:
        dispatcher = njit(**options)(function)

        def customize_flags(flags: Flags) -> Flags:
            flags.noalias = True
            return flags

        dispatcher._compiler._customize_flags = customize_flags
        return dispatcher

    return decorate


def check_disjoint(written: dict[str, np.ndarray], read: dict[str, np.ndarray]) -> None:
    """Raise ValueError if a written array shares memory with any other argument."""
    names = list(written) + list(read)
    arrays = list(written.values()) + list(read.values())
    for i, name in enumerate(written):
        for j, other in enumerate(arrays):
            if i != j and np.may_share_memory(arrays[i], other):
                raise ValueError(f"{name} overlaps {names[j]}: outputs must not alias inputs")
