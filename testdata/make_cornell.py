"""Write the bundled Cornell box scenes (OBJ + MTL), the checker texture and the animation.

Geometry: the Cornell Program of Computer Graphics "Cornell Box Data" (walls, light, short
and tall block; millimetres), published for a camera at (278, 273, -800) looking along +z.
Those numbers are kept verbatim below and rotated 180 degrees about the vertical axis through
the box centre (x' = 556 - x, z' = 559.2 - z, a proper rotation, so the red wall stays on the
left) so that the open side faces +z and the camera looks down -z, the usual OBJ convention
and the one `svgf trace`'s default camera uses. The ceiling gets a hole where the light is,
so the light sits exactly at the published height without z-fighting.

Reflectances: the box's reflectances are published as spectra (400-700 nm). The RGB values
below are the approximations of those spectra used by common renderer test scenes; the light
is likewise the customary RGB approximation of its measured emission.

Quads are wound so that walls, floor and ceiling face the inside of the box, blocks face
outwards, and the light faces down (it emits on that side only).

Run: ``python testdata/make_cornell.py`` (writes next to this file; deterministic).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent

# --- Published data (Cornell Box Data page), verbatim -------------------------------------
PUBLISHED_CAMERA = {"position": (278.0, 273.0, -800.0), "direction": (0.0, 0.0, 1.0),
                    "up": (0.0, 1.0, 0.0), "focal_length": 0.035, "film": 0.025}
LIGHT = [(343.0, 548.8, 227.0), (343.0, 548.8, 332.0), (213.0, 548.8, 332.0),
         (213.0, 548.8, 227.0)]
FLOOR = [(552.8, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 559.2), (549.6, 0.0, 559.2)]
CEILING = [(556.0, 548.8, 0.0), (556.0, 548.8, 559.2), (0.0, 548.8, 559.2), (0.0, 548.8, 0.0)]
BACK_WALL = [(549.6, 0.0, 559.2), (0.0, 0.0, 559.2), (0.0, 548.8, 559.2),
             (556.0, 548.8, 559.2)]
RIGHT_WALL = [(0.0, 0.0, 559.2), (0.0, 0.0, 0.0), (0.0, 548.8, 0.0), (0.0, 548.8, 559.2)]
LEFT_WALL = [(552.8, 0.0, 0.0), (549.6, 0.0, 559.2), (556.0, 548.8, 559.2),
             (556.0, 548.8, 0.0)]
SHORT_BLOCK = [
    [(130.0, 165.0, 65.0), (82.0, 165.0, 225.0), (240.0, 165.0, 272.0), (290.0, 165.0, 114.0)],
    [(290.0, 0.0, 114.0), (290.0, 165.0, 114.0), (240.0, 165.0, 272.0), (240.0, 0.0, 272.0)],
    [(130.0, 0.0, 65.0), (130.0, 165.0, 65.0), (290.0, 165.0, 114.0), (290.0, 0.0, 114.0)],
    [(82.0, 0.0, 225.0), (82.0, 165.0, 225.0), (130.0, 165.0, 65.0), (130.0, 0.0, 65.0)],
    [(240.0, 0.0, 272.0), (240.0, 165.0, 272.0), (82.0, 165.0, 225.0), (82.0, 0.0, 225.0)],
]
TALL_BLOCK = [
    [(423.0, 330.0, 247.0), (265.0, 330.0, 296.0), (314.0, 330.0, 456.0), (472.0, 330.0, 406.0)],
    [(423.0, 0.0, 247.0), (423.0, 330.0, 247.0), (472.0, 330.0, 406.0), (472.0, 0.0, 406.0)],
    [(472.0, 0.0, 406.0), (472.0, 330.0, 406.0), (314.0, 330.0, 456.0), (314.0, 0.0, 456.0)],
    [(314.0, 0.0, 456.0), (314.0, 330.0, 456.0), (265.0, 330.0, 296.0), (265.0, 0.0, 296.0)],
    [(265.0, 0.0, 296.0), (265.0, 330.0, 296.0), (423.0, 330.0, 247.0), (423.0, 0.0, 247.0)],
]
# RGB approximations of the published reflectance spectra and light emission.
WHITE = (0.725, 0.71, 0.68)
RED = (0.63, 0.065, 0.05)
GREEN = (0.14, 0.45, 0.091)
LIGHT_EMISSION = (17.0, 12.0, 4.0)
LIGHT_REFLECTANCE = (0.78, 0.78, 0.78)

# --- Checker texture ------------------------------------------------------------------------
CHECKER_SIZE = 256
CHECKER_SQUARES = 8
CHECKER_LIGHT = 0.9  # linear reflectance multipliers; stored sRGB-encoded in 8 bits
CHECKER_DARK = 0.2

BOX_CENTRE = np.array([278.0, 274.4, 279.6])
ROTATE_X, ROTATE_Z = 556.0, 559.2


def rotate(p: tuple[float, float, float]) -> np.ndarray:
    """180 degrees about the vertical axis x = 278, z = 279.6."""
    return np.array([ROTATE_X - p[0], p[1], ROTATE_Z - p[2]])


def oriented(quad: list[np.ndarray], toward: np.ndarray) -> list[np.ndarray]:
    """The quad wound so its normal (v1-v0)x(v2-v0) points along ``toward``."""
    normal = np.cross(quad[1] - quad[0], quad[2] - quad[0])
    return quad if float(normal @ toward) > 0 else quad[::-1]


def quad_facing_point(points: list[tuple], target: np.ndarray, inward: bool) -> list[np.ndarray]:
    quad = [rotate(p) for p in points]
    centre = np.mean(quad, axis=0)
    direction = target - centre if inward else centre - target
    return oriented(quad, direction)


def ceiling_with_hole(ceiling: list[np.ndarray], light: list[np.ndarray]) -> list[list[np.ndarray]]:
    """Four quads covering the ceiling minus the light's rectangle (all at y = 548.8)."""
    y = ceiling[0][1]
    cx = sorted({float(p[0]) for p in ceiling})
    cz = sorted({float(p[2]) for p in ceiling})
    lx = sorted({float(p[0]) for p in light})
    lz = sorted({float(p[2]) for p in light})
    x0, x1, z0, z1 = cx[0], cx[-1], cz[0], cz[-1]

    def rect(ax: float, bx: float, az: float, bz: float) -> list[np.ndarray]:
        return [np.array([ax, y, az]), np.array([bx, y, az]), np.array([bx, y, bz]),
                np.array([ax, y, bz])]

    return [
        rect(x0, x1, z0, lz[0]),
        rect(x0, x1, lz[-1], z1),
        rect(x0, lx[0], lz[0], lz[-1]),
        rect(lx[-1], x1, lz[0], lz[-1]),
    ]


def scene_objects(
    ceiling_hole: bool = True, light_drop: float = 0.0
) -> list[tuple[str, str, list[list[np.ndarray]]]]:
    """(object name, material, quads) in the rotated frame, wound as documented.

    ``ceiling_hole=False`` keeps the ceiling whole and ``light_drop`` lowers the light
    below it (mm), so the light can slide along the ceiling (``make_lag.py``).
    """
    centre = rotate(tuple(BOX_CENTRE))
    down = np.array([0.0, -1.0, 0.0])
    light = oriented([rotate(p) - np.array([0.0, light_drop, 0.0]) for p in LIGHT], down)
    ceiling_quad = [rotate(p) for p in CEILING]
    holed = ceiling_with_hole(ceiling_quad, light) if ceiling_hole else [ceiling_quad]
    ceiling = [oriented(q, down) for q in holed]
    objects = [
        ("floor", "white", [quad_facing_point(FLOOR, centre, inward=True)]),
        ("ceiling", "white", ceiling),
        ("back_wall", "white", [quad_facing_point(BACK_WALL, centre, inward=True)]),
        ("left_wall", "red", [quad_facing_point(LEFT_WALL, centre, inward=True)]),
        ("right_wall", "green", [quad_facing_point(RIGHT_WALL, centre, inward=True)]),
        ("light", "light", [light]),
    ]
    for name, faces in (("short_block", SHORT_BLOCK), ("tall_block", TALL_BLOCK)):
        block_centre = np.mean([rotate(p) for face in faces for p in face], axis=0)
        quads = [quad_facing_point(face, block_centre, inward=False) for face in faces]
        objects.append((name, "white", quads))
    return objects


def _fmt(value: float) -> str:
    return f"{value:.6g}"


def write_obj(path: Path, mtl_name: str, checker_floor: bool) -> None:
    lines = [
        "# Cornell box (Cornell Program of Computer Graphics data), rotated to face +z.",
        "# Generated by testdata/make_cornell.py; do not edit by hand.",
        f"mtllib {mtl_name}",
    ]
    vertex_count = 0
    uv_count = 0
    for name, material, quads in scene_objects():
        textured = checker_floor and name == "floor"
        lines.append(f"o {name}")
        lines.append(f"usemtl {'white_checker' if textured else material}")
        for quad in quads:
            for p in quad:
                lines.append("v " + " ".join(_fmt(c) for c in p))
            if textured:
                for p in quad:
                    lines.append(f"vt {_fmt(p[0] / ROTATE_X)} {_fmt(p[2] / ROTATE_Z)}")
                corners = [f"{vertex_count + k + 1}/{uv_count + k + 1}" for k in range(4)]
                uv_count += 4
            else:
                corners = [str(vertex_count + k + 1) for k in range(4)]
            lines.append("f " + " ".join(corners))
            vertex_count += 4
    path.write_text("\n".join(lines) + "\n")


def write_mtl(path: Path, checker_texture: str | None) -> None:
    def block(name: str, kd: tuple, ke: tuple | None = None, texture: str | None = None) -> str:
        text = f"newmtl {name}\nKd {' '.join(_fmt(c) for c in kd)}\n"
        if ke is not None:
            text += f"Ke {' '.join(_fmt(c) for c in ke)}\n"
        if texture is not None:
            text += f"map_Kd {texture}\n"
        return text

    parts = [
        "# Cornell box materials (RGB approximations of the published spectra).",
        block("white", WHITE),
        block("red", RED),
        block("green", GREEN),
        block("light", LIGHT_REFLECTANCE, LIGHT_EMISSION),
    ]
    if checker_texture is not None:
        parts.append(block("white_checker", WHITE, texture=checker_texture))
    path.write_text("\n".join(parts))


def write_checker(path: Path) -> None:
    import OpenImageIO as oiio

    cells = (np.arange(CHECKER_SIZE) * CHECKER_SQUARES) // CHECKER_SIZE
    light = (cells[:, None] + cells[None, :]) % 2 == 0
    linear = np.where(light, CHECKER_LIGHT, CHECKER_DARK)
    encoded = np.where(linear <= 0.0031308, linear * 12.92, 1.055 * linear ** (1 / 2.4) - 0.055)
    pixels = np.round(encoded * 255.0).astype(np.uint8)
    rgb = np.ascontiguousarray(np.repeat(pixels[:, :, None], 3, axis=2))
    out = oiio.ImageOutput.create(str(path))
    spec = oiio.ImageSpec(CHECKER_SIZE, CHECKER_SIZE, 3, "uint8")
    if out is None or not out.open(str(path), spec) or not out.write_image(rgb) or not out.close():
        raise SystemExit(f"cannot write {path}: {oiio.geterror()}")


def animation() -> dict:
    camera_position = rotate(PUBLISHED_CAMERA["position"])
    look_at = np.array([278.0, 273.0, 279.6])
    return {
        "comment": "Slow camera move; the short block slides and turns and comes back.",
        "camera": [
            {"frame": 1, "position": camera_position.tolist(), "look_at": look_at.tolist(),
             "up": [0, 1, 0], "fov_y": 39.3},
            {"frame": 48, "position": (camera_position + [160.0, 40.0, -120.0]).tolist(),
             "look_at": (look_at + [60.0, 0.0, 0.0]).tolist()},
        ],
        "objects": {
            "short_block": [
                {"frame": 1, "translate": [0, 0, 0], "rotate": [0, 0, 0]},
                {"frame": 24, "translate": [60, 0, 50], "rotate": [0, 35, 0]},
                {"frame": 48, "translate": [0, 0, 0], "rotate": [0, 0, 0]},
            ]
        },
    }


def main(out_dir: Path = HERE) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    write_checker(out_dir / "checker.png")
    write_obj(out_dir / "cornell.obj", "cornell.mtl", checker_floor=False)
    write_mtl(out_dir / "cornell.mtl", None)
    write_obj(out_dir / "cornell_checker.obj", "cornell_checker.mtl", checker_floor=True)
    write_mtl(out_dir / "cornell_checker.mtl", "checker.png")
    (out_dir / "anim.json").write_text(json.dumps(animation(), indent=2) + "\n")


if __name__ == "__main__":
    main()
