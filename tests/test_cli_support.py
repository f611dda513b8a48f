"""Helpers for the CLI and farm tests: tiny synthetic EXR sequences and in-process CLI runs.

(Named test_cli_* so it sits with the CLI tests; it defines no tests itself.)
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from svgf_cli.cli import main
from svgf_cli.io.exr import write_exr

REPO = Path(__file__).resolve().parents[1]
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


def run_cli(args: Sequence[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """Run `svgf ARGS` in-process; return (exit code, stdout, stderr)."""
    with pytest.raises(SystemExit) as exited:
        main([str(a) for a in args])
    captured = capsys.readouterr()
    code = exited.value.code
    return (code if isinstance(code, int) else 1), captured.out, captured.err


def svgf_subprocess(args: Sequence[str], **kwargs: object) -> subprocess.Popen[str]:
    """Start `python -m svgf_cli ARGS` as a real process (for signal and kill tests)."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen(  # noqa: S603 - our own interpreter and module
        [sys.executable, "-m", "svgf_cli", *map(str, args)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=REPO,
        env=env,
        **kwargs,  # type: ignore[arg-type]
    )


def read_pixels(path: Path) -> tuple[np.ndarray, oiio.ImageSpec]:
    image = oiio.ImageInput.open(str(path))
    assert image is not None, oiio.geterror()
    try:
        spec = image.spec().copy()
        pixels = image.read_image("float")
        assert pixels is not None, image.geterror()
    finally:
        image.close()
    return np.asarray(pixels), spec


def outputs(folder: Path, name: str = "out") -> list[Path]:
    return sorted(p for p in folder.glob(f"{name}.*.exr") if not p.name.startswith("."))
