"""Small scenes and helpers shared by the tracer tests (``from tracescenes import ...``)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

TESTDATA = Path(__file__).resolve().parent.parent / "testdata"
REC709 = np.array([0.2126, 0.7152, 0.0722])


def read_exr(path: Path) -> tuple[dict[str, np.ndarray], oiio.ImageSpec]:
    image = oiio.ImageInput.open(str(path))
    assert image is not None, oiio.geterror()
    spec = image.spec()
    pixels = image.read_image(0, 0, 0, spec.nchannels, "float")
    image.close()
    return {name: pixels[:, :, k] for k, name in enumerate(spec.channelnames)}, spec


def rgb(layers: dict[str, np.ndarray], name: str) -> np.ndarray:
    prefix = f"{name}." if name else ""
    return np.stack([layers[f"{prefix}{c}"] for c in "RGB"], axis=-1).astype(np.float64)


def glossy_cornell(tmp_path: Path, extra: dict[str, str], name: str = "g") -> Path:
    """The bundled Cornell box with extra MTL lines per material, e.g.
    ``{"white": "Pr 0.3", "red": "Pm 1\\nPr 0.1"}``."""
    mtl = (TESTDATA / "cornell.mtl").read_text()
    for material, lines in extra.items():
        mtl = mtl.replace(f"newmtl {material}\n", f"newmtl {material}\n{lines}\n")
    (tmp_path / f"{name}.mtl").write_text(mtl)
    obj = (TESTDATA / "cornell.obj").read_text().replace("mtllib cornell.mtl", f"mtllib {name}.mtl")
    (tmp_path / f"{name}.obj").write_text(obj)
    return tmp_path / f"{name}.obj"


def copy_cornell(tmp_path: Path) -> Path:
    for name in ("cornell.obj", "cornell.mtl"):
        shutil.copy(TESTDATA / name, tmp_path / name)
    return tmp_path / "cornell.obj"


def write_animation(path: Path, data: dict) -> Path:
    path.write_text(json.dumps(data))
    return path


def cornell_camera() -> list[dict]:
    """The first camera key of the bundled animation (a static camera)."""
    data = json.loads((TESTDATA / "anim.json").read_text())
    return [data["camera"][0]]


def plane_and_lamp(tmp_path: Path, *, floor_mtl: str = "Kd 0.7 0.7 0.7", le: float = 5.0,
                   half: float = 0.25, height: float = 1.0) -> Path:  # fmt: skip
    """A floor [-4, 4]^2 at y = 0 (object ``floor``) under a square lamp (object ``lamp``)
    of half-size ``half`` at ``height``, facing down."""
    (tmp_path / "p.mtl").write_text(
        f"newmtl floor\n{floor_mtl}\nnewmtl lamp\nKd 0 0 0\nKe {le} {le} {le}\n"
    )
    (tmp_path / "p.obj").write_text(
        "mtllib p.mtl\n"
        "o floor\nusemtl floor\nv -4 0 -4\nv -4 0 4\nv 4 0 4\nv 4 0 -4\nf 1 2 3 4\n"
        f"o lamp\nusemtl lamp\nv {-half} {height} {-half}\nv {half} {height} {-half}\n"
        f"v {half} {height} {half}\nv {-half} {height} {half}\nf 5 6 7 8\n"
    )
    return tmp_path / "p.obj"
