"""Helpers for the CLI and farm tests: tiny synthetic EXR sequences, in-process CLI runs, the
uninterrupted reference run, and `svgf` as a real process (signal and kill tests).

Outputs are read by channel name with ``exr_fixtures.read_exr``.
(Named test_cli_* so it sits with the CLI tests; it defines no tests itself.)
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest

from svgf_cli.cli import main
from svgf_cli.io.exr import write_exr

TESTS = Path(__file__).resolve().parent
REPO = TESTS.parent
INPUT_ATTRIBUTES = {"shot/name": "sq010_sh020", "framesPerSecond_note": "24"}


def frame_channels(
    frame: int, width: int = 32, height: int = 24, *, seed: int = 7, noise: bool = True
) -> dict[str, np.ndarray]:
    """One frame of a small scene: two depth planes, a slowly moving camera, 1-spp noise.

    The camera pans one pixel per frame to the right: pixel x of frame f shows scene point
    ``x + f``, so the scene slides left on screen and the point seen at x was at x + 1 in the
    previous frame. The backward motion (``svgf_cli.frame``: previous position minus
    current) is therefore +1 px in x everywhere, in every frame (the scene before frame 1
    moved the same way). Depth, albedo, light and ids are functions of the scene point, so
    the whole G-buffer moves with the motion (``test_cli_ground_truth`` checks it).
    ``noise=False`` gives the noise-free frame (every Exp(1) draw replaced by its mean, 1).
    """
    rng = np.random.default_rng(seed * 100_003 + frame)
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float32)
    world_x = xs + frame  # the scene point seen at pixel x
    left = world_x < (width // 2 + 4)
    depth = np.where(left, 2.0, 5.0).astype(np.float32)
    albedo_base = 0.5 + 0.3 * np.sin(world_x * 0.4)[None] * np.array([1.0, 0.7, 0.4])[:, None, None]
    albedo = np.broadcast_to(albedo_base, (3, height, width)).astype(np.float32)
    light = np.where(left, 1.0, 0.4).astype(np.float32)
    draws = rng.exponential(1.0, (2, 3, height, width)).astype(np.float32)
    if not noise:
        draws[:] = 1.0
    direct = light[None] * albedo * draws[0]
    indirect = 0.3 * albedo * draws[1]
    channels: dict[str, np.ndarray] = {}
    for i, c in enumerate("RGB"):
        channels[f"direct.{c}"] = direct[i]
        channels[f"indirect.{c}"] = indirect[i]
        channels[f"albedo.{c}"] = albedo[i]
    channels["N.X"] = np.zeros((height, width), np.float32)
    channels["N.Y"] = np.zeros((height, width), np.float32)
    channels["N.Z"] = np.ones((height, width), np.float32)
    channels["Z"] = depth
    channels["motion.X"] = np.full((height, width), 1.0, np.float32)
    channels["motion.Y"] = np.zeros((height, width), np.float32)
    channels["id"] = np.where(left, 1.0, 2.0).astype(np.float32)
    channels["A"] = np.ones((height, width), np.float32)
    return channels


def write_sequence(
    folder: Path,
    frames: Sequence[int],
    *,
    width: int = 32,
    height: int = 24,
    name: str = "in",
    compression: str = "zip",
) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for frame in frames:
        path = folder / f"{name}.{frame:04d}.exr"
        write_exr(
            path,
            frame_channels(frame, width, height),
            attributes=dict(INPUT_ATTRIBUTES),
            compression=compression,
        )
        paths.append(path)
    return paths


def exit_code(args: Sequence[object]) -> int:
    """Run `svgf ARGS` in-process and return its exit code (its output goes to pytest's
    capture, shown when a test fails)."""
    with pytest.raises(SystemExit) as exited:
        main([str(a) for a in args])
    code = exited.value.code
    return code if isinstance(code, int) else 1


def run_cli(args: Sequence[object], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """Run `svgf ARGS` in-process; return (exit code, stdout, stderr)."""
    code = exit_code(args)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def sequence_folder(
    tmp_path_factory: pytest.TempPathFactory, frames: Sequence[int], width: int = 32,
    height: int = 24,
) -> Path:
    """A fresh folder holding `write_sequence` (``in.####.exr``): a module fixture's input."""
    folder = tmp_path_factory.mktemp("seq")
    write_sequence(folder, frames, width=width, height=height)
    return folder


def reference_run(
    tmp_path_factory: pytest.TempPathFactory, sequence: Path, *options: object
) -> dict[int, Path]:
    """One uninterrupted `svgf denoise -q` of every frame of ``sequence`` (``in.####.exr``)
    into ``o.####.exr`` in a fresh folder: what chunked, resumed, interrupted and retried runs
    must reproduce. Returns frame -> output."""
    out = tmp_path_factory.mktemp("reference")
    args = ["denoise", sequence / "in.####.exr", "-o", out / "o.####.exr", "-q", *options]
    assert exit_code(args) == 0
    frames = sorted(int(p.name.split(".")[1]) for p in sequence.glob("in.*.exr"))
    return {f: out / f"o.{f:04d}.exr" for f in frames}


def svgf_subprocess(
    args: Sequence[object], *, pause_before: int | None = None, **kwargs: object
) -> subprocess.Popen[str]:
    """Start `python -m svgf_cli ARGS` as a real process (for signal and kill tests), with
    default SIGINT/SIGTERM dispositions; ``pause_before`` N stops it before it filters its
    frame N (0-based) until it is signalled (see ``svgf_child.py``)."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    pause = [] if pause_before is None else ["--pause-before", str(pause_before)]
    return subprocess.Popen(  # noqa: S603 - our own interpreter and module
        [sys.executable, str(TESTS / "svgf_child.py"), *pause, *map(str, args)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=REPO,
        env=env,
        **kwargs,  # type: ignore[arg-type]
    )


def outputs(folder: Path, name: str = "out") -> list[Path]:
    return sorted(p for p in folder.glob(f"{name}.*.exr") if not p.name.startswith("."))
