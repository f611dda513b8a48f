"""Guard for bit-identical outputs across numba builds (see svgf_cli.filters.fastmath.FASTMATH).

With numba's ``fastmath=True`` a process that JIT-compiled the kernels gave outputs 1 ulp away
from a process that loaded the same kernels from numba's cache (measured: thousands of pixels
per frame from frame 3 on). Every kernel must use the restricted flag set instead.
"""

from __future__ import annotations

import importlib
import pkgutil

from numba.core.registry import CPUDispatcher

import svgf_cli.filters
from svgf_cli.filters.fastmath import FASTMATH


def _kernels() -> list[tuple[str, CPUDispatcher]]:
    found = []
    for module_info in pkgutil.iter_modules(svgf_cli.filters.__path__):
        module = importlib.import_module(f"svgf_cli.filters.{module_info.name}")
        for name, value in vars(module).items():
            if isinstance(value, CPUDispatcher) and value.__module__ == module.__name__:
                found.append((f"{module.__name__}.{name}", value))
    return found


def test_every_kernel_uses_the_deterministic_fastmath_flags() -> None:
    kernels = _kernels()
    assert len(kernels) >= 15, "expected the filter kernels to be found"
    assert not {"arcp", "reassoc", "contract", "afn", "fast"} & set(FASTMATH)
    wrong = [name for name, k in kernels if k.targetoptions.get("fastmath") != FASTMATH]
    assert not wrong, f"kernels not compiled with FASTMATH: {wrong}"
