"""The colour history's blend (filters/feedback.py) against a float64 reference."""

from __future__ import annotations

import numpy as np
import pytest

from svgf_cli.filters.feedback import blend_history
from svgf_cli.filters.invert_motion import NO_MOTION

F32 = np.float32
LIMIT = 1e-3


def reference(unfiltered: np.ndarray, filtered: np.ndarray, motion: np.ndarray,
              still_share: float, moving_share: float) -> np.ndarray:
    """``H = w F + (1 - w) U``, ``w`` the still share where |motion| < LIMIT on both axes,
    else the moving share."""
    m = motion.astype(np.float64)
    still = (np.abs(m[0]) < F32(LIMIT)) & (np.abs(m[1]) < F32(LIMIT))
    w = np.where(still, still_share, moving_share)
    return w * filtered.astype(np.float64) + (1.0 - w) * unfiltered.astype(np.float64)


def case(seed: int, height: int = 13, width: int = 37) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    unfiltered = rng.uniform(0.0, 4.0, (2, 3, height, width)).astype(F32)
    filtered = rng.uniform(0.0, 4.0, (2, 3, height, width)).astype(F32)
    motion = rng.choice([0.0, 5e-4, -2e-3, 0.37, -1.5, NO_MOTION],
                        (2, height, width)).astype(F32)
    motion[:, 4] = 0.8  # a row where every pixel moves
    motion[:, 7] = 0.0  # a row where none does
    return unfiltered, filtered, motion


# (still, moving): a causal run's default and a share; a bidirectional pass's (0.3, 0).
@pytest.mark.parametrize("shares", [(1.0, 0.0), (1.0, 0.3), (1.0, 1.0), (0.3, 0.0)])
def test_matches_the_float64_reference(shares: tuple[float, float]) -> None:
    unfiltered, filtered, motion = case(3)
    want = reference(unfiltered, filtered, motion, *shares)
    got = unfiltered.copy()
    blend_history(got, filtered, motion, F32(LIMIT), F32(shares[0]), F32(shares[1]))
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(filtered, case(3)[1])  # the feedback output is not touched


def test_weights_of_one_and_zero_are_exact() -> None:
    """Still pixels get F bit for bit, moving ones U bit for bit (share 0): the history is
    the paper's where nothing moves and the accumulation where everything does."""
    unfiltered, filtered, motion = case(5)
    still = (np.abs(motion[0]) < LIMIT) & (np.abs(motion[1]) < LIMIT)
    assert still.any() and (~still).any()
    got = unfiltered.copy()
    blend_history(got, filtered, motion, F32(LIMIT), F32(1.0), F32(0.0))
    np.testing.assert_array_equal(got[:, :, still], filtered[:, :, still])
    np.testing.assert_array_equal(got[:, :, ~still], unfiltered[:, :, ~still])
    np.testing.assert_array_equal(got[:, :, 4], unfiltered[:, :, 4])
    np.testing.assert_array_equal(got[:, :, 7], filtered[:, :, 7])
