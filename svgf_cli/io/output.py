"""Writing a denoised frame as a drop-in replacement for its input file.

The output is the input file again, written by the same library that decoded it (the
OpenEXR bindings: they hand back every header attribute, per-channel pixel type, window,
tile description, line order and part exactly as read), with the colour channels replaced
by the denoised colour and, optionally, debug channels added. Nothing else changes, so a
compositing script can swap the file in for the original. Writes are atomic (hidden unique
temporary, then rename: `svgf_cli.io.atomic`).

Value policy at this boundary (`prepare_colour`): non-finite colour becomes 0, then half
output is clamped to the largest finite half (+-65504); both are counted for a warning.
"""

from __future__ import annotations

import os
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import OpenEXR

from svgf_cli.errors import InputError
from svgf_cli.halfconv import storable
from svgf_cli.io import atomic, zipchunks
from svgf_cli.io.exr import (
    LOSSY_COMPRESSIONS,
    ExrWriteError,
    check_compression,
    check_output_path,
    compression_name,
    is_colour_channel,
    output_error,
)
from svgf_cli.io.source import SourceChannel, SourceFile, SourcePart, one_line

HALF_MAX = float(np.finfo(np.float16).max)  # 65504

_CODECS = {
    "none": OpenEXR.NO_COMPRESSION,
    "rle": OpenEXR.RLE_COMPRESSION,
    "zips": OpenEXR.ZIPS_COMPRESSION,
    "zip": OpenEXR.ZIP_COMPRESSION,
    "piz": OpenEXR.PIZ_COMPRESSION,
    "pxr24": OpenEXR.PXR24_COMPRESSION,
    "b44": OpenEXR.B44_COMPRESSION,
    "b44a": OpenEXR.B44A_COMPRESSION,
    "dwaa": OpenEXR.DWAA_COMPRESSION,
    "dwab": OpenEXR.DWAB_COMPRESSION,
}
_CODEC_NAMES = {int(v): k for k, v in _CODECS.items()}

# Header keys the library computes itself when writing.
_COMPUTED_KEYS = ("channels", "chunkCount")


def codec_name(header: Mapping[str, Any]) -> str:
    """The part's compression as our lower-case name (``zip``, ``dwaa``, ...)."""
    value = header.get("compression", OpenEXR.NO_COMPRESSION)
    return _CODEC_NAMES.get(int(value), str(value).rsplit(".", 1)[-1].lower())


# -- the colour, converted for the file ------------------------------------------------------


@dataclass
class PreparedColour:
    """Colour planes in their output pixel type, and what the conversion had to fix."""

    planes: np.ndarray  # (3, H, W) float16 or float32
    nonfinite: int = 0  # NaN/Inf set to 0
    clamped: int = 0  # beyond +-65504, clamped to it (half output only)


def prepare_colour(colour: np.ndarray, half: bool) -> PreparedColour:
    """The output conversion boundary: non-finite -> 0 first, then (half) clamp to +-65504.

    The order matters: a value is finite before it is clamped, and a finite value above
    65504 would otherwise become Inf in half. ``colour`` is modified in place.
    """
    planes, nonfinite, clamped = storable(colour, half)
    if nonfinite or clamped:  # rare: the same fixes in place, as documented
        colour[~np.isfinite(colour)] = 0.0
        if half:
            np.clip(colour, -HALF_MAX, HALF_MAX, out=colour)
    return PreparedColour(planes, nonfinite, clamped)


# -- choosing per-part settings --------------------------------------------------------------


def part_compression(
    part_codec: str, channel_names: Collection[str], explicit: str | None
) -> str:
    """The codec a part is written with: ``explicit`` (``--compression``, checked against the
    part's channels), else the part's own. An inherited lossy codec (B44, DWA) falls back
    to ``zip`` when the part holds data channels (depth, normals, motion, ids, debug
    layers): decoding and re-encoding them lossily would degrade them a second time."""
    if explicit:
        check_compression(explicit, channel_names)
        return explicit
    if part_codec in LOSSY_COMPRESSIONS and any(
        not is_colour_channel(n) for n in channel_names
    ):
        return "zip"
    return part_codec


def _tiles_one_level(header: dict[str, Any], notes: list[str], part_label: str) -> None:
    tiles = header.get("tiles")
    if tiles is None or tiles.mode == OpenEXR.ONE_LEVEL:
        return
    one = OpenEXR.TileDescription()
    one.xSize, one.ySize = tiles.xSize, tiles.ySize
    one.mode, one.roundingMode = OpenEXR.ONE_LEVEL, tiles.roundingMode
    header["tiles"] = one
    notes.append(f"{part_label}: mip/rip-map levels are not written (level 0 only)")


def _apply_codec(header: dict[str, Any], codec: str) -> None:
    base = compression_name(codec)
    header["compression"] = _CODECS[base]
    _, _, level = codec.partition(":")
    if base in ("dwaa", "dwab") and level.strip():
        header["dwaCompressionLevel"] = float(level)


def _append_software(header: dict[str, Any], tag: str) -> None:
    key = next((k for k in ("Software", "software") if k in header), "Software")
    current = str(header.get(key, "")).strip()
    header[key] = f"{current}; {tag}" if current and tag not in current else (current or tag)


# -- writing ---------------------------------------------------------------------------------


def write_output(
    path: str | os.PathLike[str],
    source: SourceFile,
    *,
    part_index: int,
    channels: Mapping[str, np.ndarray],
    attributes: Mapping[str, Any],
    software: str | None = None,
    compression: str | None = None,
    keep_only: Collection[str] | None = None,
    threads: int = 0,
) -> list[str]:
    """Write ``source`` to ``path`` with ``channels`` set in part ``part_index``.

    ``channels`` (name -> (H, W) plane in its output type, float16/float32/uint32) replace
    the part's channels of the same name or are added to it; ``attributes`` are added to
    that part's header and ``software`` appended to its Software attribute. Every other
    part, channel and attribute is written as read. ``compression`` None keeps each part's
    codec (see `part_compression`). ``keep_only`` writes only part ``part_index`` with only
    those input channels (plus ``channels``). Returns notes about structure the writer
    could not keep (mip-map levels). Raises InputError for input channels that cannot be
    written back (subsampled), ExrWriteError (one line, real cause) when writing fails.

    A single scanline part written with ZIP or ZIPS has its chunks encoded by `zipchunks`
    (the same file, ~3x less CPU than the library's codec); everything else by the library.
    """
    path = Path(path)
    notes: list[str] = []
    parts: list[_PartOut] = []
    for part in source.parts:
        if keep_only is not None and part.index != part_index:
            continue
        target = part.index == part_index
        parts.append(
            _output_part(
                source,
                part,
                channels if target else {},
                attributes if target else {},
                software if target else None,
                compression,
                keep_only if target else None,
                notes,
            )
        )
    check_output_path(path)
    chunks = _chunk_writer(parts[0]) if len(parts) == 1 else None
    if chunks is not None:

        def write(tmp: Path) -> None:
            with open(tmp, "xb") as fh:
                chunks.write(fh, threads)
    else:
        exr = OpenEXR.File([p.library_part() for p in parts], num_threads=threads)

        def write(tmp: Path) -> None:
            try:
                exr.write(str(tmp))
            except OSError:
                raise
            except Exception as exc:  # the bindings raise RuntimeError/ValueError on failure
                raise ExrWriteError(f"write failed: {_write_reason(exc, tmp)}",
                                    str(path)) from None

    try:
        atomic.write_atomically(path, write)
    except OSError as exc:
        raise output_error(exc, path) from None
    return notes


def _write_reason(exc: Exception, tmp: Path) -> str:
    """The library's reason without the temporary's name (the final name is reported)."""
    return one_line(str(exc).replace(str(tmp), "output").replace(tmp.name, "output"))


@dataclass
class _PartOut:
    """One output part before encoding: its header (bindings' dict), its channels (pixels
    in their output type) and the source part it was made from."""

    name: str
    header: dict[str, Any]
    channels: dict[str, SourceChannel]
    source: SourcePart

    def library_part(self) -> Any:
        """The part for the OpenEXR bindings' writer."""
        return OpenEXR.Part(
            self.header,
            {name: OpenEXR.Channel(name, c.pixels, c.x_sampling, c.y_sampling, c.p_linear)
             for name, c in self.channels.items()},
            self.name,
        )


def _chunk_writer(out: _PartOut) -> zipchunks.ChunkWriter | None:
    """The part as `zipchunks` writes it (the source's attributes byte for byte, changed and
    new ones encoded), or None where the library writes it: no raw header, not a
    full-resolution scanline ZIP/ZIPS part in increasing line order, or a value `zipchunks`
    cannot encode."""
    source = out.source
    if source.raw is None or source.header.get("tiles") is not None:
        return None
    if any((c.x_sampling, c.y_sampling) != (1, 1) for c in out.channels.values()):
        return None
    if out.header.get("lineOrder", OpenEXR.INCREASING_Y) != OpenEXR.INCREASING_Y:
        return None
    codec = codec_name(out.header)
    if codec not in ("zip", "zips"):
        return None
    stored = {a.name: a for a in source.raw}
    attributes = []
    for key, value in out.header.items():
        if key in _COMPUTED_KEYS or key == "type":  # the library's own view of the part
            continue
        if key == "compression":
            code = 3 if codec == "zip" else 2
            attributes.append(zipchunks.RawAttribute(key, "compression", bytes([code])))
        elif key in stored and value is source.header.get(key):
            attributes.append(stored[key])
        else:
            encoded = zipchunks.encode_value(value)
            if encoded is None:
                return None
            attributes.append(zipchunks.RawAttribute(key, *encoded))
    planes = {name: c.pixels for name, c in out.channels.items()}
    linear = {name: c.p_linear for name, c in out.channels.items()}
    try:
        return zipchunks.ChunkWriter(attributes, planes, linear)
    except zipchunks.Declined:
        return None


def _output_part(
    source: SourceFile,
    part: SourcePart,
    replace: Mapping[str, np.ndarray],
    attributes: Mapping[str, Any],
    software: str | None,
    explicit_codec: str | None,
    keep_only: Collection[str] | None,
    notes: list[str],
) -> _PartOut:
    label = f"part {part.index}" + (f" {part.name!r}" if part.name else "")
    header = {k: v for k, v in part.header.items() if k not in _COMPUTED_KEYS}
    kept = {
        name: channel
        for name, channel in part.channels.items()
        if name not in replace and (keep_only is None or name in keep_only)
    }
    subsampled = [n for n, c in kept.items() if (c.x_sampling, c.y_sampling) != (1, 1)]
    if subsampled:
        raise InputError(
            f"{label}: channel(s) {', '.join(subsampled)} are subsampled and cannot be passed "
            "through; --colour-only writes the colour alone",
            str(source.path),
        )
    released = [n for n, c in kept.items() if c.pixels is None]
    if released:
        raise ExrWriteError(f"{label}: no pixels for channel(s) {', '.join(released)}",
                            str(source.path))
    names = [*kept, *replace]
    own = codec_name(part.header)
    codec = part_compression(own, names, explicit_codec)
    if codec != own or explicit_codec:
        _apply_codec(header, codec)
    # else: the part's own codec value as read (also codecs we have no name for: HTJ2K...)
    _tiles_one_level(header, notes, label)
    header.update(attributes)
    if software:
        _append_software(header, software)
    channels = dict(kept)
    for name, plane in replace.items():
        channels[name] = SourceChannel(plane)
    return _PartOut(part.name, header, channels, part)


def synthetic_source(
    path: str | os.PathLike[str],
    shape: tuple[int, int],
    attributes: Mapping[str, Any] | None = None,
    compression: str = "zip",
    alpha: np.ndarray | None = None,
) -> SourceFile:
    """A one-part source with no channels but ``A`` (when given): the output layout for a
    reader that did not decode a file (tests, stand-in readers)."""
    height, width = shape
    header: dict[str, Any] = {
        "compression": _CODECS[compression_name(compression)],
        "type": OpenEXR.scanlineimage,
        "dataWindow": (np.array([0, 0], np.int32), np.array([width - 1, height - 1], np.int32)),
        "displayWindow": (
            np.array([0, 0], np.int32),
            np.array([width - 1, height - 1], np.int32),
        ),
    }
    for key, value in (attributes or {}).items():
        if isinstance(value, (str, int, float)):
            header[key] = value
    part = SourcePart(0, "", header)
    if alpha is not None:
        from svgf_cli.io.source import SourceChannel

        part.channels["A"] = SourceChannel(np.ascontiguousarray(alpha, dtype=np.float32))
    return SourceFile(Path(path), [part])
