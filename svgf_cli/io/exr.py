"""OpenEXR reading and writing. Knows files and channels, not filtering.

Headers and writing go through OpenImageIO; pixel decoding through the OpenEXR library's
Python bindings, which decode the same file with about a third of the CPU time.

Reading: `read_info` (header only), `read_frame` (the roles a `LayerMapping` resolves to, as
a `Frame`), `read_rgb` (plain R,G,B). Writing: `write_exr` (atomic, checked), with
`check_compression` refusing lossy codecs on data channels.
"""

from __future__ import annotations

import contextlib
import math
import os
from collections.abc import Collection, Iterable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import OpenEXR
import OpenImageIO as oiio

from svgf_cli.errors import InputError, SvgfError, UsageError
from svgf_cli.frame import Frame, Signal
from svgf_cli.halfconv import gather_float32
from svgf_cli.io import atomic
from svgf_cli.io.colour import LuminanceWeights, luminance_weights
from svgf_cli.io.layers import (
    RADIANCE_ROLES,
    REQUIRED_ROLES,
    LayerMapping,
    ResolvedLayers,
    build_mapping,
    describe_output_colour,
    resolve_layers,
    resolve_output_colour,
    to_backward_pixels,
    to_next_pixels,
)
from svgf_cli.io.signals import (
    CHECK_SHARE,
    SignalPlan,
    SumCheck,
    check_sum,
    compose_signals,
    plan_signals,
)
from svgf_cli.io.source import SourceFile, SourcePart, decode_source, one_line


class ExrWriteError(SvgfError):
    """An output could not be written (nothing is left behind under the final name)."""


def temporary_path(path: Path) -> Path:
    """Hidden, unique sibling name used while writing (see `svgf_cli.io.atomic`)."""
    return atomic.temporary_path(path)


def check_output_path(path: Path) -> None:
    """Refuse, with the real reason, an output path that cannot be written as a file."""
    if path.is_dir():
        raise ExrWriteError("cannot write: is a directory", str(path))
    parent = path.parent
    if not parent.exists():
        raise ExrWriteError(f"cannot write: folder {parent} does not exist", str(path))
    if not parent.is_dir():
        raise ExrWriteError(f"cannot write: {parent} is not a directory", str(path))


def output_error(exc: OSError, path: Path) -> ExrWriteError:
    """An OSError while writing ``path`` as a one-line ExrWriteError naming the real cause."""
    reason = exc.strerror or str(exc)
    if isinstance(exc, IsADirectoryError) or path.is_dir():
        reason = "is a directory"
    elif isinstance(exc, FileNotFoundError) and not path.parent.is_dir():
        reason = f"folder {path.parent} does not exist"
    return ExrWriteError(f"cannot write: {reason}", str(path))


def write_exr(
    path: str | os.PathLike[str],
    channels: Mapping[str, np.ndarray],
    *,
    attributes: Mapping[str, Any] | None = None,
    half: Mapping[str, bool] | bool = False,
    compression: str = "zip",
) -> None:
    """Write ``channels`` (name -> (H, W) plane) to one EXR part, atomically.

    ``half`` is either one flag for all channels or a per-channel mapping (missing names are
    float). Attributes are passed through as header attributes; values OpenImageIO cannot
    store are skipped. The file is written to a temporary name and renamed, so the final name
    only ever holds a complete file; every OpenImageIO return value is checked.
    """
    path = Path(path)
    names = list(channels)
    if not names:
        raise ExrWriteError("no channels to write", str(path))
    planes = [np.asarray(channels[n], dtype=np.float32) for n in names]
    h, w = planes[0].shape
    for n, p in zip(names, planes, strict=True):
        if p.shape != (h, w):
            raise ExrWriteError(f"channel {n} has shape {p.shape}, expected {(h, w)}", str(path))
    # One contiguous (H, W, C) float32 buffer: OpenImageIO silently writes a header-only
    # file for non-contiguous arrays, so never hand it a view.
    pixels = np.ascontiguousarray(np.stack(planes, axis=-1), dtype=np.float32)

    def is_half(name: str) -> bool:
        return bool(half) if isinstance(half, bool) else bool(half.get(name, False))

    if all(is_half(n) for n in names):
        # All-half (the denoised RGBA default): convert in numpy and hand OpenImageIO a half
        # buffer. Its own float->half conversion measured 0.67 s against 0.43 s for a float
        # write of 1080p RGBA; numpy rounds to nearest-even exactly as OpenEXR's half does.
        with np.errstate(over="ignore"):  # above 65504 becomes inf, as in OpenEXR's half
            pixels = pixels.astype(np.float16)
        spec = oiio.ImageSpec(w, h, len(names), oiio.TypeDesc("half"))
        spec.channelnames = tuple(names)
    else:
        formats = [oiio.TypeDesc("half") if is_half(n) else oiio.TypeDesc("float") for n in names]
        spec = oiio.ImageSpec(w, h, len(names), oiio.TypeDesc("float"))
        spec.channelnames = tuple(names)
        spec.channelformats = tuple(formats)
    check_compression(compression, names, float_channels=[n for n in names if not is_half(n)])
    spec.attribute("compression", compression)
    # OpenImageIO stamps the current time as DateTime unless one is given; an empty value
    # suppresses it, so the same inputs give byte-identical files. A passed-through
    # DateTime (the render's) still wins.
    spec.attribute("DateTime", "")
    for key, value in (attributes or {}).items():
        _set_attribute(spec, key, value)

    check_output_path(path)

    def write(tmp: Path) -> None:
        out = oiio.ImageOutput.create(str(tmp))
        if out is None:
            raise ExrWriteError(f"cannot create EXR writer: {oiio.geterror()}", str(path))
        try:
            if not out.open(str(tmp), spec):
                raise ExrWriteError(f"cannot open for writing: {_one_line(out.geterror())}",
                                    str(path))
            if not out.write_image(pixels):
                raise ExrWriteError(f"write failed: {_one_line(out.geterror())}", str(path))
        finally:
            closed = out.close()
        if not closed:
            raise ExrWriteError(f"close failed: {_one_line(out.geterror())}", str(path))

    try:
        atomic.write_atomically(path, write)
    except OSError as exc:
        raise output_error(exc, path) from None


def _set_attribute(spec: oiio.ImageSpec, key: str, value: Any) -> None:
    """Set one header attribute, choosing the EXR type from the Python value.

    An attribute OpenImageIO cannot store is dropped rather than failing the write.
    """
    with contextlib.suppress(Exception):
        if isinstance(value, TypedAttribute):
            spec.attribute(key, oiio.TypeDesc(value.type_name), value.value)
        elif isinstance(value, (bool, int, np.integer)):
            spec.attribute(key, int(value))
        elif isinstance(value, (float, np.floating)):
            spec.attribute(key, float(value))
        elif isinstance(value, str):
            spec.attribute(key, value)
        elif isinstance(value, np.ndarray) and value.shape == (4, 4):
            spec.attribute(key, oiio.TypeDesc("matrix"), tuple(float(v) for v in value.ravel()))
        elif isinstance(value, (tuple, list)) and len(value) == 16:
            spec.attribute(key, oiio.TypeDesc("matrix"), tuple(float(v) for v in value))
        else:
            spec.attribute(key, value)


# ---------------------------------------------------------------------------------------------
# Compression rules

LOSSLESS_COMPRESSIONS = ("none", "rle", "zips", "zip", "piz")
# Lossy for every channel: B44 quantises half data; DWA's DCT hits every channel whose name
# ends in R, G, B, Y, RY or BY (so N.Y and motion.Y), which is why it is refused wholesale.
LOSSY_COMPRESSIONS = ("b44", "b44a", "dwaa", "dwab")
# PXR24 is exact for half and 16/32-bit integers but rounds float32 to 24 bits.
FLOAT_LOSSY_COMPRESSIONS = ("pxr24",)
COMPRESSIONS = LOSSLESS_COMPRESSIONS + FLOAT_LOSSY_COMPRESSIONS + LOSSY_COMPRESSIONS

_COLOUR_CHANNELS = frozenset("RGBA")


def is_colour_channel(name: str) -> bool:
    """``R``, ``G``, ``B``, ``A`` or a layer's ``*.R/*.G/*.B/*.A``: may be stored lossily."""
    return name.rpartition(".")[2] in _COLOUR_CHANNELS


def compression_name(compression: str) -> str:
    """``"dwaa:45"`` -> ``"dwaa"``; raises UsageError for a name OpenEXR does not have."""
    base = compression.strip().lower().partition(":")[0]
    if base not in COMPRESSIONS:
        raise UsageError(
            f"unknown EXR compression {compression!r} (choose from {', '.join(COMPRESSIONS)})"
        )
    return base


def check_compression(
    compression: str,
    channel_names: Iterable[str],
    *,
    float_channels: Collection[str] | None = None,
) -> None:
    """Refuse a lossy codec when data channels (normals, depth, motion, ids...) are written.

    Colour channels (``R,G,B,A`` and ``*.R/*.G/*.B/*.A``) may be lossy. ``pxr24`` is refused
    only when a data channel is float (``float_channels`` None means all are float).
    """
    base = compression_name(compression)
    data = [n for n in channel_names if not is_colour_channel(n)]
    if base in LOSSY_COMPRESSIONS and data:
        raise UsageError(
            f"compression {base} is lossy and would corrupt data channel(s) "
            f"{', '.join(data[:6])}{' ...' if len(data) > 6 else ''}; use zip, zips or piz"
        )
    if base in FLOAT_LOSSY_COMPRESSIONS:
        floats = data if float_channels is None else [n for n in data if n in float_channels]
        if floats:
            raise UsageError(
                f"compression {base} rounds float data channel(s) {', '.join(floats[:6])} "
                "to 24 bits; use zip, zips or piz"
            )


# ---------------------------------------------------------------------------------------------
# Reading

# Header attributes that describe the file's structure rather than its content: a writer
# sets its own, so they are not passed through.
_STRUCTURAL_ATTRIBUTES = frozenset(
    {
        "channels",
        "compression",
        "dataWindow",
        "displayWindow",
        "tiles",
        "chunkCount",
        "lineOrder",
        "type",
        "name",
        "version",
        "planarconfig",
        "textureformat",
        "wrapmodes",
        "fovcot",
    }
)
_STRUCTURAL_PREFIXES = ("oiio:", "openexr:")

# Depth at or beyond this is background: Cycles writes 1e10 and Arnold huge values there.
FAR_DEPTH = 1e9



@dataclass(frozen=True)
class TypedAttribute:
    """A header attribute with an explicit OIIO type (``float2``, ``int[4]``, ``timecode``...)."""

    type_name: str
    value: Any


@dataclass
class ExrPart:
    """One part (OIIO subimage) of an EXR file."""

    index: int
    name: str
    channels: list[str]
    channel_types: list[str]
    data_window: tuple[int, int, int, int]  # x, y, width, height
    compression: str
    tiled: bool = False


@dataclass
class ExrInfo:
    """What the header says: size, channels of every part, pass-through attributes."""

    path: Path
    width: int
    height: int
    channels: list[str]
    channel_types: list[str]
    attributes: dict[str, Any]
    compression: str
    parts: list[str]
    part_info: list[ExrPart] = field(default_factory=list)
    display_window: tuple[int, int, int, int] = (0, 0, 0, 0)
    views: list[str] = field(default_factory=list)  # multi-view (stereo) files only
    chromaticities: tuple[float, ...] | None = None

    def channel_type(self, name: str) -> str:
        return self.channel_types[self.channels.index(name)]

    @property
    def luminance_weights(self) -> LuminanceWeights:
        return luminance_weights(self.chromaticities)


@dataclass
class ReadResult:
    """A decoded frame plus everything a caller may want to log or pass through.

    ``source`` is the whole decoded file (every part and channel, as stored) for writing a
    drop-in replacement; ``colour_channels`` are the names the denoised colour is written
    under (the input's colour layer; None: the file has none, write ``R,G,B``).
    """

    frame: Frame
    alpha: np.ndarray | None
    info: ExrInfo
    resolved: ResolvedLayers
    warnings: list[str]
    source: SourceFile | None = None
    colour_channels: tuple[str, str, str] | None = None
    luminance_weights: LuminanceWeights = field(
        default_factory=lambda: luminance_weights(None)
    )
    # The signal set read (its plan), the light-pass check of a set built from lobe passes
    # (None: not checked), and the warning the check gave (also in ``warnings``).
    plan: SignalPlan | None = None
    sum_check: SumCheck | None = None
    signal_warning: str | None = None


# Threads the OpenEXR decoder may use per file (0: decode in the calling thread).
_decode_threads = 0


def set_io_threads(threads: int) -> None:
    """Threads for EXR decoding and encoding, in OpenImageIO and in the OpenEXR library's
    global pool (0 = OpenImageIO's default of all cores; OpenEXR single-threaded)."""
    global _decode_threads
    oiio.attribute("threads", int(threads))
    oiio.attribute("exr_threads", int(threads))
    _decode_threads = max(0, int(threads))
    if OpenEXR.global_thread_count() < _decode_threads:
        OpenEXR.set_global_thread_count(_decode_threads)


def io_threads() -> int:
    """The thread count `set_io_threads` last set for the OpenEXR library (0: none)."""
    return _decode_threads


def _one_line(message: str) -> str:
    """OpenImageIO's (often repeated, multi-line) error text as one short line."""
    return one_line(message)


def _oiio_error(source: Any = None) -> str:
    """OpenImageIO's last error as one line; its bindings raise on undecodable bytes (a
    corrupt header quoted in the message), which must not hide the error itself."""
    try:
        text = (source or oiio).geterror()
    except UnicodeDecodeError:
        return "corrupt header (its text is not UTF-8)"
    return _one_line(text)


def _open(path: Path) -> oiio.ImageInput:
    """Open ``path`` for reading or raise InputError naming the file and the reason."""
    if not path.exists():
        raise InputError("file not found", str(path))
    if path.is_dir():
        raise InputError("is a directory, not an EXR file", str(path))
    try:
        with open(path, "rb") as handle:
            magic = handle.read(4)
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", str(path)) from exc
    if magic != b"\x76\x2f\x31\x01":
        raise InputError("not an OpenEXR file (bad magic number)", str(path))
    image = oiio.ImageInput.open(str(path))
    if image is None:
        raise InputError(f"cannot open EXR: {_oiio_error()}", str(path))
    return image


def _attribute_value(attr: Any) -> Any:
    """A header attribute as a Python value `write_exr` can write back unchanged."""
    type_name = str(attr.type)
    value = attr.value
    if type_name in ("string", "int", "float"):
        return value
    if type_name == "matrix":
        return np.asarray(value, dtype=np.float32).reshape(4, 4)
    return TypedAttribute(type_name, value)


def _header_attributes(spec: oiio.ImageSpec) -> dict[str, Any]:
    attributes: dict[str, Any] = {}
    for attr in spec.extra_attribs:
        name = attr.name
        if name in _STRUCTURAL_ATTRIBUTES or name.startswith(_STRUCTURAL_PREFIXES):
            continue
        attributes[name] = _attribute_value(attr)
    return attributes


def _channel_types(spec: oiio.ImageSpec) -> list[str]:
    formats = list(spec.channelformats)
    if not formats:
        return [str(spec.format)] * spec.nchannels
    return [str(f) for f in formats]


def _not_utf8(text: str) -> bool:
    """OpenImageIO hands undecodable header bytes over as lone surrogates."""
    return any("\udc80" <= ch <= "\udcff" for ch in text)


def _check_text(path: Path, what: str, text: Any) -> None:
    values = text if isinstance(text, (tuple, list)) else (text,)
    for value in values:
        if isinstance(value, str) and _not_utf8(value):
            shown = value.encode("utf-8", "surrogateescape").decode("latin-1")
            raise InputError(f"header holds text that is not UTF-8 ({what} {shown!r})", str(path))


def _views(specs: list[oiio.ImageSpec]) -> list[str]:
    """The views of a multi-view file: ``multiView`` (single part) or the parts' ``view``."""
    listed = specs[0].getattribute("multiView")
    if isinstance(listed, (tuple, list)) and len(listed) > 1:
        return [str(v) for v in listed]
    views = [spec.get_string_attribute("view") for spec in specs]
    distinct = list(dict.fromkeys(v for v in views if v))
    return distinct if len(distinct) > 1 else []


def _read_header(image: oiio.ImageInput, path: Path) -> ExrInfo:
    parts: list[ExrPart] = []
    specs: list[oiio.ImageSpec] = []
    index = 0
    while image.seek_subimage(index, 0):
        spec = image.spec().copy()
        name = spec.get_string_attribute("oiio:subimagename") or ""
        if spec.deep:
            shown = f" (part {index}{f' {name!r}' if name else ''})"
            raise InputError(f"deep EXR parts are not supported{shown}", str(path))
        _check_text(path, "part name", name)
        _check_text(path, "channel name", list(spec.channelnames))
        for attr in spec.extra_attribs:
            _check_text(path, f"attribute {attr.name}", attr.value)
        specs.append(spec)
        parts.append(
            ExrPart(
                index=index,
                name=name,
                channels=list(spec.channelnames),
                channel_types=_channel_types(spec),
                data_window=(spec.x, spec.y, spec.width, spec.height),
                compression=spec.get_string_attribute("compression") or "none",
                tiled=spec.tile_width > 0,
            )
        )
        index += 1
    if not specs:
        raise InputError(f"no readable part: {_oiio_error(image)}", str(path))
    first_spec = specs[0]
    chromaticities = first_spec.getattribute("chromaticities")
    channels = [name for part in parts for name in part.channels]
    types = [t for part in parts for t in part.channel_types]
    return ExrInfo(
        path=path,
        width=first_spec.width,
        height=first_spec.height,
        channels=channels,
        channel_types=types,
        attributes=_header_attributes(first_spec),
        compression=parts[0].compression,
        parts=[part.name for part in parts],
        part_info=parts,
        display_window=(
            first_spec.full_x,
            first_spec.full_y,
            first_spec.full_width,
            first_spec.full_height,
        ),
        views=_views(specs),
        chromaticities=(
            tuple(float(v) for v in chromaticities)
            if isinstance(chromaticities, (tuple, list)) and len(chromaticities) == 8
            else None
        ),
    )


def read_info(path: str | os.PathLike[str]) -> ExrInfo:
    """Read only the header(s). InputError for a missing, non-EXR or corrupt file."""
    path = Path(path)
    image = _open(path)
    try:
        return _read_header(image, path)
    except UnicodeError as exc:
        raise InputError(f"header holds text that is not UTF-8 ({exc})", str(path)) from None
    finally:
        image.close()


def refuse_multiview(info: ExrInfo) -> None:
    """A stereo/multi-view file is refused rather than silently denoised for one view."""
    if info.views:
        raise InputError(
            f"multi-view (stereo) file with views {', '.join(info.views)}: svgf denoises one "
            "view per sequence; write one file per view (e.g. with oiiotool) and denoise each",
            str(info.path),
        )


class _Planes:
    """Role planes gathered from a decoded file, as float32 arrays."""

    def __init__(self, source: SourceFile, located: dict[str, SourcePart]) -> None:
        self.source = source
        self.located = located

    def gather(self, names: tuple[str, ...]) -> np.ndarray:
        """(len(names), H, W) float32, C-contiguous (a copy: the source stays as read)."""
        return gather_float32([self.located[name].channels[name].pixels for name in names])

    def locate_like(self, names: tuple[str, ...], like: str) -> bool:
        """Locate ``names`` (not asked for when the file was read) in a part with the same
        data window as the part holding ``like``, full-resolution; False where one is not."""
        window = self.located[like].data_window
        for name in names:
            for part in self.source.parts:
                channel = part.channels.get(name)
                if (channel is not None and part.data_window == window
                        and channel.x_sampling == 1 and channel.y_sampling == 1):
                    self.located[name] = part
                    break
            else:
                return False
        return True

    def share(self, names: tuple[str, ...], stacked: np.ndarray) -> None:
        """The source's float32 channels ``names`` become views of ``stacked`` (which holds
        the same values), so a frame's planes are not held twice while it is written.

        The frame's planes are then also the bytes passed through to the output: consumers
        must not modify a Frame in place (the Denoiser copies what it keeps).
        """
        for index, name in enumerate(names):
            channel = self.located[name].channels[name]
            if channel.pixels is not None and channel.pixels.dtype == np.float32:
                channel.pixels = stacked[index]


def _read_channels(
    info: ExrInfo, names: Iterable[str], also_in_window: Iterable[str] = ()
) -> _Planes:
    """Decode the whole file (every part, every channel) and locate ``names`` in it.

    Pixels are decoded by the OpenEXR library's own reader, not OpenImageIO's: measured on
    a ZIP 1080p frame of 26 float channels, 0.47 CPU-seconds against 0.8 s for
    OpenImageIO's whole-image read and 1.3-2.0 s for its scanline-strip reads. EXR blocks
    hold all channels, so decoding everything costs no more than decoding what is needed,
    and the writer needs every channel anyway to pass them through. The parts holding
    ``names`` (and ``also_in_window``, the output colour) must share one data window.
    """
    wanted = list(dict.fromkeys(names))
    parts_of: dict[str, ExrPart] = {}
    for name in [*wanted, *also_in_window]:
        for part in info.part_info:
            if name in part.channels:
                parts_of[name] = part
                break
        else:  # resolve_layers only returns channels the header listed
            if name in wanted:
                raise InputError(f"channel {name} not found in any part", str(info.path))
    windows = {part.data_window for part in parts_of.values()}
    if len(windows) > 1:
        shown = "; ".join(
            f"part {p.name or p.index} {p.data_window}"
            for p in {p.index: p for p in parts_of.values()}.values()
        )
        raise InputError(
            f"parts holding the needed channels have different data windows ({shown})",
            str(info.path),
        )
    source = decode_source(info.path, threads=_decode_threads, expected_parts=len(info.parts))
    located: dict[str, SourcePart] = {}
    for name in wanted:
        part = source.parts[parts_of[name].index]
        channel = part.channels.get(name)
        if channel is None:
            raise InputError(f"channel {name} not found in part {part.index}", str(info.path))
        if channel.x_sampling != 1 or channel.y_sampling != 1:
            raise InputError(f"channel {name} is subsampled (not supported)", str(info.path))
        _, _, width, height = part.data_window
        if channel.pixels.shape != (height, width):
            raise InputError(
                f"channel {name} has shape {channel.pixels.shape}, expected {(height, width)}",
                str(info.path),
            )
        located[name] = part
    return _Planes(source, located)


def _scrub(
    role: str, data: np.ndarray, path: Path, warnings: list[str], clamp_negative: bool
) -> int:
    """In place: NaN/Inf -> 0 (and negatives -> 0), one counted warning line per problem.
    Returns how many values were changed."""
    # Fast path for clean data (almost every plane): min and max propagate NaN.
    low, high = float(data.min()), float(data.max())
    if math.isfinite(low) and math.isfinite(high) and (low >= 0 or not clamp_negative):
        return 0
    bad = ~np.isfinite(data)
    count = int(np.count_nonzero(bad))
    if count:
        data[bad] = 0.0
        warnings.append(f"{path}: {count} NaN/Inf values in {role} scrubbed to 0")
    changed = count
    if clamp_negative:
        negative = data < 0
        count = int(np.count_nonzero(negative))
        if count:
            data[negative] = 0.0
            warnings.append(f"{path}: {count} negative values in {role} clamped to 0")
        changed += count
    return changed


def _clean_depth(depth: np.ndarray, path: Path, warnings: list[str]) -> int:
    """In place: depth that marks background becomes 0 (Frame convention).

    Background conventions are silent: +-Inf, <= 0, or >= FAR_DEPTH (Cycles writes 1e10).
    NaN is no convention but a broken pixel: also background, with a counted warning.
    """
    nan = np.isnan(depth)
    count = int(np.count_nonzero(nan))
    if count:
        warnings.append(f"{path}: {count} NaN values in depth treated as background")
    with np.errstate(invalid="ignore"):
        background = ~((depth > 0) & (depth < FAR_DEPTH))  # NaN compares False: included
    changed = int(np.count_nonzero(background & (depth != 0)))
    depth[background] = 0.0
    return changed


def centre_sampled(attributes: Mapping[str, Any]) -> bool:
    """Whether the header says the frame is one sample per pixel through the pixel centre.

    Cycles writes ``cycles.<view layer>.samples`` and traces its sample 0 through the pixel
    centre (docs/cycles.md): a value of 1 is such a frame. With a sample offset it writes
    the subset's end (2 or more) and the one sample is jittered. Other renderers' headers
    say nothing of it: False.
    """
    for key, value in attributes.items():
        if key.startswith("cycles.") and key.endswith(".samples"):
            try:
                if int(str(value).strip()) == 1:
                    return True
            except ValueError:
                continue
    return False


def samples_per_pixel(attributes: Mapping[str, Any]) -> int:
    """The samples per pixel the header says the frame was rendered with (1 when it says
    nothing).

    Cycles writes ``cycles.<view layer>.samples``: the sample count, or the end of the
    subset for a render with a sample offset (then an overestimate). Other renderers'
    headers carry no count svgf knows: 1, the tool's premise.
    """
    for key, value in attributes.items():
        if key.startswith("cycles.") and key.endswith(".samples"):
            try:
                return max(1, int(str(value).strip()))
            except ValueError:
                continue
    return 1


def _depth_with_surfaces(
    depth: np.ndarray,
    resolved: ResolvedLayers,
    planes: _Planes,
    path: Path,
    warnings: list[str],
) -> np.ndarray:
    """The cleaned (1, H, W) depth, or the first alternative depth with a surface in it.

    Cycles writes its Depth pass (and IndexOB) from sample 0 only, so a frame rendered
    with a sample offset holds background there on every pixel, while Denoising Depth
    averages every sample; filtering such a frame would pass it through untouched. A
    depth with no surface on any pixel where an alternative has some is replaced, with a
    warning; with none to fall back to, the warning says the frame is left unfiltered.
    """
    if np.any(depth[0] > 0):
        return depth
    chosen_names = resolved["depth"] or ()
    chosen = ",".join(chosen_names)
    for alternative in resolved.alternatives.get("depth", []):
        if not planes.locate_like(alternative, chosen_names[0]):
            continue
        candidate = planes.gather(alternative)
        _clean_depth(candidate[0], path, [])
        if np.any(candidate[0] > 0):
            warnings.append(
                f"{path}: depth {chosen} is background on every pixel (Cycles writes Depth "
                f"from sample 0 only); using {','.join(alternative)}"
            )
            resolved.channels["depth"] = alternative
            return candidate
    warnings.append(f"{path}: depth {chosen} is background on every pixel: nothing is filtered")
    return depth


def _keep_colour_part_only(
    source: SourceFile, colour: tuple[str, str, str] | None, resolved: ResolvedLayers
) -> None:
    """--colour-only: free every channel the writer will not write (all but the colour
    layer's alpha, in the colour's part) as soon as the frame is read."""
    anchor = colour[0] if colour else (resolved[resolved.signal_roles[0]] or ("",))[0]
    part = source.part_holding(anchor) or source.parts[0]
    layer, dot, _ = anchor.rpartition(".")
    keep = {f"{layer}{dot}A", *(colour or ())}
    part.channels = {n: c for n, c in part.channels.items() if n in keep}
    source.parts = [p if p is part else SourcePart(p.index, p.name, p.header) for p in source.parts]


# The largest float32 below 2^31: float32 values up to it round to an int32 as they are.
_INT32_SAFE_FLOAT = float(np.nextafter(np.float32(2**31), np.float32(0)))


def mesh_ids(raw_id: np.ndarray) -> np.ndarray:
    """Mesh ids from a float32 id plane: rounded to the nearest integer (ties to even),
    clipped to the int32 range, NaN/Inf -> -1."""
    low, high = float(raw_id.min()), float(raw_id.max())  # NaN propagates: slow path
    if low >= -_INT32_SAFE_FLOAT and high <= _INT32_SAFE_FLOAT:
        # The common case in two passes; rounding a float32 is exact in float32.
        return np.rint(raw_id).astype(np.int32)
    finite = np.isfinite(raw_id)
    limit = float(np.iinfo(np.int32).max)
    mesh_id = np.full(raw_id.shape, -1, dtype=np.int32)
    # In float64: float32 rounds the int32 limit up to 2^31, which wraps negative.
    rounded = np.rint(raw_id[finite].astype(np.float64))
    mesh_id[finite] = np.clip(rounded, -limit, limit).astype(np.int32)
    return mesh_id


def _renormalise(normal: np.ndarray) -> int:
    """In place: non-zero normals to unit length. Normals already unit to 1e-5 (what
    renderers store) are left as stored, so their bits can be shared with the output.
    Returns how many normals were changed."""
    length = np.sqrt(np.einsum("chw,chw->hw", normal, normal))
    off = (length > 0) & (np.abs(length - 1.0) > 1e-5)
    count = int(np.count_nonzero(off))
    if count:
        normal[:, off] /= length[off]
    return count


def _read_one_view_info(path: Path) -> ExrInfo:
    """The header(s) of a file that is read for its pixels: multi-view files refused."""
    info = read_info(path)
    refuse_multiview(info)
    return info


@dataclass
class _ReadPlan:
    """What `read_frame` reads from one file: the resolved layers, the signal plan, the
    ``combined`` fallback of a checked set, and the channels to decode."""

    resolved: ResolvedLayers
    plan: SignalPlan
    fallback: SignalPlan | None
    names: list[str]  # the channels of the roles to read
    gradient: list[str]  # A-SVGF gradient-sample channels of the plan and its fallback


def _plan_read(mapping: LayerMapping, info: ExrInfo, path: Path) -> _ReadPlan:
    """Resolve ``mapping`` against the file's channels and plan its signals."""
    resolved = resolve_layers(mapping, info.channels, str(path))
    plan = plan_signals(mapping, resolved, info.channels, str(path))
    assert plan is not None  # resolve_layers refused a file without any signal
    # The combined colour is the fallback of a checked set: read it too.
    fallback = None
    if plan.checked and not mapping.signals_fixed:
        fallback = plan_signals(mapping, resolved, info.channels, str(path),
                                requested="combined")
    resolved.plan = plan
    resolved.requested_signals = mapping.signals
    roles = resolved.roles_to_read()
    if fallback is not None:
        roles = list(dict.fromkeys([*roles, *fallback.roles()]))
    names = [name for role in roles for name in (resolved[role] or ())]
    gradient = [p.gradient_mask for p in (plan, fallback) if p and p.gradient_mask]
    gradient += [name for p in (plan, fallback) if p
                 for _, pair in p.gradient_channels for name in pair]
    return _ReadPlan(resolved, plan, fallback, names, gradient)


def _clean_role(role: str, data: np.ndarray, path: Path, warnings: list[str]) -> int:
    """Clean one role's planes in place by its rules; returns how many values changed."""
    if role in (*RADIANCE_ROLES, "albedo") or role.endswith("_color"):
        return _scrub(role, data, path, warnings, clamp_negative=True)
    if role == "depth":
        return _clean_depth(data[0], path, warnings)
    if role == "normal":
        changed = _scrub("normal", data, path, warnings, clamp_negative=False)
        return changed + _renormalise(data)
    if role in ("motion", "motion_next", "alpha"):
        return _scrub(role, data, path, warnings, clamp_negative=False)
    return 0  # id: read as is (the mesh id is derived from it later)


@dataclass
class _RoleReader:
    """Role by role: gather a float32 copy, clean it, and when cleaning changed nothing let
    the source reference the copy instead of holding the same values twice. The G-buffer
    is gathered first (`read_gbuffer`); the signals' roles when the composition asks for
    them (`fetch`, `channel`, `release` are what `compose_signals` calls)."""

    planes: _Planes
    resolved: ResolvedLayers
    path: Path
    warnings: list[str]
    values: dict[str, np.ndarray] = field(default_factory=dict)
    gathered: dict[str, np.ndarray] = field(default_factory=dict)
    gbuffer: list[str] = field(default_factory=list)

    def fetch(self, role: str) -> np.ndarray:
        if role in self.values:
            return self.values[role]
        channel_names = self.resolved[role]
        assert channel_names is not None
        data = self.values[role] = self.planes.gather(channel_names)
        if not _clean_role(role, data, self.path, self.warnings):
            self.planes.share(channel_names, data)
        return data

    def read_gbuffer(self) -> None:
        self.gbuffer = [r for r in (*REQUIRED_ROLES, "motion_next", "id", "alpha")
                        if self.resolved[r] is not None]
        for role in self.gbuffer:
            self.fetch(role)
        self.values["depth"] = _depth_with_surfaces(
            self.values["depth"], self.resolved, self.planes, self.path, self.warnings
        )

    def release(self, role: str) -> None:
        if role not in self.gbuffer:
            self.values.pop(role, None)

    def channel(self, name: str) -> np.ndarray:
        if name not in self.gathered:
            self.gathered[name] = self.planes.gather((name,))[0]
        return self.gathered[name]


@dataclass
class _Signals:
    """The composed signals of a frame, with the light-pass check that chose them."""

    plan: SignalPlan
    signals: list[Signal]
    emission: np.ndarray | None
    sum_check: SumCheck | None = None
    signal_warning: str | None = None


def _compose_checked(read: _ReadPlan, reader: _RoleReader, path: Path) -> _Signals:
    """Compose the planned signals; a checked set whose light passes do not add up to the
    colour warns and, when not fixed, is composed again as its ``combined`` fallback."""
    plan = read.plan
    signals, emission = compose_signals(plan, reader.fetch, reader.channel, reader.release)
    if not plan.checked:
        return _Signals(plan, signals, emission)
    warnings = reader.warnings
    sum_check = check_sum(signals, emission, reader.fetch("color"))
    signal_warning = None
    if not sum_check.passed:
        signal_warning = _sum_warning(path, plan, sum_check, read.fallback is None)
        warnings.append(signal_warning)
        if read.fallback is not None:
            plan = read.fallback
            read.resolved.plan = plan
            signals, emission = compose_signals(plan, reader.fetch, reader.channel,
                                                reader.release)
    # A role gathered again for the fallback is cleaned again: report its fixes once.
    warnings[:] = dict.fromkeys(warnings)
    return _Signals(plan, signals, emission, sum_check, signal_warning)


def _assemble_frame(
    values: dict[str, np.ndarray], composed: _Signals, info: ExrInfo, convention: str
) -> Frame:
    """The validated `Frame` from the cleaned role planes and the composed signals."""
    depth = values["depth"][0]
    motion = to_backward_pixels(values["motion"], convention)

    if "id" in values:
        mesh_id = mesh_ids(values["id"][0])
    else:
        mesh_id = np.where(depth > 0, 0, -1).astype(np.int32)

    frame = Frame(
        signals=composed.signals,
        albedo=values["albedo"],
        normal=values["normal"],
        depth=np.ascontiguousarray(depth),
        motion=motion,
        mesh_id=mesh_id,
        emission=composed.emission,
        # The filter's luminance is the file's own (its chromaticities), never negative.
        luminance_weights=info.luminance_weights.for_filter(),
        centre_sampled=centre_sampled(info.attributes),
        samples_per_pixel=samples_per_pixel(info.attributes),
        # The volume lobe's signal (sets of lobe passes) marks the medium's pixels.
        medium=next((s.radiance for s in composed.signals if s.name == "volume"), None),
    )
    if "motion_next" in values:
        frame.motion_next = to_next_pixels(values["motion_next"], convention)
    frame.validate()
    return frame


def read_frame(
    path: str | os.PathLike[str],
    mapping: LayerMapping,
    motion_convention: str | None = None,
    *,
    passthrough: bool = True,
) -> ReadResult:
    """Read the channels ``mapping`` resolves to and return them as a clean `Frame`.

    ``motion_convention`` None uses ``mapping.motion_convention`` (the preset's, or what
    ``--motion-convention`` set). The signals are the set ``mapping.signals`` names
    (`io.signals`); a set built from lobe passes is checked against the file's colour
    (`check_sum`): where it fails, an unfixed mapping falls back to ``combined`` with a
    warning, a fixed one (`fix_signal_set`) keeps its set and warns. Cleaning rules:
    depth <= 0, +-Inf or >= FAR_DEPTH -> 0 (background); NaN depth -> 0 with a counted
    warning; normals non-finite -> 0 then renormalised; NaN/Inf in radiance, albedo,
    emission, motion -> 0 with a counted warning; negative radiance/albedo -> 0 with a
    counted warning; mesh id rounded to int32, NaN -> -1, absent -> -1 on background and 0
    elsewhere. The frame's luminance weights are the file's (chromaticities;
    ``LuminanceWeights.for_filter``). The whole file is decoded and kept in ``source``
    (unchanged) for the writer; ``passthrough`` False keeps only what a ``--colour-only``
    output needs. Raises InputError (one line, naming the file) for anything unreadable,
    for deep parts and for multi-view files.
    """
    path = Path(path)
    convention = motion_convention or mapping.motion_convention
    info = _read_one_view_info(path)
    read = _plan_read(mapping, info, path)
    resolved = read.resolved
    colour_channels = resolve_output_colour(mapping, info.channels)
    planes = _read_channels(info, list(dict.fromkeys([*read.names, *read.gradient])),
                            also_in_window=colour_channels or ())

    # The output replaces the colour channels: the writer never needs their input values.
    colour_is_read = set(colour_channels or ()) & set(read.names)
    for name in (colour_channels or ()) if not colour_is_read else ():
        planes.source.release(name)
    reader = _RoleReader(planes, resolved, path, warnings=[])
    reader.read_gbuffer()
    composed = _compose_checked(read, reader, path)
    # The output replaces the colour channels: the writer never needs their input values.
    for name in colour_channels or ():
        planes.source.release(name)
    if not passthrough:
        _keep_colour_part_only(planes.source, colour_channels, resolved)
    values = reader.values
    frame = _assemble_frame(values, composed, info, convention)
    return ReadResult(
        frame=frame,
        alpha=values["alpha"][0] if "alpha" in values else None,
        info=info,
        resolved=resolved,
        warnings=reader.warnings,
        source=planes.source,
        colour_channels=colour_channels,
        luminance_weights=info.luminance_weights,
        plan=composed.plan,
        sum_check=composed.sum_check,
        signal_warning=composed.signal_warning,
    )


def _sum_warning(path: Path, plan: SignalPlan, check: SumCheck, kept: bool) -> str:
    """The one-line warning of a failed light-pass check."""
    what = (
        f"the light passes of signal set {plan.set} do not add up to the colour on "
        f"{check.share:.2%} of pixels (more than {CHECK_SHARE:.1%}; light groups, holdouts, "
        "a shadow catcher or missing volume passes?)"
    )
    if kept:
        return f"{path}: {what}; keeping {plan.set}, chosen on the first frame"
    return f"{path}: {what}; filtering the combined colour for the whole run"


def fix_signal_set(
    path: str | os.PathLike[str], mapping: LayerMapping
) -> tuple[LayerMapping, ReadResult]:
    """Decide the signal set of a run on ``path`` (its first frame): read it with
    ``mapping`` (``auto`` picks, a failed light-pass check falls back to ``combined``) and
    return the mapping fixed to that set, with the read. Every later frame is read as the
    same set, whatever its own check says: the Denoiser's signals cannot change mid-run."""
    result = read_frame(path, mapping)
    assert result.plan is not None
    return replace(mapping, signals=result.plan.set, signals_fixed=True), result


def read_rgb(
    path: str | os.PathLike[str], mapping: LayerMapping | None = None
) -> tuple[np.ndarray, ExrInfo]:
    """The colour layer as a (3, H, W) float32 array (references, denoised outputs).

    The colour layer is found as `svgf denoise` writes it: through ``mapping``'s output
    colour (e.g. ``ViewLayer.Combined.R/G/B`` with the cycles preset), else plain ``R,G,B``.
    NaN/Inf are left as they are: evaluation should see what the file holds.
    """
    path = Path(path)
    info = _read_one_view_info(path)
    names = resolve_output_colour(mapping or build_mapping(), info.channels)
    if names is None and all(c in info.channels for c in "RGB"):
        names = ("R", "G", "B")
    if names is None:
        raise InputError(
            f"missing channel(s) for the colour layer (looked for "
            f"{describe_output_colour(mapping or build_mapping())}); file has: "
            f"{', '.join(info.channels)}",
            str(path),
        )
    return _read_channels(info, names).gather(names), info
