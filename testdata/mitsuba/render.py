"""Render svgf's Cornell box animations with Mitsuba 3: one-sample frames as Mitsuba writes them.

Run with `make mitsuba-fixtures` (a virtualenv with `mitsuba` 3.9 and this project):
`--scene seq` (`testdata/seq`'s animation) and the `lag` sequences' (`--scene lag/shadow`,
...). Each
frame is three Mitsuba renders of the same scene, CPU variant `scalar_rgb`, `path`
integrator with its defaults (no depth limit, Russian roulette), `independent` sampler,
`hdrfilm` with a box pixel filter (`--pixel-filter`, Mitsuba's default is a Gaussian whose
splats correlate one-sample noise between pixels, which OIDN does not remove):

* the input: 1 spp through the `aov` integrator around `path`: the colour and, from the
  same jittered primary ray, `albedo`, `sh_normal` and `position` (view depth is computed
  from it here, as Mitsuba has no linear-depth AOV);
* the emission seen at the primary hit: `path` with `max_depth` 1 and the same sampler
  seed, so the same sample positions (Mitsuba has no emission AOV);
* the reference: `path` at `--ref-spp` samples, another seed, the same pixel filter.

Mitsuba writes no motion vectors: the input's `motion.X/Y` are `svgf trace`'s of the same
animation (pixel centres), as a pipeline computes them from its own scene description. No
object ids: Mitsuba's `shape_index` AOV numbers shapes in load order, which changes from
one scene load to the next (docs/inputs.md#object-ids).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from svgf_cli.io.exr import write_exr  # noqa: E402
from svgf_trace.animation import load_animation  # noqa: E402
from svgf_trace.scene import Scene, load_obj  # noqa: E402

WIDTH, HEIGHT = 128, 72
# name -> (scene, animation, frames): seq's animation and the lag sequences' (testdata/lag).
SCENES = {
    "seq": (ROOT / "testdata" / "cornell_checker.obj", ROOT / "testdata" / "anim.json", "1-10"),
    **{f"lag/{name}": (ROOT / "testdata" / "lag" / "cornell_lag.obj",
                       ROOT / "testdata" / "lag" / name / "anim.json", "1-16")
       for name in ("shadow", "light_slide_dim", "light_step", "camera")},
}


def _args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="seq", choices=sorted(SCENES))
    parser.add_argument("--out", type=Path, help="default: testdata/mitsuba/SCENE")
    parser.add_argument("--frames", help="first-last (default: the scene's)")
    parser.add_argument("--ref-spp", type=int, default=4096)
    parser.add_argument("--seed", type=int, default=0, help="added to each frame's seeds")
    parser.add_argument("--pixel-filter", default="box", choices=["box", "gaussian"])
    return parser.parse_args()


def _write_ply(path: Path, positions: np.ndarray, uvs: np.ndarray) -> None:
    """Triangles (T, 3, 3) with their corners' UVs as a binary PLY, one vertex per corner."""
    count = positions.shape[0]
    header = ("ply\nformat binary_little_endian 1.0\n"
              f"element vertex {3 * count}\nproperty float x\nproperty float y\n"
              "property float z\nproperty float u\nproperty float v\n"
              f"element face {count}\nproperty list uchar int vertex_indices\nend_header\n")
    vertices = np.concatenate([positions.reshape(-1, 3), uvs.reshape(-1, 2)], axis=1)
    faces = np.empty(count, dtype=[("n", "u1"), ("i", "<i4", 3)])
    faces["n"] = 3
    faces["i"] = np.arange(3 * count).reshape(count, 3)
    path.write_bytes(header.encode() + vertices.astype("<f4").tobytes() + faces.tobytes())


def _shapes(mi: object, scene: Scene, animation: object, frame: int, folder: Path) -> dict:
    """The frame's objects, moved by the animation, as Mitsuba shape dicts."""
    shapes = {}
    for obj in scene.objects:
        rows = slice(obj.start, obj.stop)
        corners = scene.positions[rows].reshape(-1, 3)
        pivot = (corners.min(axis=0) + corners.max(axis=0)) * 0.5  # svgf trace's default
        matrix = animation.object_matrix(obj.name, frame, pivot)
        moved = corners @ matrix[:3, :3].T + matrix[:3, 3]
        ply = folder / f"{obj.name}.{frame:04d}.ply"
        _write_ply(ply, moved.reshape(-1, 3, 3), scene.uvs[rows])
        material = scene.materials[int(scene.material[obj.start])]
        if material.texture is not None:
            texel = (material.texture * material.kd[None, None, :]).astype(np.float32)
            reflectance = {"type": "bitmap", "bitmap": mi.Bitmap(texel), "raw": True}
        else:
            reflectance = {"type": "rgb", "value": [float(v) for v in material.kd]}
        shape = {"type": "ply", "filename": str(ply), "face_normals": True,
                 "bsdf": {"type": "diffuse", "reflectance": reflectance}}
        if material.emissive:
            scaled = material.ke * animation.emission_scale(obj.name, frame)
            radiance = [float(v) for v in scaled]
            shape["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": radiance}}
        shapes[obj.name] = shape
    return shapes


def _render(mi: object, shapes: dict, camera: object, integrator: dict, spp: int, seed: int,
            pixel_filter: str) -> np.ndarray:
    scene = mi.load_dict({
        "type": "scene", "integrator": integrator, **shapes,
        "sensor": {
            "type": "perspective", "fov": float(camera.fov_y), "fov_axis": "y",
            "to_world": mi.ScalarTransform4f().look_at(
                origin=[float(v) for v in camera.position],
                target=[float(v) for v in camera.look_at], up=[float(v) for v in camera.up]),
            "film": {"type": "hdrfilm", "width": WIDTH, "height": HEIGHT,
                     "pixel_format": "rgba", "rfilter": {"type": pixel_filter}},
            "sampler": {"type": "independent", "sample_count": spp},
        },
    })
    return np.array(mi.render(scene, spp=spp, seed=seed), dtype=np.float32)


def _motion(scene: Path, animation: Path, frames: tuple[int, int], folder: Path
            ) -> dict[int, np.ndarray]:
    """`svgf trace`'s motion of the animation at pixel centres: frame -> (2, H, W)."""
    import OpenImageIO as oiio

    pattern = folder / "trace.####.exr"
    subprocess.run([sys.executable, "-m", "svgf_cli", "trace", str(scene), "-o", str(pattern),
                    "--frames", f"{frames[0]}-{frames[1]}", "--resolution", f"{WIDTH}x{HEIGHT}",
                    "--spp", "1", "--max-depth", "1", "--animation", str(animation), "--quiet"],
                   check=True)
    motion = {}
    for frame in range(frames[0], frames[1] + 1):
        image = oiio.ImageBuf(str(folder / f"trace.{frame:04d}.exr"))
        names = list(image.spec().channelnames)
        pixels = image.get_pixels(oiio.FLOAT)
        motion[frame] = np.stack([pixels[..., names.index(c)] for c in ("motion.X", "motion.Y")])
    return motion


def _input_channels(aov: np.ndarray, emitted: np.ndarray, camera: object,
                    motion: np.ndarray) -> dict[str, np.ndarray]:
    """The svgf preset's channels from the `aov` render (R G B A, albedo, sh_normal,
    position) and the emission render."""
    covered = aov[..., 3] > 0
    forward = np.asarray(camera.look_at, float) - np.asarray(camera.position, float)
    forward /= np.linalg.norm(forward)
    depth = np.where(covered, (aov[..., 10:13] - camera.position) @ forward, 0.0)
    channels = {c: aov[..., i] for i, c in enumerate("RGB")}
    channels.update({f"albedo.{c}": aov[..., 4 + i] for i, c in enumerate("RGB")})
    channels.update({f"N.{c}": aov[..., 7 + i] for i, c in enumerate("XYZ")})
    channels["Z"] = depth.astype(np.float32)
    channels.update({f"emission.{c}": emitted[..., i] for i, c in enumerate("RGB")})
    channels["motion.X"], channels["motion.Y"] = motion[0], motion[1]
    return channels


def main() -> None:
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    args = _args()
    scene_path, animation_path, frames = SCENES[args.scene]
    out = args.out or ROOT / "testdata" / "mitsuba" / args.scene
    first, last = (int(v) for v in (args.frames or frames).split("-"))
    scene = load_obj(scene_path)
    animation = load_animation(animation_path, [o.name for o in scene.objects])
    aov = {"type": "aov", "aovs": "albedo:albedo,nn:sh_normal,pp:position",
           "integrator": {"type": "path"}}
    out.mkdir(parents=True, exist_ok=True)
    attributes = {"generatedBy": f"Mitsuba {mi.__version__} (testdata/mitsuba/render.py)"}
    with tempfile.TemporaryDirectory() as tmp:
        motion = _motion(scene_path, animation_path, (first, last), Path(tmp))
        for frame in range(first, last + 1):
            camera = animation.camera(frame, WIDTH, HEIGHT)
            shapes = _shapes(mi, scene, animation, frame, Path(tmp))
            seed = args.seed * 100000 + frame
            noisy = _render(mi, shapes, camera, aov, 1, seed, args.pixel_filter)
            emitted = _render(mi, shapes, camera, {"type": "path", "max_depth": 1}, 1, seed,
                              args.pixel_filter)
            write_exr(out / f"in.{frame:04d}.exr",
                      _input_channels(noisy, emitted, camera, motion[frame]),
                      attributes=attributes)
            if args.ref_spp:
                ref = _render(mi, shapes, camera, {"type": "path"}, args.ref_spp,
                              seed + 50000, args.pixel_filter)
                write_exr(out / f"ref.{frame:04d}.exr",
                          {c: ref[..., i] for i, c in enumerate("RGB")},
                          attributes=attributes, half=True)
            print(f"frame {frame} done", flush=True)


if __name__ == "__main__":
    main()
