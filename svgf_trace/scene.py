"""OBJ + MTL scene loading at full precision.

The OBJ and MTL are parsed here rather than through ``trimesh.load``: trimesh's default load
merges faces by material, quantises ``Kd`` to 8-bit colour and keeps ``Ke`` only in the raw
``parse_mtl`` output, all of which lose what the tracer needs (float albedo and emission, the
object names that animation keyframes and mesh ids refer to). The format subset read:

* ``v x y z``, ``vt u v``, ``vn x y z``; ``f`` with ``v``, ``v/vt``, ``v//vn``, ``v/vt/vn``
  corners (negative indices count from the end); polygons are fan-triangulated in order;
* ``o NAME`` / ``g NAME`` start (or resume) the object called NAME; faces before either
  belong to an object named after the file;
* ``mtllib FILE...`` and ``usemtl NAME``; in the MTL: ``newmtl``, ``Kd``, ``Ke``, ``map_Kd``
  (the last token is the file; options before it are ignored), and for glossy materials
  ``Pr``, ``Pm``, ``Ns``, ``Ks``, ``illum`` (below). Everything else is ignored.

Materials are Lambertian unless they ask for a specular lobe (``svgf_trace.bsdf``):

* ``Pr`` (roughness, 0-1) or ``Pm`` (metallic, 0-1), the PBR extension of the MTL format
  that Blender's and other exporters write, make a material glossy: base colour ``Kd`` (x
  ``map_Kd``), roughness ``Pr`` (else from ``Ns`` if given, else 0.5), metallic ``Pm``
  (default 0).
* Without them, a material with a nonzero ``Ks`` and ``illum`` absent or >= 2 (the MTL
  illumination models with highlights) is a glossy dielectric with roughness from ``Ns``:
  ``r = 1 - sqrt(clamp(Ns, 0, 1000) / 1000)`` (Blender's OBJ importer's mapping; ``Ns``
  absent counts as 0, i.e. r = 1).
* Dielectric specular level: ``s = mean(Ks)`` when ``Ks`` is given, else 0.5; the
  dielectric reflectance at normal incidence is ``F0 = 0.08 s`` (0.04 for the default,
  IOR 1.5), as in Blender's Principled BSDF.

Triangles keep their winding: an emissive triangle emits on the side its counter-clockwise
winding faces, ``n = (v1 - v0) x (v2 - v0)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from svgf_cli.errors import InputError

DEFAULT_KD = (0.8, 0.8, 0.8)


DEFAULT_ROUGHNESS = 0.5
DEFAULT_SPECULAR = 0.5
# Blender's Principled BSDF: F0 = ((ior - 1) / (ior + 1))^2 * 2 * specular = 0.08 specular
# at the default IOR 1.5.
SPECULAR_TO_F0 = 0.08


@dataclass
class Material:
    """A Lambertian material, or a glossy one (GGX specular over a diffuse base, or a
    metal), with optional emission and an optional base-colour texture."""

    name: str
    kd: np.ndarray = field(default_factory=lambda: np.array(DEFAULT_KD))
    ke: np.ndarray = field(default_factory=lambda: np.zeros(3))
    texture: np.ndarray | None = None  # (H, W, 3) float32, linear, row 0 = top of image
    texture_path: Path | None = None
    glossy: bool = False
    roughness: float = DEFAULT_ROUGHNESS  # perceptual: GGX alpha = roughness^2
    metallic: float = 0.0
    specular: float = DEFAULT_SPECULAR  # dielectric F0 = 0.08 specular

    @property
    def emissive(self) -> bool:
        return bool(np.any(self.ke > 0.0))

    @property
    def dielectric_f0(self) -> float:
        return min(SPECULAR_TO_F0 * self.specular, 1.0)


@dataclass
class _MtlKeys:
    """The glossy-related keys of one MTL material as read, resolved by ``_resolve``."""

    pr: float | None = None
    pm: float | None = None
    ns: float | None = None
    ks: np.ndarray | None = None
    illum: int | None = None


def _resolve(material: Material, keys: _MtlKeys) -> None:
    """Decide whether a material is glossy and with which parameters (module docstring)."""
    from_ns = None
    if keys.ns is not None:
        from_ns = 1.0 - float(np.sqrt(min(max(keys.ns, 0.0), 1000.0) / 1000.0))
    if keys.ks is not None:
        material.specular = float(np.mean(keys.ks))
    if keys.pr is not None or keys.pm is not None:
        material.glossy = True
        if keys.pr is not None:
            material.roughness = keys.pr
        elif from_ns is not None:
            material.roughness = from_ns
        material.metallic = keys.pm if keys.pm is not None else 0.0
    elif (
        keys.ks is not None
        and float(np.max(keys.ks)) > 0.0
        and (keys.illum is None or keys.illum >= 2)
    ):
        material.glossy = True
        material.roughness = from_ns if from_ns is not None else 1.0
        material.metallic = 0.0


@dataclass
class SceneObject:
    """One OBJ object/group: a name (animation key) and its triangles ``[start, stop)``."""

    name: str
    index: int
    start: int
    stop: int


@dataclass
class Scene:
    """Triangle soup in object (file) space, structure of arrays, float64.

    ``positions``, ``normals``: ``(T, 3, 3)`` (triangle, corner, xyz); ``uvs``: ``(T, 3, 2)``;
    ``has_normals``/``has_uvs``: ``(T,)`` bool; ``material``/``object_index``: ``(T,)`` int32.
    Triangles of one object are contiguous (``SceneObject.start:stop``).
    """

    path: Path
    positions: np.ndarray
    normals: np.ndarray
    has_normals: np.ndarray
    uvs: np.ndarray
    has_uvs: np.ndarray
    material: np.ndarray
    object_index: np.ndarray
    materials: list[Material]
    objects: list[SceneObject]

    @property
    def triangle_count(self) -> int:
        return int(self.positions.shape[0])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        flat = self.positions.reshape(-1, 3)
        return flat.min(axis=0), flat.max(axis=0)

    def object_by_name(self, name: str) -> SceneObject | None:
        for obj in self.objects:
            if obj.name == name:
                return obj
        return None


def _floats(tokens: list[str], count: int, path: Path, line_no: int, what: str) -> list[float]:
    try:
        values = [float(t) for t in tokens[:count]]
    except ValueError:
        raise InputError(f"line {line_no}: bad number in {what}", str(path)) from None
    if len(values) < count:
        raise InputError(f"line {line_no}: {what} needs {count} numbers", str(path))
    return values


def srgb_to_linear(values: np.ndarray) -> np.ndarray:
    """The sRGB transfer function inverted (8/16-bit textures are stored sRGB-encoded)."""
    v = np.asarray(values, dtype=np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def load_texture(path: Path, material: str, mtl_path: Path) -> np.ndarray:
    """An (H, W, 3) float32 linear texture; integer formats are decoded from sRGB."""
    if not path.is_file():
        raise InputError(
            f"texture not found: {path} (map_Kd of material {material!r})", str(mtl_path)
        )
    import OpenImageIO as oiio  # imported here: only scenes with textures need it

    image = oiio.ImageInput.open(str(path))
    if image is None:
        raise InputError(f"cannot read texture {path}: {oiio.geterror()}", str(mtl_path))
    try:
        spec = image.spec()
        is_integer = spec.format.basetype in (oiio.UINT8, oiio.UINT16, oiio.INT8, oiio.INT16)
        pixels = image.read_image(0, 0, 0, spec.nchannels, "float")
    finally:
        image.close()
    if pixels is None or pixels.size == 0:
        raise InputError(f"cannot read texture {path}", str(mtl_path))
    pixels = np.asarray(pixels, dtype=np.float64).reshape(spec.height, spec.width, -1)
    channels = pixels.shape[2]
    rgb = np.repeat(pixels[:, :, :1], 3, axis=2) if channels < 3 else pixels[:, :, :3]
    if is_integer:
        rgb = srgb_to_linear(rgb)
    return np.ascontiguousarray(rgb, dtype=np.float32)


def parse_mtl(path: Path, materials: dict[str, Material]) -> None:
    """Read every material of one MTL file into ``materials`` (values at full precision)."""
    if not path.is_file():
        raise InputError("material library not found", str(path))
    current: Material | None = None
    textures: dict[str, Path] = {}
    glossy_keys: dict[str, _MtlKeys] = {}

    def unit(args: list[str], line_no: int, what: str) -> float:
        value = _floats(args, 1, path, line_no, what)[0]
        if not 0.0 <= value <= 1.0:
            raise InputError(f"line {line_no}: {what} {value} is not in [0, 1]", str(path))
        return value
    for line_no, raw in enumerate(path.read_text(errors="replace").splitlines(), start=1):
        tokens = raw.split("#", 1)[0].split()
        if not tokens:
            continue
        key, args = tokens[0], tokens[1:]
        if key == "newmtl":
            name = " ".join(args)
            current = Material(name=name)
            materials[name] = current
            glossy_keys[name] = _MtlKeys()
        elif current is None:
            continue
        elif key == "Kd":
            current.kd = np.array(_floats(args, 3, path, line_no, "Kd"))
        elif key == "Ke":
            current.ke = np.array(_floats(args, 3, path, line_no, "Ke"))
        elif key == "Pr":
            glossy_keys[current.name].pr = unit(args, line_no, "Pr")
        elif key == "Pm":
            glossy_keys[current.name].pm = unit(args, line_no, "Pm")
        elif key == "Ns":
            glossy_keys[current.name].ns = _floats(args, 1, path, line_no, "Ns")[0]
        elif key == "Ks":
            ks = np.array(_floats(args[:3] if len(args) >= 3 else args * 3, 3, path, line_no,
                                  "Ks"))  # fmt: skip
            if np.any(ks < 0.0):
                raise InputError(f"line {line_no}: Ks must not be negative", str(path))
            glossy_keys[current.name].ks = ks
        elif key == "illum":
            try:
                glossy_keys[current.name].illum = int(args[0])
            except (IndexError, ValueError):
                raise InputError(f"line {line_no}: bad illum", str(path)) from None
        elif key == "map_Kd":
            if not args:
                raise InputError(f"line {line_no}: map_Kd without a file name", str(path))
            textures[current.name] = path.parent / args[-1]
    for name, keys in glossy_keys.items():
        _resolve(materials[name], keys)
    for name, texture_path in textures.items():
        material = materials[name]
        material.texture_path = texture_path
        material.texture = load_texture(texture_path, name, path)


def _corner(token: str, counts: tuple[int, int, int], path: Path, line_no: int) -> tuple[int, ...]:
    """``v/vt/vn`` -> zero-based (v, vt, vn) with -1 for absent; negatives count from the end."""
    parts = token.split("/")
    out = []
    for slot in range(3):
        text = parts[slot] if slot < len(parts) else ""
        if not text:
            if slot == 0:
                raise InputError(f"line {line_no}: face corner {token!r} has no vertex", str(path))
            out.append(-1)
            continue
        try:
            index = int(text)
        except ValueError:
            raise InputError(f"line {line_no}: bad face index {token!r}", str(path)) from None
        resolved = index - 1 if index > 0 else counts[slot] + index
        if index == 0 or not 0 <= resolved < counts[slot]:
            kind = ("vertex", "texture coordinate", "normal")[slot]
            raise InputError(
                f"line {line_no}: {kind} index {index} out of range (have {counts[slot]})",
                str(path),
            )
        out.append(resolved)
    return tuple(out)


# Triangles grouped by object name in first-appearance order: name -> list of
# (corner indices (3 x (v, vt, vn)), material name).
_Groups = dict[str, list[tuple[tuple[tuple[int, ...], ...], str | None]]]


@dataclass
class _ObjRecords:
    """What an OBJ file lists, as parsed: vertex data, materials and grouped triangles."""

    verts: list[list[float]] = field(default_factory=list)
    texcoords: list[list[float]] = field(default_factory=list)
    normals: list[list[float]] = field(default_factory=list)
    materials: dict[str, Material] = field(default_factory=dict)
    groups: _Groups = field(default_factory=dict)


def _read_scene_text(path: Path) -> str:
    if not path.is_file():
        raise InputError("scene file not found", str(path))
    try:
        return path.read_text(errors="replace")
    except OSError as exc:
        raise InputError(f"cannot read scene: {exc.strerror}", str(path)) from exc


def _parse_obj(text: str, path: Path) -> _ObjRecords:
    """Parse the OBJ lines (and the MTL files they name); faces fan-triangulated."""
    obj = _ObjRecords()
    current_object = path.stem
    current_material: str | None = None

    for line_no, raw in enumerate(text.splitlines(), start=1):
        tokens = raw.split("#", 1)[0].split()
        if not tokens:
            continue
        key, args = tokens[0], tokens[1:]
        if key == "v":
            obj.verts.append(_floats(args, 3, path, line_no, "v"))
        elif key == "vt":
            uv = _floats(args, 1, path, line_no, "vt")
            v_coord = float(args[1]) if len(args) > 1 else 0.0
            obj.texcoords.append([uv[0], v_coord])
        elif key == "vn":
            obj.normals.append(_floats(args, 3, path, line_no, "vn"))
        elif key == "f":
            if len(args) < 3:
                raise InputError(f"line {line_no}: face with fewer than 3 corners", str(path))
            counts = (len(obj.verts), len(obj.texcoords), len(obj.normals))
            corners = [_corner(t, counts, path, line_no) for t in args]
            tris = obj.groups.setdefault(current_object, [])
            for i in range(1, len(corners) - 1):
                tris.append(((corners[0], corners[i], corners[i + 1]), current_material))
        elif key in ("o", "g"):
            current_object = " ".join(args) if args else path.stem
        elif key == "usemtl":
            current_material = " ".join(args)
        elif key == "mtllib":
            for name in args:
                parse_mtl(path.parent / name, obj.materials)
    return obj


@dataclass
class _Triangles:
    """The triangles numbered object by object: corner indices, material and object."""

    corner_idx: np.ndarray  # (T, 3, 3) int64 (v, vt, vn) per corner, -1 absent
    material: np.ndarray  # (T,) int32 index into ``materials``
    object_index: np.ndarray  # (T,) int32
    objects: list[SceneObject]
    materials: list[Material]  # in first-use order; "(default)" for faces without usemtl


def _number_triangles(obj: _ObjRecords, triangle_total: int, path: Path) -> _Triangles:
    """Lay the grouped triangles out in arrays; InputError for an undefined material."""
    material_index: dict[str | None, int] = {}
    material_list: list[Material] = []

    def index_of(name: str | None) -> int:
        if name not in material_index:
            if name is None:
                material = Material(name="(default)")
            elif name in obj.materials:
                material = obj.materials[name]
            else:
                raise InputError(f"material {name!r} is used but not defined", str(path))
            material_index[name] = len(material_list)
            material_list.append(material)
        return material_index[name]

    corner_idx = np.empty((triangle_total, 3, 3), dtype=np.int64)
    mat = np.empty(triangle_total, dtype=np.int32)
    obj_idx = np.empty(triangle_total, dtype=np.int32)
    objects: list[SceneObject] = []
    cursor = 0
    for obj_number, (name, tris) in enumerate((n, t) for n, t in obj.groups.items() if t):
        start = cursor
        for corners, material_name in tris:
            corner_idx[cursor] = corners
            mat[cursor] = index_of(material_name)
            obj_idx[cursor] = obj_number
            cursor += 1
        objects.append(SceneObject(name=name, index=obj_number, start=start, stop=cursor))
    return _Triangles(corner_idx, mat, obj_idx, objects, material_list)


def load_obj(path: str | Path) -> Scene:
    """Load an OBJ (and the MTL files it names) into a :class:`Scene`.

    Raises InputError for a missing or unreadable file, a malformed line, a missing material
    library or texture (named), an undefined material, or a file without triangles.
    """
    path = Path(path)
    obj = _parse_obj(_read_scene_text(path), path)

    triangle_total = sum(len(t) for t in obj.groups.values())
    if triangle_total == 0:
        raise InputError("scene has no faces (empty mesh)", str(path))

    v_arr = np.asarray(obj.verts, dtype=np.float64).reshape(-1, 3)
    vt_arr = np.asarray(obj.texcoords, dtype=np.float64).reshape(-1, 2)
    vn_arr = np.asarray(obj.normals, dtype=np.float64).reshape(-1, 3)
    triangles = _number_triangles(obj, triangle_total, path)
    corner_idx = triangles.corner_idx

    positions = v_arr[corner_idx[:, :, 0]]
    has_uvs = np.all(corner_idx[:, :, 1] >= 0, axis=1)
    uvs = np.zeros((triangle_total, 3, 2))
    if len(vt_arr):
        uvs[has_uvs] = vt_arr[corner_idx[has_uvs][:, :, 1]]
    has_normals = np.all(corner_idx[:, :, 2] >= 0, axis=1)
    tri_normals = np.zeros((triangle_total, 3, 3))
    if len(vn_arr):
        tri_normals[has_normals] = vn_arr[corner_idx[has_normals][:, :, 2]]
        lengths = np.linalg.norm(tri_normals, axis=2)
        # A zero-length vn cannot shade: fall back to the geometric normal for that triangle.
        has_normals &= np.all(lengths > 0.0, axis=1)
    if not np.all(np.isfinite(positions)):
        raise InputError("scene has non-finite vertex coordinates", str(path))

    return Scene(
        path=path,
        positions=positions,
        normals=tri_normals,
        has_normals=has_normals,
        uvs=uvs,
        has_uvs=has_uvs,
        material=triangles.material,
        object_index=triangles.object_index,
        materials=triangles.materials,
        objects=triangles.objects,
    )
