"""io.halfconv: float32 <-> half conversion bit for bit as NumPy's astype, without its slow
subnormal path (exhaustive over every half; over every float32 near each half's rounding
boundaries, and random bit patterns)."""

from __future__ import annotations

import numpy as np
import pytest

from svgf_cli.halfconv import gather_float32, storable, to_float32, to_half, zero_nonfinite

F32 = np.float32


def _every_half() -> np.ndarray:
    return np.arange(65536, dtype=np.uint32).astype(np.uint16).view(np.float16)


def test_every_half_to_float32_as_numpy() -> None:
    halves = _every_half()
    want = halves.astype(F32).view(np.uint32)
    assert np.array_equal(to_float32(halves).view(np.uint32), want)


def test_float32_to_half_as_numpy_at_every_rounding_boundary() -> None:
    # Each half's float32 value, the midpoints to its neighbours and one float32 ulp on each
    # side of them: every tie, every carry into the exponent, overflow, underflow, NaN.
    centres = _every_half().astype(F32).view(np.uint32).astype(np.int64)
    finite = centres[(centres & 0x7F800000) != 0x7F800000]
    mids = np.concatenate([(finite[:-1] + finite[1:]) // 2, finite])
    near = (mids[:, None] + np.arange(-2, 3)[None]).ravel() & 0xFFFFFFFF
    extra = np.array([0x477FEFFF, 0x477FF000, 0x477FF001, 0x7F800000, 0x7F800001, 0x7FC00000,
                      0x7F802000, 0x00000001, 0x00800000, 0x33000000, 0x33000001, 0x387FFFFF,
                      0x38800000], dtype=np.int64)
    bits = np.concatenate([near, extra, extra | 0x80000000]).astype(np.uint32)
    rng = np.random.default_rng(3)
    bits = np.concatenate([bits, rng.integers(0, 2**32, 2_000_000, dtype=np.uint64)
                           .astype(np.uint32)])
    values = bits.view(F32)
    with np.errstate(all="ignore"):
        want = values.astype(np.float16).view(np.uint16)
    got = to_half(values).view(np.uint16)
    assert np.array_equal(got, want), np.flatnonzero(got != want)[:5]


def test_conversions_keep_shape_and_take_out() -> None:
    values = (np.arange(24, dtype=F32).reshape(2, 3, 4) - 5) * F32(1e-6)
    halves = to_half(values)
    assert halves.shape == (2, 3, 4) and halves.dtype == np.float16
    out = np.empty((2, 3, 4), dtype=F32)
    assert to_float32(halves, out=out) is out
    assert np.array_equal(out, halves.astype(F32))
    with pytest.raises(ValueError):
        to_float32(halves, out=np.empty((2, 3, 5), dtype=F32))


def test_storable_fixes_and_counts_like_numpy() -> None:
    values = np.array([[1.0, np.nan, -np.inf, 7e4], [-7e4, 3e-7, -0.0, 65519.0]], dtype=F32)
    half, nonfinite, clamped = storable(values, half=True)
    want = np.clip(np.where(np.isfinite(values), values, 0.0), -65504, 65504).astype(np.float16)
    assert np.array_equal(half.view(np.uint16), want.view(np.uint16))
    assert (nonfinite, clamped) == (2, 3)  # 65519 rounds to 65504 but is beyond it
    full, nonfinite, clamped = storable(values, half=False)
    assert full.dtype == F32 and (nonfinite, clamped) == (2, 0)
    assert np.array_equal(full, np.where(np.isfinite(values), values, 0.0))
    assert np.isnan(values[0, 1])  # the input is left as it was


def test_zero_nonfinite_and_gather() -> None:
    plane = np.array([[1.0, np.nan], [np.inf, -2.0]], dtype=F32)
    assert zero_nonfinite(plane) == 2
    assert np.array_equal(plane, [[1.0, 0.0], [0.0, -2.0]])
    with pytest.raises(ValueError):
        zero_nonfinite(plane.T)
    half = np.array([[1e-6, 2.0]], dtype=np.float16)
    stacked = gather_float32([half, np.array([[3.0, 4.0]], dtype=F32)])
    assert stacked.shape == (2, 1, 2) and stacked.dtype == F32
    assert np.array_equal(stacked[0], half.astype(F32)) and np.array_equal(stacked[1], [[3, 4]])
