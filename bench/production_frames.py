"""A 1080p ~80-channel Blender Cycles production-like frame set, made on demand (not committed).

Preferred source: ``testdata/cycles/render.py --scene production`` (light groups, a fog
volume, glass, Cryptomatte) rendered at 1920x1080 when that scene exists and ``bpy`` is
installed (``.venv-blender``). Otherwise (``--stand-in``, and the fallback) a *stand-in*:
the committed 128x72 Cycles ``roll`` frames widened to a production frame's layout:

* every plane upscaled 15x to 1920x1080 (motion vectors scaled with it), the light passes
  and ``Combined`` times one per-pixel 1-spp-like noise factor (so the lobe passes still add
  up to the colour and ZIP meets noise, not flat blocks);
* ``VolumeDir``/``VolumeInd`` (a faint fog, added to ``Combined``), three light groups
  ``Combined_<name>`` (RGB), ``CryptoObject00..02`` (RGBA: id hash, coverage);
* every channel float32, ZIP, one part, ``ViewLayer.`` prefix: 80 channels.

Run: ``.venv/bin/python bench/production_frames.py [--out bench/out/production] [--frames 4]``
prints the folder and the pattern; a set already there is reused.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import OpenEXR  # noqa: E402

from svgf_cli.io.source import decode_source  # noqa: E402

SOURCE = REPO / "testdata" / "cycles" / "roll"
DEFAULT_OUT = REPO / "bench" / "out" / "production"
SCALE = 15  # 128x72 -> 1920x1080
LIGHT_PASSES = ("DiffDir", "DiffInd", "GlossDir", "GlossInd", "TransDir", "TransInd", "Emit",
                "Env", "Combined")
LIGHT_GROUPS = ("key", "fill", "rim")


def _up(plane: np.ndarray) -> np.ndarray:
    return np.repeat(np.repeat(plane.astype(np.float32), SCALE, 0), SCALE, 1)


def _noise(frame: int, shape: tuple[int, int]) -> np.ndarray:
    rng = np.random.default_rng(9001 + frame)
    return rng.exponential(1.0, shape).astype(np.float32)


def stand_in_channels(frame: int) -> tuple[dict[str, np.ndarray], dict]:
    """One widened frame: channel name -> (1080, 1920) float32, and the source header."""
    source = decode_source(SOURCE / f"in.{frame:04d}.exr")
    part = source.parts[0]
    planes = {name: _up(c.pixels) for name, c in part.channels.items()}
    noise = _noise(frame, next(iter(planes.values())).shape)
    prefix = "ViewLayer."
    for name in planes:
        layer = name[len(prefix):].rpartition(".")[0]
        if layer in LIGHT_PASSES and not name.endswith(".A"):
            planes[name] *= noise
        if layer == "Vector":
            planes[name] *= SCALE
    fog = _noise(frame + 1000, noise.shape)
    for c in "RGB":
        direct, indirect = 0.02 * fog, 0.01 * fog * noise
        planes[f"{prefix}VolumeDir.{c}"] = direct
        planes[f"{prefix}VolumeInd.{c}"] = indirect
        planes[f"{prefix}Combined.{c}"] += direct + indirect
        for share, group in zip((0.6, 0.3, 0.1), LIGHT_GROUPS, strict=True):
            planes[f"{prefix}Combined_{group}.{c}"] = share * planes[f"{prefix}Combined.{c}"]
    ids = planes[f"{prefix}IndexOB.X"]
    for rank in range(3):
        hashed = np.sin(ids * (12.9898 + rank)).astype(np.float32)
        coverage = np.clip(0.5 + 0.5 * fog * (rank + 1) / 3, 0, 1).astype(np.float32)
        for c, plane in zip("RGBA", (hashed, coverage, hashed * 0.5, coverage * 0.5),
                            strict=True):
            planes[f"{prefix}CryptoObject{rank:02d}.{c}"] = np.ascontiguousarray(plane)
    header = {k: v for k, v in part.header.items() if k not in ("channels", "chunkCount")}
    height, width = noise.shape
    header["dataWindow"] = (np.array([0, 0], np.int32),
                            np.array([width - 1, height - 1], np.int32))
    header["displayWindow"] = header["dataWindow"]
    header["compression"] = OpenEXR.ZIP_COMPRESSION
    return dict(sorted(planes.items())), header


def write_stand_in(out: Path, frames: int) -> None:
    out.mkdir(parents=True, exist_ok=True)
    for frame in range(1, frames + 1):
        path = out / f"in.{frame:04d}.exr"
        if path.exists():
            continue
        planes, header = stand_in_channels(frame)
        channels = {n: OpenEXR.Channel(n, p) for n, p in planes.items()}
        OpenEXR.File([OpenEXR.Part(header, channels, "")]).write(str(path))
        print(f"{path}: {len(planes)} channels, {path.stat().st_size / 1e6:.0f} MB", flush=True)


def render_production(out: Path, frames: int) -> bool:
    """``render.py --scene production`` at 1080p into ``out/production/``, when the scene
    and bpy exist."""
    script = REPO / "testdata" / "cycles" / "render.py"
    python = REPO / ".venv-blender" / "bin" / "python"
    if "production" not in script.read_text() or not python.exists():
        return False
    # render.py writes into OUT/<scene>/.
    if all((out / "production" / f"in.{f:04d}.exr").exists() for f in range(1, frames + 1)):
        return True
    rc = subprocess.call(["nice", "-n", "10", str(python), str(script), "--scene", "production",
                          "--resolution", "1920", "1080", "--what", "inputs", "--frames", "1",
                          str(frames), "--out", str(out)])
    return rc == 0


def make(out: Path | None = None, frames: int = 4, stand_in: bool = False) -> Path:
    """The folder holding ``in.####.exr`` frames 1..frames (made if missing)."""
    if out is None:
        out = DEFAULT_OUT.with_name("production_standin") if stand_in else DEFAULT_OUT
    if not stand_in and render_production(out, frames):
        return out / "production"
    out = out if stand_in else out.with_name("production_standin")
    write_stand_in(out, frames)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--frames", type=int, default=4)
    parser.add_argument("--stand-in", action="store_true",
                        help="widen the committed roll frames even if the scene exists")
    args = parser.parse_args(argv)
    folder = make(args.out, args.frames, args.stand_in)
    print(folder / "in.####.exr")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
