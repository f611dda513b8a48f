"""Camera, rigid object and emission animation from a small JSON file, evaluated per frame.

Format (every key optional except each keyframe's ``frame``)::

    {
      "camera": [
        {"frame": 1,  "position": [278, 273, 1359.2], "look_at": [278, 273, 279.6],
         "up": [0, 1, 0], "fov_y": 39.3},
        {"frame": 48, "position": [318, 283, 1359.2], "look_at": [278, 273, 279.6]}
      ],
      "objects": {
        "short_block": [
          {"frame": 1,  "translate": [0, 0, 0]},
          {"frame": 48, "translate": [120, 0, 0], "rotate": [0, 20, 0]}
        ],
        "tall_block": {"pivot": [368, 0, 351],
                       "keys": [{"frame": 1, "rotate": {"axis": [0, 1, 0], "angle": 0}},
                                {"frame": 9, "rotate": {"axis": [0, 1, 0], "angle": 90}}]},
        "light": [
          {"frame": 1, "translate": [0, 0, 0]},
          {"frame": 16, "translate": [-150, 0, 0]},
          {"frame": 9, "emission_scale": 1.0},
          {"frame": 10, "emission_scale": 0.45}
        ]
      }
    }

* Camera keys: ``position`` and ``look_at`` (world), ``up`` (default ``[0, 1, 0]``),
  ``fov_y`` vertical field of view in degrees (default 39.3). A key that omits a value keeps
  the previous key's.
* Object keys, by OBJ object/group name: ``translate`` ``[x, y, z]``; ``rotate`` either Euler
  degrees ``[rx, ry, rz]`` (about x, then y, then z, fixed axes) or ``{"axis": [...],
  "angle": degrees}``; ``scale`` a number or ``[sx, sy, sz]``. Rotation and scale act about
  the object's ``pivot`` (default: the centre of its bounding box in the OBJ). The matrix is
  ``T(translate) T(pivot) R S T(-pivot)``.
* Emission keys: ``emission_scale``, a number or ``[r, g, b]`` (>= 0), multiplies the
  object's ``Ke`` (every emissive triangle of the object); 1 where an object has no emission
  keys. Emission keys form their own track: a key with only ``emission_scale`` (and
  ``frame``) leaves the transform alone, a key with only transform fields leaves the
  emission alone, and a key may carry both. Emission is interpolated linearly like the
  rest, so a step is two keys on consecutive frames (``1.0`` at 9, ``0.45`` at 10: frame 10
  on is dimmed). Next-event estimation samples the lights with the frame's emission and
  the frame's (moved) geometry.
* Between keys: linear interpolation of vectors, fov and emission, quaternion slerp
  (shortest arc) of rotations, so keep successive rotation keys less than 180 degrees
  apart. Before the first and after the last key the end key holds. Fractional frames are
  allowed.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from svgf_cli.errors import InputError
from svgf_trace.camera import Camera

DEFAULT_FOV_Y = 39.3
TRANSFORM_FIELDS = ("translate", "rotate", "scale")


def quaternion_from_axis_angle(axis: np.ndarray, degrees: float) -> np.ndarray:
    """Unit quaternion (w, x, y, z)."""
    axis = np.asarray(axis, dtype=np.float64)
    norm = float(np.linalg.norm(axis))
    if norm == 0.0:
        return np.array([1.0, 0.0, 0.0, 0.0])
    half = math.radians(degrees) * 0.5
    return np.concatenate([[math.cos(half)], axis / norm * math.sin(half)])


def quaternion_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.array(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ]
    )


def quaternion_from_euler(degrees: np.ndarray) -> np.ndarray:
    """Rotation about x, then y, then z (fixed axes): q = qz * qy * qx."""
    rx, ry, rz = (float(d) for d in degrees)
    qx = quaternion_from_axis_angle(np.array([1.0, 0.0, 0.0]), rx)
    qy = quaternion_from_axis_angle(np.array([0.0, 1.0, 0.0]), ry)
    qz = quaternion_from_axis_angle(np.array([0.0, 0.0, 1.0]), rz)
    return quaternion_multiply(qz, quaternion_multiply(qy, qx))


def quaternion_to_matrix(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def slerp(a: np.ndarray, b: np.ndarray, t: float) -> np.ndarray:
    dot = float(np.dot(a, b))
    if dot < 0.0:
        b, dot = -b, -dot
    if dot > 0.9995:
        q = a + (b - a) * t
        return q / np.linalg.norm(q)
    theta = math.acos(min(dot, 1.0))
    s = math.sin(theta)
    return (math.sin((1 - t) * theta) * a + math.sin(t * theta) * b) / s


@dataclass(frozen=True)
class CameraKey:
    frame: float
    position: np.ndarray
    look_at: np.ndarray
    up: np.ndarray
    fov_y: float


@dataclass(frozen=True)
class TransformKey:
    frame: float
    translate: np.ndarray
    rotation: np.ndarray  # unit quaternion (w, x, y, z)
    scale: np.ndarray


@dataclass(frozen=True)
class EmissionKey:
    frame: float
    scale: np.ndarray  # (3,) multiplier of Ke


def _bracket(frames: list[float], frame: float) -> tuple[int, int, float]:
    """Indices of the keys around ``frame`` and the blend weight of the second."""
    if frame <= frames[0]:
        return 0, 0, 0.0
    if frame >= frames[-1]:
        last = len(frames) - 1
        return last, last, 0.0
    hi = int(np.searchsorted(frames, frame, side="right"))
    lo = hi - 1
    t = (frame - frames[lo]) / (frames[hi] - frames[lo])
    return lo, hi, t


class Animation:
    """Camera and per-object keyframes; ``Animation()`` is a static scene."""

    def __init__(
        self,
        camera_keys: list[CameraKey] | None = None,
        object_keys: dict[str, list[TransformKey]] | None = None,
        pivots: dict[str, np.ndarray] | None = None,
        emission_keys: dict[str, list[EmissionKey]] | None = None,
    ) -> None:
        self.camera_keys = sorted(camera_keys or [], key=lambda k: k.frame)
        self.object_keys = {
            name: sorted(keys, key=lambda k: k.frame) for name, keys in (object_keys or {}).items()
        }
        self.pivots = dict(pivots or {})
        self.emission_keys = {
            name: sorted(keys, key=lambda k: k.frame)
            for name, keys in (emission_keys or {}).items()
            if keys
        }

    @property
    def has_camera(self) -> bool:
        return bool(self.camera_keys)

    def camera(self, frame: float, width: int, height: int) -> Camera:
        keys = self.camera_keys
        lo, hi, t = _bracket([k.frame for k in keys], frame)
        a, b = keys[lo], keys[hi]
        return Camera(
            position=a.position + (b.position - a.position) * t,
            look_at=a.look_at + (b.look_at - a.look_at) * t,
            up=a.up + (b.up - a.up) * t,
            fov_y=a.fov_y + (b.fov_y - a.fov_y) * t,
            width=width,
            height=height,
        )

    def object_matrix(self, name: str, frame: float, pivot: np.ndarray) -> np.ndarray:
        """4x4 column-vector object-to-world matrix of ``name`` at ``frame`` (identity when
        the object is not animated)."""
        keys = self.object_keys.get(name)
        if not keys:
            return np.eye(4)
        lo, hi, t = _bracket([k.frame for k in keys], frame)
        a, b = keys[lo], keys[hi]
        translate = a.translate + (b.translate - a.translate) * t
        scale = a.scale + (b.scale - a.scale) * t
        rotation = a.rotation if lo == hi else slerp(a.rotation, b.rotation, t)
        pivot = self.pivots.get(name, pivot)
        linear = quaternion_to_matrix(rotation) * scale[None, :]
        matrix = np.eye(4)
        matrix[:3, :3] = linear
        matrix[:3, 3] = translate + pivot - linear @ pivot
        return matrix

    def emission_scale(self, name: str, frame: float) -> np.ndarray:
        """(3,) multiplier of the object's ``Ke`` at ``frame`` (ones when not keyed)."""
        keys = self.emission_keys.get(name)
        if not keys:
            return np.ones(3)
        lo, hi, t = _bracket([k.frame for k in keys], frame)
        a, b = keys[lo], keys[hi]
        return a.scale + (b.scale - a.scale) * t


def _vector(value: Any, where: str, path: Path, size: int = 3) -> np.ndarray:
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{where}: expected {size} numbers, got {value!r}", str(path)) from None
    if array.shape != (size,) or not np.all(np.isfinite(array)):
        raise InputError(f"{where}: expected {size} finite numbers, got {value!r}", str(path))
    return array


def _frame_of(key: Any, where: str, path: Path) -> float:
    if not isinstance(key, dict) or "frame" not in key:
        raise InputError(f"{where}: each keyframe needs a \"frame\"", str(path))
    try:
        frame = float(key["frame"])
    except (TypeError, ValueError):
        raise InputError(f"{where}: bad frame {key['frame']!r}", str(path)) from None
    if not math.isfinite(frame):
        raise InputError(f"{where}: bad frame {key['frame']!r}", str(path))
    return frame


def _emission(value: Any, where: str, path: Path) -> np.ndarray:
    raw = [value] * 3 if isinstance(value, (int, float)) else value
    scale = _vector(raw, f"{where}.emission_scale", path)
    if np.any(scale < 0.0):
        raise InputError(f"{where}.emission_scale: must not be negative, got {value!r}",
                         str(path))  # fmt: skip
    return scale


def _rotation(value: Any, where: str, path: Path) -> np.ndarray:
    if isinstance(value, dict):
        axis = _vector(value.get("axis"), f"{where}.axis", path)
        try:
            angle = float(value.get("angle", 0.0))
        except (TypeError, ValueError):
            raise InputError(f"{where}.angle: not a number", str(path)) from None
        return quaternion_from_axis_angle(axis, angle)
    return quaternion_from_euler(_vector(value, where, path))


def load_animation(path: str | Path, object_names: list[str]) -> Animation:
    """Parse an animation file; object names must exist in the scene (listed on error)."""
    path = Path(path)
    if not path.is_file():
        raise InputError("animation file not found", str(path))
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read animation: {exc}", str(path)) from exc
    except json.JSONDecodeError as exc:
        raise InputError(f"invalid JSON: {exc}", str(path)) from exc
    if not isinstance(data, dict):
        raise InputError("expected a JSON object with \"camera\" and/or \"objects\"", str(path))

    camera_keys: list[CameraKey] = []
    raw_camera = data.get("camera", [])
    if isinstance(raw_camera, dict):
        raw_camera = [{"frame": 0, **raw_camera}] if "frame" not in raw_camera else [raw_camera]
    if not isinstance(raw_camera, list):
        raise InputError("\"camera\" must be a list of keyframes", str(path))
    previous: dict[str, Any] = {"up": [0.0, 1.0, 0.0], "fov_y": DEFAULT_FOV_Y}
    for i, key in enumerate(raw_camera):
        where = f"camera[{i}]"
        frame = _frame_of(key, where, path)
        merged = {**previous, **key}
        for required in ("position", "look_at"):
            if required not in merged:
                raise InputError(f"{where}: missing \"{required}\"", str(path))
        try:
            fov_y = float(merged["fov_y"])
        except (TypeError, ValueError):
            raise InputError(f"{where}.fov_y: not a number", str(path)) from None
        if not 0.0 < fov_y < 180.0:
            raise InputError(f"{where}.fov_y: {fov_y} is not in (0, 180) degrees", str(path))
        position = _vector(merged["position"], f"{where}.position", path)
        look_at = _vector(merged["look_at"], f"{where}.look_at", path)
        up = _vector(merged["up"], f"{where}.up", path)
        forward = look_at - position
        if np.linalg.norm(forward) == 0.0 or np.linalg.norm(np.cross(forward, up)) == 0.0:
            raise InputError(f"{where}: position, look_at and up are degenerate", str(path))
        camera_keys.append(CameraKey(frame, position, look_at, up, fov_y))
        previous = merged

    object_keys: dict[str, list[TransformKey]] = {}
    emission_keys: dict[str, list[EmissionKey]] = {}
    pivots: dict[str, np.ndarray] = {}
    raw_objects = data.get("objects", {})
    if not isinstance(raw_objects, dict):
        raise InputError("\"objects\" must map object names to keyframes", str(path))
    for name, spec in raw_objects.items():
        if name not in object_names:
            known = ", ".join(object_names)
            raise InputError(f"object {name!r} is not in the scene (objects: {known})", str(path))
        keys = spec
        if isinstance(spec, dict):
            if "pivot" in spec:
                pivots[name] = _vector(spec["pivot"], f"objects.{name}.pivot", path)
            keys = spec.get("keys", [])
        if not isinstance(keys, list):
            raise InputError(f"objects.{name}: expected a list of keyframes", str(path))
        parsed: list[TransformKey] = []
        emission: list[EmissionKey] = []
        for i, key in enumerate(keys):
            where = f"objects.{name}[{i}]"
            frame = _frame_of(key, where, path)
            if "emission_scale" in key:
                emission.append(EmissionKey(frame, _emission(key["emission_scale"], where, path)))
                if not any(field in key for field in TRANSFORM_FIELDS):
                    continue
            translate = _vector(key.get("translate", [0, 0, 0]), f"{where}.translate", path)
            rotation = _rotation(key.get("rotate", [0, 0, 0]), f"{where}.rotate", path)
            raw_scale = key.get("scale", 1.0)
            if isinstance(raw_scale, (int, float)):
                raw_scale = [raw_scale] * 3
            scale = _vector(raw_scale, f"{where}.scale", path)
            parsed.append(TransformKey(frame, translate, rotation, scale))
        object_keys[name] = parsed
        emission_keys[name] = emission
    return Animation(camera_keys, object_keys, pivots, emission_keys)
