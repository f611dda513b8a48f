"""Value policy of the filter: what non-finite and extreme inputs become, and a history guard.

Every kernel compiles with the fast-math flags ``nnan``/``ninf`` (``fastmath.FASTMATH``),
which let LLVM assume that no float is NaN or Inf; a non-finite input would make their
results undefined (and a NaN in the history spreads to the whole frame within a few
frames). So no such value may reach them, and no arithmetic may create one:

* **Non-finite inputs** are replaced and counted: radiance, emission and albedo values by 0,
  a normal with a non-finite component by the zero normal (no spatial weight), a non-finite
  depth by background (0), non-finite motion by "no history" (a far-away position).
* **Extreme finite inputs**: radiance, emission and normal components of magnitude above
  :data:`VALUE_LIMIT` (1e15) are replaced by 0 (the normal by the zero normal) and counted,
  a depth above it is background. No renderer's radiance unit comes near 1e15 (the sun's
  disc is ~1.6e9 cd/m^2); such a value is a numerical blow-up like an Inf, and keeping it,
  even clamped, would leave a 1e15 firefly in the history for hundreds of frames.
* **Demodulated illumination** (radiance over a small albedo) is clamped to
  ``+-VALUE_LIMIT`` (counted). With every filtered value within 1e15, the largest
  intermediate (luminance squared in the moments, summed over a 7x7 window, divided by the
  Bessel correction, boosted by ``threshold / h``, summed with squared weights in the
  a-trous) stays below ~1e34, far from float32's 3.4e38.
* **History guard**: after a frame, a pixel whose history (illumination, moments, history
  length) holds a non-finite value in any signal has that signal's history reset (length 0)
  and is counted. With the rules above this never fires; it keeps a future defect from
  poisoning every later frame.

Finiteness is tested on the IEEE-754 bits (an integer compare of the magnitude bits), which
no fast-math flag can optimise away, and one compare tests "finite and within the limit".
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from svgf_cli.filters.fastmath import FASTMATH, float32_bits

F32 = np.float32
VALUE_LIMIT = F32(1e15)
# Magnitude bits: at least _INF_BITS is Inf or NaN; above LIMIT_BITS is beyond VALUE_LIMIT.
_MAGNITUDE_MASK = np.int32(0x7FFFFFFF)
_INF_BITS = np.int32(0x7F800000)
LIMIT_BITS = np.int32(VALUE_LIMIT.view(np.int32))

_JIT = dict(fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy")


@njit(inline="always", **_JIT)
def magnitude_bits(x: np.float32) -> np.int32:
    """The bits of ``|x|`` as an int32: ordered like ``|x|``, NaN and Inf on top."""
    return float32_bits(x) & _MAGNITUDE_MASK


@njit(inline="always", **_JIT)
def is_nonfinite(x: np.float32) -> bool:
    """NaN or +-Inf (a bit test that fast-math cannot remove)."""
    return magnitude_bits(x) >= _INF_BITS


@njit(inline="always", **_JIT)
def is_usable(x: np.float32) -> bool:
    """Finite and ``|x| <= VALUE_LIMIT``."""
    return magnitude_bits(x) <= LIMIT_BITS


@njit(parallel=True, **_JIT)
def _count_rows(planes: np.ndarray, out: np.ndarray) -> None:
    """Per row of (C, H, W) ``planes``: non-finite values, finite values beyond the limit."""
    channels, height, width = planes.shape
    for y in prange(height):
        nonfinite = 0
        extreme = 0
        for c in range(channels):
            row = planes[c, y]
            for x in range(width):
                bits = magnitude_bits(row[x])
                nonfinite += bits >= _INF_BITS
                extreme += (bits > LIMIT_BITS) & (bits < _INF_BITS)
        out[y, 0] = nonfinite
        out[y, 1] = extreme


def count_invalid(plane: np.ndarray) -> tuple[int, int]:
    """``(non-finite, finite beyond VALUE_LIMIT)`` value counts of a float32 plane stack."""
    planes = plane if plane.ndim == 3 else plane.reshape(1, *plane.shape)
    counts = np.zeros((planes.shape[1], 2), dtype=np.int64)
    _count_rows(planes, counts)
    total = counts.sum(axis=0)
    return int(total[0]), int(total[1])


def cleaned_depth(depth: np.ndarray) -> np.ndarray:
    """A copy of ``depth`` with non-finite and beyond-limit values made background (0)."""
    with np.errstate(invalid="ignore"):
        bad = ~(np.abs(depth) <= VALUE_LIMIT)
    return np.where(bad, F32(0.0), depth).astype(F32)


def cleaned_normal(normal: np.ndarray) -> np.ndarray:
    """A copy of (3, H, W) ``normal`` with the zero normal wherever a component is
    non-finite or beyond the limit."""
    with np.errstate(invalid="ignore"):
        bad = ~np.all(np.abs(normal) <= VALUE_LIMIT, axis=0)
    return np.where(bad[None], F32(0.0), normal).astype(F32)


def cleaned_motion(motion: np.ndarray) -> np.ndarray:
    """A copy of (2, H, W) ``motion`` with non-finite vectors pointing far outside the image
    (so the pixel has no history)."""
    bad = ~np.all(np.isfinite(motion), axis=0)
    return np.where(bad[None], VALUE_LIMIT, motion).astype(F32)


@njit(parallel=True, **_JIT)
def _reset_rows(
    illumination: np.ndarray, moments: np.ndarray, history_length: np.ndarray, out: np.ndarray
) -> None:
    """Per row: reset (zero) every signal's history at pixels holding a non-finite value."""
    num_signals, height, width = history_length.shape
    for y in prange(height):
        resets = 0
        for s in range(num_signals):
            for x in range(width):
                bad = (
                    is_nonfinite(illumination[s, 0, y, x]) or is_nonfinite(illumination[s, 1, y, x])
                    or is_nonfinite(illumination[s, 2, y, x]) or is_nonfinite(moments[s, 0, y, x])
                    or is_nonfinite(moments[s, 1, y, x]) or is_nonfinite(history_length[s, y, x])
                )
                if bad:
                    resets += 1
                    for c in range(3):
                        illumination[s, c, y, x] = F32(0.0)
                    moments[s, 0, y, x] = F32(0.0)
                    moments[s, 1, y, x] = F32(0.0)
                    history_length[s, y, x] = F32(0.0)
        out[y] = resets


@njit(parallel=True, **_JIT)
def _any_nonfinite_rows(planes: np.ndarray, out: np.ndarray) -> None:
    """Per row of (N, H, W) ``planes``: the number of non-finite values (read only)."""
    count, height, width = planes.shape
    for y in prange(height):
        bad = 0
        for n in range(count):
            row = planes[n, y]
            for x in range(width):
                bad += magnitude_bits(row[x]) >= _INF_BITS
        out[y] = bad


def reset_nonfinite_history(
    illumination: np.ndarray, moments: np.ndarray, history_length: np.ndarray
) -> int:
    """In place: reset each signal's history where it holds a non-finite value; return how
    many (signal, pixel) histories were reset. ``illumination`` (S, 3, H, W), ``moments``
    (S, 2, H, W), ``history_length`` (S, H, W), all C-contiguous.

    A read-only scan first (the common, clean case); the reset pass only when needed.
    """
    s, _, h, w = illumination.shape
    rows = np.zeros(h, dtype=np.int64)
    found = 0
    for stack in (illumination.reshape(s * 3, h, w), moments.reshape(s * 2, h, w),
                  history_length):
        _any_nonfinite_rows(stack, rows)
        found += int(rows.sum())
    if found == 0:
        return 0
    _reset_rows(illumination, moments, history_length, rows)
    return int(rows.sum())
