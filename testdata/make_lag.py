"""Write (and with ``--render``, render) the lag test sequences under ``testdata/lag/``.

Five 16-frame sequences of the Cornell box (``make_cornell.py``'s geometry with a whole
ceiling, the light 1 mm below it so it can slide, and a sphere on the floor) that exercise
temporal filtering where lighting changes and where it does not (the control):

* ``light_slide_dim``: the light slides 240 mm right to left across the ceiling over frames
  1-16 and dims to 45% at frame 10 (keys 1.0 at 9, 0.45 at 10).
* ``light_step``: static scene and camera; the light steps down to 30% at frame 6 and back
  to 100% at frame 11 (frames 6-10 are dimmed).
* ``shadow``: static camera and light; the sphere (scaled to radius 65 mm) rolls 120 mm
  left to right across the floor in front of the tall block by frame 8.5 and back by frame
  16 (about 16 mm, 2 pixels, per frame), its shadow moving with it.
* ``camera``: static lighting and objects, the camera moves 200 mm right, 40 mm up and
  150 mm closer while looking at the box centre (the control sequence).
* ``glossy``: a glossy floor (dielectric coat, roughness 0.25), a gold sphere (metal,
  roughness 0.2) and a steel tall block (metal, roughness 0.3); the light slides as in
  ``light_slide_dim`` (no dimming) and the camera moves as in ``camera``. Rendered with the
  lobe passes.

Scenes: ``lag/cornell_lag.obj``/``.mtl`` (Lambertian) and ``lag/cornell_glossy.obj``/``.mtl``
(the same geometry, glossy floor, metal sphere and tall block); each sequence's animation is
``lag/<name>/anim.json``. Everything is deterministic.

Run: ``python testdata/make_lag.py`` (scene and animation files only) or ``python
testdata/make_lag.py --render [--svgf PATH] [--only NAME ...]`` (also the EXR frames, with
``nice -n 10``; ``make lag-fixtures`` does this). ``--resolution WxH --out DIR`` renders the
same sequences at another size into ``DIR`` (validation beyond the bundled 128x72 frames).
The render commands are printed and listed in ``lag/README.md``.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from make_cornell import WHITE, _fmt, rotate, scene_objects, write_mtl

HERE = Path(__file__).resolve().parent
LAG = HERE / "lag"

FRAMES = "1-16"
RESOLUTION = "128x72"
REFERENCE_SPP = 2048
# Jittered sequences: 64 samples at each of 4x4 positions per pixel (--reference-supersample).
JITTER_REFERENCE_SPP = 64
MAX_DEPTH = 5
LIGHT_DROP = 1.0  # mm below the ceiling
SPHERE_RADIUS = 50.0
# In front of the tall block, left of the short one: it rolls without touching either.
SPHERE_START = np.array([75.0, SPHERE_RADIUS, 410.0])
# The shadow sequence scales the sphere to radius 65 mm and rolls it 120 mm right and back.
SHADOW_SPHERE_SCALE = 1.3
SHADOW_ROLL = 120.0
SPHERE_SUBDIVISIONS = 2  # icosphere: 320 triangles, smooth vertex normals
LIGHT_SLIDE = 120.0  # the light goes from +120 to -120 mm in x
GOLD = (0.95, 0.72, 0.35)
STEEL = (0.75, 0.75, 0.77)

# Layers the fixtures leave out: P (world position) is not read by svgf denoise.
SKIP_LAYERS = ("P",)


def icosphere(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit-sphere vertices and outward-wound triangles of a subdivided icosahedron."""
    t = (1.0 + math.sqrt(5.0)) / 2.0
    verts = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t),
             (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]  # fmt: skip
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
             (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
             (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]  # fmt: skip
    points = [np.array(v, float) / np.linalg.norm(v) for v in verts]

    def midpoint(a: int, b: int, cache: dict[tuple[int, int], int]) -> int:
        key = (min(a, b), max(a, b))
        if key not in cache:
            m = points[a] + points[b]
            points.append(m / np.linalg.norm(m))
            cache[key] = len(points) - 1
        return cache[key]

    for _ in range(subdivisions):
        cache: dict[tuple[int, int], int] = {}
        refined = []
        for a, b, c in faces:
            ab, bc, ca = midpoint(a, b, cache), midpoint(b, c, cache), midpoint(c, a, cache)
            refined += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = refined
    vertices = np.array(points)
    tris = np.array(faces)
    # Outward winding: (v1 - v0) x (v2 - v0) along the centroid direction.
    v = vertices[tris]
    normal = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    inward = np.einsum("ij,ij->i", normal, v.mean(axis=1)) < 0
    tris[inward] = tris[inward][:, ::-1]
    return vertices, tris


def write_scene(path: Path, mtl_name: str, materials: dict[str, str]) -> None:
    """The lag Cornell box: whole ceiling, lowered light, and the sphere (smooth normals).
    ``materials`` maps object names to material names (default: make_cornell's)."""
    lines = [
        "# Cornell box for the lag sequences: whole ceiling, light 1 mm below it, a sphere.",
        "# Generated by testdata/make_lag.py; do not edit by hand.",
        f"mtllib {mtl_name}",
    ]
    count = 0
    for name, material, quads in scene_objects(ceiling_hole=False, light_drop=LIGHT_DROP):
        lines += [f"o {name}", f"usemtl {materials.get(name, material)}"]
        for quad in quads:
            lines += ["v " + " ".join(_fmt(c) for c in p) for p in quad]
            lines.append("f " + " ".join(str(count + k + 1) for k in range(4)))
            count += 4
    unit, tris = icosphere(SPHERE_SUBDIVISIONS)
    lines += ["o sphere", f"usemtl {materials.get('sphere', 'white')}"]
    lines += ["v " + " ".join(_fmt(c) for c in SPHERE_START + SPHERE_RADIUS * p) for p in unit]
    lines += ["vn " + " ".join(_fmt(c) for c in p) for p in unit]
    for tri in tris:
        lines.append("f " + " ".join(f"{count + i + 1}//{i + 1}" for i in tri))
    path.write_text("\n".join(lines) + "\n")


def write_glossy_mtl(path: Path) -> None:
    write_mtl(path, None)
    text = path.read_text()
    text += (
        f"\nnewmtl floor_glossy\nKd {' '.join(_fmt(c) for c in WHITE)}\nPr 0.25\nPm 0\n"
        f"\nnewmtl gold\nKd {' '.join(_fmt(c) for c in GOLD)}\nPr 0.2\nPm 1\n"
        f"\nnewmtl steel\nKd {' '.join(_fmt(c) for c in STEEL)}\nPr 0.3\nPm 1\n"
    )
    path.write_text(text)


def camera_keys(moving: bool) -> list[dict]:
    position = rotate((278.0, 273.0, -800.0))
    look_at = np.array([278.0, 273.0, 279.6])
    first = {"frame": 1, "position": position.tolist(), "look_at": look_at.tolist(),
             "up": [0, 1, 0], "fov_y": 39.3}  # fmt: skip
    if not moving:
        return [first]
    return [first, {"frame": 16, "position": (position + [200.0, 40.0, -150.0]).tolist(),
                    "look_at": look_at.tolist()}]  # fmt: skip


def light_slide() -> list[dict]:
    return [{"frame": 1, "translate": [LIGHT_SLIDE, 0, 0]},
            {"frame": 16, "translate": [-LIGHT_SLIDE, 0, 0]}]  # fmt: skip


def sphere_roll() -> list[dict]:
    """The shadow sequence's sphere, scaled up to radius ``SHADOW_SPHERE_SCALE`` x 50 mm (and
    lifted to keep it on the floor), rolls without slipping ``SHADOW_ROLL`` mm along +x by
    frame 8.5 and back by frame 16: a turn of -distance / radius about z, each slerp under
    180 degrees."""
    radius = SPHERE_RADIUS * SHADOW_SPHERE_SCALE
    lift = radius - SPHERE_RADIUS
    keys = []
    for frame, distance in ((1.0, 0.0), (8.5, SHADOW_ROLL), (16.0, 0.0)):
        angle = math.degrees(-distance / radius) + 0.0  # no -0.0 in the file
        keys.append({"frame": frame, "translate": [distance, lift, 0], "scale": SHADOW_SPHERE_SCALE,
                     "rotate": {"axis": [0, 0, 1], "angle": angle}})  # fmt: skip
    return keys


SEQUENCES: dict[str, dict] = {
    "light_slide_dim": {
        "scene": "cornell_lag.obj",
        "comment": "Light slides right to left over frames 1-16; dims to 45% at frame 10.",
        "camera": camera_keys(False),
        "objects": {"light": [*light_slide(), {"frame": 9, "emission_scale": 1.0},
                              {"frame": 10, "emission_scale": 0.45}]},
    },
    "light_step": {
        "scene": "cornell_lag.obj",
        "comment": "Static; light at 30% on frames 6-10, 100% otherwise.",
        "camera": camera_keys(False),
        "objects": {"light": [{"frame": 5, "emission_scale": 1.0},
                              {"frame": 6, "emission_scale": 0.3},
                              {"frame": 10, "emission_scale": 0.3},
                              {"frame": 11, "emission_scale": 1.0}]},
    },
    "shadow": {
        "scene": "cornell_lag.obj",
        "comment": "Static camera and light; the sphere rolls 120 mm along +x and back.",
        "camera": camera_keys(False),
        "objects": {"sphere": sphere_roll()},
    },
    "camera": {
        "scene": "cornell_lag.obj",
        "comment": "Control: static lighting and objects, moving camera.",
        "camera": camera_keys(True),
        "objects": {},
    },
    "glossy": {
        "scene": "cornell_glossy.obj",
        "comment": "Glossy floor, gold sphere, steel tall block; light slides, camera moves.",
        "camera": camera_keys(True),
        "objects": {"light": light_slide()},
        "lobes": True,
    },
}


def write_inputs() -> None:
    LAG.mkdir(parents=True, exist_ok=True)
    write_scene(LAG / "cornell_lag.obj", "cornell_lag.mtl", {})
    write_mtl(LAG / "cornell_lag.mtl", None)
    write_scene(LAG / "cornell_glossy.obj", "cornell_glossy.mtl",
                {"floor": "floor_glossy", "sphere": "gold", "tall_block": "steel"})  # fmt: skip
    write_glossy_mtl(LAG / "cornell_glossy.mtl")
    for name, spec in SEQUENCES.items():
        folder = LAG / name
        folder.mkdir(exist_ok=True)
        data = {"comment": spec["comment"], "camera": spec["camera"], "objects": spec["objects"]}
        (folder / "anim.json").write_text(json.dumps(data, indent=2) + "\n")


def trace_command(name: str, svgf: str, resolution: str = RESOLUTION,
                  out: Path | None = None, seed: int = 0, reference: bool = True,
                  jitter: bool = False) -> list[str]:
    """The `svgf trace` command of one sequence; ``out`` (default: ``testdata/lag``) holds its
    folder, so larger renders for validation stay out of the fixtures. Another ``seed`` is
    another noise realisation of the same frames (``bench/bias_variance.py``), which needs no
    ``reference`` of its own. ``jitter``: each pixel's sample (G-buffer included) at a random
    position in the pixel, as Mitsuba's one-sample frames, without gradient samples (they
    re-trace pixel centres), against references averaged over 4x4 positions of 64 samples
    each (a box pixel filter, 1024 samples)."""
    spec = SEQUENCES[name]
    rel = Path("testdata") / "lag"
    frames = (out if out is not None else rel) / name
    command = [
        svgf, "trace", str(rel / spec["scene"]), "-o", str(frames / "in.####.exr"),
        "--frames", FRAMES, "--resolution", resolution, "--spp", "1",
        "--max-depth", str(MAX_DEPTH), "--seed", str(seed),
        "--animation", str(rel / name / "anim.json"),
        "--motion-next", "--compression", "zip", "--overwrite", "-q",
    ]  # fmt: skip
    command += ["--jitter"] if jitter else ["--gradient-samples"]
    if reference:
        command += ["--reference", str(frames / "ref.####.exr"), "--reference-spp",
                    str(JITTER_REFERENCE_SPP if jitter else REFERENCE_SPP),
                    "--reference-channels", "rgb", "--reference-half"]
        if jitter:
            command += ["--reference-supersample", "4"]
    for layer in SKIP_LAYERS:
        command += ["--skip-layer", layer]
    if spec.get("lobes"):
        command.append("--lobes")
    return command


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--render", action="store_true", help="also render the EXR frames")
    parser.add_argument("--svgf", default=str(HERE.parent / ".venv" / "bin" / "svgf"))
    parser.add_argument("--only", nargs="*", choices=sorted(SEQUENCES), default=None)
    parser.add_argument("--resolution", default=RESOLUTION, metavar="WxH",
                        help=f"render size (default {RESOLUTION}, the fixtures')")
    parser.add_argument("--jitter", action="store_true",
                        help="jittered samples and box-filtered references, into "
                        "testdata/lag_jit/<name>/ (the committed: camera)")
    parser.add_argument("--out", type=Path, default=None, metavar="DIR",
                        help="render into DIR/<name>/ instead of testdata/lag/<name>/ (e.g. a "
                        "larger validation set: --resolution 256x144 --out /tmp/lag256)")
    args = parser.parse_args(argv)
    write_inputs()
    if not args.render:
        return 0
    for name in args.only or list(SEQUENCES):
        out = args.out.resolve() if args.out is not None else None
        if out is None and args.jitter:
            out = HERE / "lag_jit"
        if out is not None:
            (out / name).mkdir(parents=True, exist_ok=True)
        command = ["nice", "-n", "10", *trace_command(name, args.svgf, args.resolution, out,
                                                      jitter=args.jitter)]
        print(" ".join(command), flush=True)
        start = time.perf_counter()
        subprocess.run(command, check=True, cwd=HERE.parent)
        print(f"{name}: {time.perf_counter() - start:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
