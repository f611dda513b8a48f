"""Motion to the next frame: the reader's ``motion_next`` role (our tracer's
``motion_next.X/Y``, Cycles' ``Vector.Z/W``) against the motion derived by inverting the
next frame's backward motion (``filters.invert_motion``), on committed renders where both
exist. Agreement says the two sources and the Cycles convention are consistent."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from svgf_cli.filters.invert_motion import NO_MOTION, invert_motion
from svgf_cli.io.exr import read_frame
from svgf_cli.io.layers import build_mapping, to_next_pixels

TESTDATA = Path(__file__).resolve().parent.parent / "testdata"


@pytest.mark.parametrize(("preset", "sequence", "frame"), [
    ("svgf", "lag/camera", 8),  # camera motion
    ("svgf", "lag/shadow", 3),  # a rolling sphere over a static scene
    ("cycles", "cycles/roll", 5),  # Blender: camera dolly and a rolling ball
])
def test_derived_motion_matches_the_written_one(preset: str, sequence: str, frame: int) -> None:
    mapping = build_mapping(preset)
    now = read_frame(TESTDATA / sequence / f"in.{frame:04d}.exr", mapping).frame
    later = read_frame(TESTDATA / sequence / f"in.{frame + 1:04d}.exr", mapping).frame
    assert now.motion_next is not None
    derived = np.zeros_like(now.motion)
    invert_motion(later.motion, later.depth, derived)
    surface = now.depth > 0
    landed = surface & (derived[0] != NO_MOTION)
    assert landed.sum() > 0.9 * surface.sum()
    error = np.hypot(*(derived - now.motion_next))[landed]
    moving = np.hypot(*now.motion_next)[surface]
    assert moving.max() > 0.3  # something moves by a visible amount
    # Measured: median 0.00-0.02 px, 95th percentile 0.00-0.17 px (silhouettes, where the
    # written motion follows points the next frame no longer shows, make the tail).
    assert np.median(error) < 0.05 and np.percentile(error, 95) < 0.25


def test_cycles_vector_zw_is_current_minus_next_with_y_up() -> None:
    zw = np.array([[[1.5]], [[-0.25]]], dtype=np.float32)
    np.testing.assert_array_equal(to_next_pixels(zw, "cycles")[:, 0, 0], [-1.5, -0.25])
    np.testing.assert_array_equal(to_next_pixels(zw, "backward-pixels"), zw)
    with pytest.raises(ValueError, match="convention"):
        to_next_pixels(zw, "sideways")
