"""Turning objects: the light's history fetched at the object's translation
(``filters.object_motion``, ``filters.stages.object_history``)."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic import make_frame, true_radiance

from svgf_cli.filters import object_motion
from svgf_cli.filters.denoiser import Denoiser
from svgf_cli.filters.object_motion import refine_translation, turning_pixels
from svgf_cli.filters.params import PRESETS
from svgf_cli.filters.pipeline import stage_names

F32 = np.float32
WIDTH, HEIGHT, RADIUS = 72, 40, 11.0
LIGHT = np.array([-0.5, -0.6, 0.62]) / np.linalg.norm([-0.5, -0.6, 0.62])


def _ball(t: int, *, step: float = 4.0, turn: float = 0.35, bias: float = 0.0):
    """A ball rolling to the right over a flat floor, seen along its axis (orthographic):
    centre ``(14 + step t, 20)``, turned by ``turn`` radians per frame. Returns the normal,
    depth, mesh id, backward motion (the material point's: the turn about the centre plus
    the step) and the noise-free light ``0.05 + 2 max(0, n . L)^2`` (a function of the
    normal, as direct light from a far light is)."""
    y, x = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float64) + 0.5
    cx, cy = 14.0 + step * t, 20.0
    dx, dy = x - cx, y - cy
    inside = dx * dx + dy * dy < RADIUS * RADIUS
    dz = np.sqrt(np.maximum(RADIUS * RADIUS - dx * dx - dy * dy, 0.0))
    normal = np.zeros((3, HEIGHT, WIDTH))
    normal[2] = 1.0
    normal[:, inside] = np.stack([dx, dy, dz])[:, inside] / RADIUS
    depth = np.where(inside, 20.0 - dz, 20.0)
    mesh = np.where(inside, 2, 1).astype(np.int32)
    # Last frame the point at offset d from the centre sat at rot(-turn) d from the centre
    # then, one step to the left.
    c, s = np.cos(-turn), np.sin(-turn)
    px = cx - step + c * dx - s * dy
    py = cy + s * dx + c * dy
    motion = np.zeros((2, HEIGHT, WIDTH))
    motion[0] = np.where(inside, px - x + bias, 0.0)
    motion[1] = np.where(inside, py - y, 0.0)
    light = 0.05 + 2.0 * np.maximum(np.einsum("chw,c->hw", normal, LIGHT), 0.0) ** 2
    light = np.where(inside, light, 0.6)
    return (normal.astype(F32), depth.astype(F32), mesh, motion.astype(F32),
            light.astype(F32), inside)


def test_turn_evidence_matches_a_float64_reference() -> None:
    """Per pixel, from a plain loop: 0 off ``where``/background/off the image/another
    object at the nearest tap, 1 on the same object, 2 when the normals differ by more than
    the threshold; NaN motion is no tap."""
    rng = np.random.default_rng(5)
    height, width = 13, 17
    mesh = rng.integers(-1, 3, (height, width)).astype(np.int32)
    prev_mesh = np.where(rng.random((height, width)) < 0.8, mesh, 2).astype(np.int32)
    normal = rng.normal(size=(3, height, width)).astype(F32)
    prev_normal = (normal + rng.normal(0.0, 0.08, normal.shape)).astype(F32)
    motion = rng.uniform(-3.0, 3.0, (2, height, width)).astype(F32)
    motion[:, 4, 5] = np.nan
    where = rng.random((height, width)) < 0.9
    out = np.empty((height, width), np.uint8)
    object_motion.turn_evidence(motion, normal, mesh, prev_normal, prev_mesh,
                                where.view(np.uint8), F32(0.01), out)
    for y in range(height):
        for x in range(width):
            want = 0
            px = np.floor(np.float64(x) + np.float64(motion[0, y, x]) + 0.5)
            py = np.floor(np.float64(y) + np.float64(motion[1, y, x]) + 0.5)
            if (where[y, x] and mesh[y, x] >= 0 and 0 <= px < width and 0 <= py < height
                    and prev_mesh[int(py), int(px)] == mesh[y, x]):
                d = normal[:, y, x].astype(np.float64) - prev_normal[:, int(py), int(px)]
                want = 2 if float(d @ d) > 0.01 else 1
            assert out[y, x] == want, (y, x)
    assert {0, 1, 2} <= set(np.unique(out).tolist())


def test_a_rolling_ball_turns_and_its_translation_is_found() -> None:
    """Every ball pixel whose material point was on the ball turns, with the ball's step as
    its translation; the floor does not."""
    normal0, _, mesh0, _, _, _ = _ball(0)
    normal1, _, mesh1, motion1, _, inside = _ball(1)
    translation = turning_pixels(motion1, normal1, mesh1, normal0, mesh0, np.ones_like(inside))
    turning = np.isfinite(translation[0])
    assert not np.any(turning & ~inside)
    assert np.count_nonzero(turning) > 0.8 * np.count_nonzero(inside)
    assert np.allclose(translation[0, turning], -4.0, atol=0.3)
    assert np.allclose(translation[1, turning], 0.0, atol=0.3)


def test_the_translation_search_corrects_a_biased_mean() -> None:
    """A mean motion off by 1.6 pixels (an occluded or obliquely seen object) is found
    again to a fraction of a pixel by matching normals."""
    normal0, _, mesh0, _, _, _ = _ball(0)
    normal1, _, _, _, _, inside = _ball(1)
    ys, xs = np.nonzero(inside)
    tx, ty = refine_translation(xs, ys, (-4.0 + 1.6, 0.9), normal1, normal0, mesh0, 2)
    assert tx == pytest.approx(-4.0, abs=0.3) and ty == pytest.approx(0.0, abs=0.3)


@pytest.mark.parametrize("kind", ["translating", "still", "turning_box", "flat_parallax"])
def test_what_does_not_turn_about_its_axis_is_left_alone(kind: str) -> None:
    """A ball that only translates or stands still, a box face that turns (its normal at
    the translated position is as far off as at the material point) and a flat floor whose
    motion varies (parallax) have no turning pixels."""
    if kind in ("translating", "still"):
        step = 4.0 if kind == "translating" else 0.0
        normal0, _, mesh0, _, _, _ = _ball(0, step=step, turn=0.0)
        normal1, _, mesh1, motion1, _, _ = _ball(1, step=step, turn=0.0)
    elif kind == "turning_box":
        # One face, its normal turning by 0.35 rad a frame, the motion a turn in the image.
        normal0, _, mesh0, _, _, inside = _ball(0)
        normal1, _, mesh1, motion1, _, _ = _ball(1)
        for normal, angle in ((normal0, 0.0), (normal1, 0.35)):
            face = np.array([np.sin(angle), 0.0, np.cos(angle)], F32)
            normal[:, inside] = face[:, None]
        mesh0, mesh1 = mesh0.copy(), mesh1.copy()
    else:
        normal0 = np.zeros((3, HEIGHT, WIDTH), F32)
        normal0[1] = 1.0
        normal1, mesh0, mesh1 = normal0.copy(), np.ones((HEIGHT, WIDTH), np.int32), None
        mesh1 = mesh0.copy()
        motion1 = np.zeros((2, HEIGHT, WIDTH), F32)
        motion1[0] = np.linspace(-3.0, 3.0, HEIGHT, dtype=F32)[:, None]
    translation = turning_pixels(motion1, normal1, mesh1, normal0, mesh0,
                                 np.ones((HEIGHT, WIDTH), bool))
    assert not np.any(np.isfinite(translation))


def _rolling_run(params, frames: int = 9, bias: float = 0.0):
    """The rolling ball (turning 0.5 rad a frame, Gaussian noise) through the Denoiser: per
    frame the
    relative error of the output on the ball, the ball's mean history length of the direct
    signal and how many histories the stage replaced."""
    denoiser = Denoiser(params, debug_layers=True)
    errors, lengths, adopted = [], [], []
    for t in range(frames):
        normal, depth, mesh, motion, light, inside = _ball(t, turn=0.5, bias=bias)
        noisy = make_frame(WIDTH, HEIGHT, illumination=light, albedo=0.5, noise=0.3,
                           seed=40 + t, depth=depth, normal=normal, mesh_id=mesh,
                           motion=motion)
        out = denoiser.process(noisy)
        truth = true_radiance(light, width=WIDTH, height=HEIGHT, albedo=0.5)
        errors.append(float(np.mean(np.abs(out.color - truth)[:, inside])
                            / np.mean(truth[:, inside])))
        lengths.append(float(np.mean(out.layers["history_length.direct"][inside])))
        adopted.append(out.counts.get("object_history", 0))
    return errors, lengths, adopted


def test_the_default_runs_the_object_history_stages_around_antilag() -> None:
    names = stage_names(PRESETS["default"])
    assert names.index("reproject") < names.index("object_history") < names.index("antilag")
    assert names.index("antilag") < names.index("adopt_object_history") < names.index(
        "accumulate")
    assert "object_history" not in stage_names(PRESETS["paper"])
    assert "object_history" not in stage_names(PRESETS["default"].replace(antilag=False))


def test_a_rolling_balls_light_keeps_its_history() -> None:
    """Without the stages anti-lag drops the direct light's history on the ball every frame
    (each material point turns to another light); with them the history at the ball's
    translation serves, and the ball's error falls by a third."""
    off_errors, off_lengths, off_adopted = _rolling_run(
        PRESETS["default"].replace(object_history=False))
    on_errors, on_lengths, on_adopted = _rolling_run(PRESETS["default"])
    assert not any(off_adopted) and all(on_adopted[1:])
    assert max(off_lengths[3:]) < 2.6  # the history is dropped often
    assert np.mean(on_errors[3:]) < 0.75 * np.mean(off_errors[3:])
    assert max(on_errors[3:]) < min(off_errors[3:])


def test_a_biased_motion_field_does_not_break_it() -> None:
    """The ball's motion vectors all off by 1.3 pixels (the mean with them): the search
    finds the translation that matches the normals, and the error still falls."""
    on_errors, _, _ = _rolling_run(PRESETS["default"], bias=1.3)
    off_errors, _, _ = _rolling_run(PRESETS["default"].replace(object_history=False),
                                    bias=1.3)
    assert np.mean(on_errors[3:]) < 0.85 * np.mean(off_errors[3:])


def test_an_adopted_history_counts_as_one_frame() -> None:
    """``TURNED_FRAMES``: the ball's direct light never counts more than two frames (the
    adopted history and this frame) where it was adopted."""
    _, on_lengths, _ = _rolling_run(PRESETS["default"])
    assert 1.8 < np.mean(on_lengths[3:]) < 2.6
