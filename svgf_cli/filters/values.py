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
  length) holds a non-finite value in any signal has its history reset (length 0, and a
  mode no pixel has, so the next frame does not resample it) and is counted. With the rules
  above this never fires; it keeps a future defect from poisoning every later frame.

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

# Top bit of a history mode mask (see ``modulate``): no usable history at that pixel. No
# current mask has it, so reprojection rejects such a tap for every signal.
NO_HISTORY = np.uint16(1 << 15)

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
def is_extreme(x: np.float32) -> bool:
    """Finite with ``|x| > VALUE_LIMIT``."""
    bits = magnitude_bits(x)
    return bits > LIMIT_BITS and bits < _INF_BITS


@njit(inline="always", **_JIT)
def is_usable(x: np.float32) -> bool:
    """Finite and ``|x| <= VALUE_LIMIT``."""
    return magnitude_bits(x) <= LIMIT_BITS


@njit(**_JIT)
def _largest_magnitude_bits(row: np.ndarray) -> np.int32:
    """The largest magnitude bits of a row (a max reduction on integers: it vectorizes)."""
    largest = np.int32(0)
    for x in range(row.shape[0]):
        largest = max(largest, magnitude_bits(row[x]))
    return largest


@njit(**_JIT)
def _count_row(row: np.ndarray) -> tuple[int, int]:
    """(non-finite, finite beyond the limit) values of one row: a vectorized max first, the
    value-by-value count only for a row that holds a bad value (the rare case)."""
    if _largest_magnitude_bits(row) <= LIMIT_BITS:
        return 0, 0
    nonfinite = 0
    extreme = 0
    for x in range(row.shape[0]):
        bits = magnitude_bits(row[x])
        if bits >= _INF_BITS:
            nonfinite += 1
        elif bits > LIMIT_BITS:
            extreme += 1
    return nonfinite, extreme


@njit(parallel=True, **_JIT)
def _count_geometry_rows(
    depth: np.ndarray, normal: np.ndarray, motion: np.ndarray, out: np.ndarray
) -> None:
    """Per row: (non-finite, beyond-limit) counts of depth, normal and motion (6 columns),
    in one parallel region (on a busy machine every region costs a thread rendezvous)."""
    height = depth.shape[0]
    for y in prange(height):
        out[y, 0], out[y, 1] = _count_row(depth[y])
        out[y, 2] = 0
        out[y, 3] = 0
        for c in range(3):
            nonfinite, extreme = _count_row(normal[c, y])
            out[y, 2] += nonfinite
            out[y, 3] += extreme
        out[y, 4] = 0
        out[y, 5] = 0
        for c in range(2):
            nonfinite, extreme = _count_row(motion[c, y])
            out[y, 4] += nonfinite
            out[y, 5] += extreme


def count_geometry(
    depth: np.ndarray, normal: np.ndarray, motion: np.ndarray
) -> dict[str, tuple[int, int]]:
    """``{"depth" | "normal" | "motion": (non-finite, finite beyond VALUE_LIMIT)}`` value
    counts of the frame's geometry planes."""
    counts = np.zeros((depth.shape[0], 6), dtype=np.int64)
    _count_geometry_rows(depth, normal, motion, counts)
    total = counts.sum(axis=0)
    return {name: (int(total[2 * i]), int(total[2 * i + 1]))
            for i, name in enumerate(("depth", "normal", "motion"))}


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
    illumination: np.ndarray,
    moments: np.ndarray,
    history_length: np.ndarray,
    mode: np.ndarray,
    out: np.ndarray,
) -> None:
    """Per row: reset the history (every signal) of pixels holding a non-finite value."""
    num_signals, height, width = history_length.shape
    for y in prange(height):
        resets = 0
        for x in range(width):
            bad = False
            for s in range(num_signals):
                bad = bad or (
                    is_nonfinite(illumination[s, 0, y, x]) or is_nonfinite(illumination[s, 1, y, x])
                    or is_nonfinite(illumination[s, 2, y, x]) or is_nonfinite(moments[s, 0, y, x])
                    or is_nonfinite(moments[s, 1, y, x]) or is_nonfinite(history_length[s, y, x])
                )
            if bad:
                resets += 1
                for s in range(num_signals):
                    for c in range(3):
                        illumination[s, c, y, x] = F32(0.0)
                    moments[s, 0, y, x] = F32(0.0)
                    moments[s, 1, y, x] = F32(0.0)
                    history_length[s, y, x] = F32(0.0)
                mode[y, x] = NO_HISTORY
        out[y] = resets


@njit(parallel=True, **_JIT)
def _nonfinite_history_rows(
    illumination: np.ndarray, moments: np.ndarray, history_length: np.ndarray, out: np.ndarray
) -> None:
    """Per row: 1 if any signal's history holds a non-finite value there (read only)."""
    num_signals, height, _ = history_length.shape
    for y in prange(height):
        largest = np.int32(0)
        for s in range(num_signals):
            for c in range(3):
                largest = max(largest, _largest_magnitude_bits(illumination[s, c, y]))
            for c in range(2):
                largest = max(largest, _largest_magnitude_bits(moments[s, c, y]))
            largest = max(largest, _largest_magnitude_bits(history_length[s, y]))
        out[y] = largest >= _INF_BITS


def reset_nonfinite_history(
    illumination: np.ndarray, moments: np.ndarray, history_length: np.ndarray, mode: np.ndarray
) -> int:
    """In place: reset the history of pixels where any signal's history holds a non-finite
    value; return how many pixels were reset. ``illumination`` (S, 3, H, W), ``moments``
    (S, 2, H, W), ``history_length`` (S, H, W) and the (H, W) ``mode`` mask, all
    C-contiguous. A reset pixel gets history length 0, zero values and the mode
    :data:`NO_HISTORY`, so the next frame's reprojection does not resample it at all.

    A read-only scan first (the common, clean case); the reset pass only when needed.
    """
    rows = np.zeros(history_length.shape[1], dtype=np.int64)
    _nonfinite_history_rows(illumination, moments, history_length, rows)
    if not rows.any():
        return 0
    _reset_rows(illumination, moments, history_length, mode, rows)
    return int(rows.sum())
