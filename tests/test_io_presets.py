"""What each AOV preset implies, end to end through real EXR files: the motion convention
and the role listing.

For every preset a two-frame sequence is written with that renderer's own channel names and
the motion its documented convention stores for a scene that moves (+2, +1) px per frame
(right and down on screen); read back with the preset, frame t's canonical backward motion
must land every pixel on the same surface point of frame t-1 (checked through the albedo
texture, exactly, since the shift is whole pixels).

The conventions pinned here are the project's documented reading of each renderer (README
"Motion vectors"; Arnold and Karma are marked [verify] there): ``svgf`` backward pixels;
Cycles ``Vector.XY`` = previous - current with +Y up; Arnold and Karma ``motionvector`` =
current - previous (towards this frame). Change them together with the README.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from svgf_cli.io.exr import read_frame, write_exr
from svgf_cli.io.layers import AOV_PRESETS, ROLES, build_mapping

WIDTH, HEIGHT = 16, 10
VELOCITY = (2, 1)  # screen pixels per frame, x right, y down

# What each renderer's motion layer holds for that velocity (previous - current = (-2, -1)).
STORED_MOTION = {
    "svgf": (-2.0, -1.0),  # backward, pixels, y down
    "cycles": (-2.0, 1.0),  # previous - current, +Y up
    "arnold": (2.0, 1.0),  # current - previous, y down
    "karma": (2.0, 1.0),
}


def _albedo(frame: int) -> np.ndarray:
    """A texture fixed to the moving scene: pixel (x, y) of frame f shows scene point
    (x - 2f, y - f)."""
    ys, xs = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float64)
    u, v = xs - VELOCITY[0] * frame, ys - VELOCITY[1] * frame
    return np.stack([0.5 + 0.4 * np.sin(0.9 * u + 0.3 * v), 0.5 + 0.4 * np.cos(0.7 * v),
                     0.5 + 0.4 * np.sin(0.4 * u - 0.8 * v)]).astype(np.float32)


def _write(path: Path, preset: str, frame: int) -> None:
    table = AOV_PRESETS[preset]
    planes = {
        "color": _albedo(frame),
        "albedo": _albedo(frame),
        "normal": np.stack([np.zeros((HEIGHT, WIDTH)), np.zeros((HEIGHT, WIDTH)),
                            np.ones((HEIGHT, WIDTH))]),
        "depth": np.full((1, HEIGHT, WIDTH), 4.0),
        "motion": np.stack([np.full((HEIGHT, WIDTH), m) for m in STORED_MOTION[preset]]),
    }
    channels: dict[str, np.ndarray] = {}
    for role, plane in planes.items():
        for name, channel in zip(table[role][0], plane, strict=True):
            channels[name] = np.asarray(channel, dtype=np.float32)
    if preset == "cycles":  # Cycles' Vector pass has four channels; ZW point to the next frame
        channels["Vector.Z"] = np.full((HEIGHT, WIDTH), 7.0, np.float32)
        channels["Vector.W"] = np.full((HEIGHT, WIDTH), -7.0, np.float32)
    write_exr(path, channels)


@pytest.mark.parametrize("preset", list(AOV_PRESETS))
def test_preset_motion_convention_reprojects_onto_the_previous_frame(
    preset: str, tmp_path: Path
) -> None:
    mapping = build_mapping(preset)
    for f in (1, 2):
        _write(tmp_path / f"in.{f}.exr", preset, f)
    previous = read_frame(tmp_path / "in.1.exr", mapping).frame
    current = read_frame(tmp_path / "in.2.exr", mapping).frame
    np.testing.assert_array_equal(current.motion[0], -VELOCITY[0])
    np.testing.assert_array_equal(current.motion[1], -VELOCITY[1])
    # Backward motion: the surface at (x, y) was at (x + mx, y + my) in the previous frame.
    ys, xs = np.mgrid[0:HEIGHT, 0:WIDTH]
    px = xs + current.motion[0].astype(int)
    py = ys + current.motion[1].astype(int)
    inside = (px >= 0) & (px < WIDTH) & (py >= 0) & (py < HEIGHT)
    assert inside.sum() > 100
    np.testing.assert_array_equal(previous.albedo[:, py[inside], px[inside]],
                                  current.albedo[:, inside])


def test_describe_lists_each_roles_candidates_and_overrides() -> None:
    """The role listing printed at start-up: every role with the preset's candidates in
    order, ``(none)`` for a role switched off, ``(--aov)`` on an override."""
    for preset, table in AOV_PRESETS.items():
        mapping = build_mapping(preset)
        lines = mapping.describe().splitlines()
        assert lines[0] == f"preset {preset}, motion convention {mapping.motion_convention}"
        assert len(lines) == 1 + len(ROLES)
        for role, line in zip(ROLES, lines[1:], strict=True):
            label, _, listed = line.partition(": ")
            assert label.strip() == role
            expected = " | ".join(",".join(c) for c in table[role]) or "(none)"
            assert listed == expected, (preset, role)
    overridden = [line.strip() for line in
                  build_mapping("svgf", ["emission=none", "depth=Pz"]).describe().splitlines()]
    assert "emission: (none) (--aov)" in overridden
    assert "depth: Pz | Pz.Z | Pz.Y | Pz.R | Pz.X (--aov)" in overridden
