"""Single-part scanline EXR files with ZIP or ZIPS chunks, deflated with zlib-ng.

ZIP is what Cycles, Arnold and RenderMan write by default, and OpenEXR's own encoder was
the largest single cost of a production frame: ~3.5 CPU-s to write a 1080p 80-channel frame,
on one core whatever its thread count (docs/performance.md). zlib-ng's level 1 deflates the
same format (a zlib stream of the chunk's bytes, reordered and delta-predicted as OpenEXR
specifies) ~3x faster, and the chunks are encoded on several threads. Its output depends on
the input bytes alone: ISA-L's, used before, varied from run to run on 1080p production
frames (the same planes written ten times gave two or three different files, every one
decoding to the same pixels), and a drop-in output must be the same file for the same
input (docs/output.md). Written by hand because the OpenEXR bindings expose neither another
deflate nor raw chunk I/O. Reading stays with the library (its inflate is as fast).

The header is carried as raw attributes: each attribute read from the input is written back
byte for byte, so types this module knows nothing about (timecodes, matrices, Cryptomatte
manifests) survive untouched; only the channel list, the codec and new string/int
attributes are encoded here.
"""

from __future__ import annotations

import struct
import threading
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, BinaryIO

import numba
import numpy as np
from zlib_ng import zlib_ng

MAGIC = 20000630
VERSION = 2
LONG_NAMES, NON_IMAGE, MULTIPART = 0x400, 0x800, 0x1000
ZIPS, ZIP = 2, 3
LINES_PER_CHUNK = {ZIPS: 1, ZIP: 16}
TYPE_CODES = {np.dtype("<u4"): 0, np.dtype("<f2"): 1, np.dtype("<f4"): 2}  # uint, half, float
# zlib-ng's fastest: level 2 makes 1080p production frames 10 % smaller for 1.5x the CPU.
DEFLATE_LEVEL = 1
# A chunk's deflated stream is made and written in pieces from this much input (a 16-line
# production chunk deflates to ~1.5 MB in one piece: a block that size is mapped afresh for
# every chunk, while pieces of ~100 kB are recycled by the heap).
DEFLATE_PIECE = 1 << 18
_MAX_NAME = 255
_MAX_PIXELS = 1 << 31  # beyond this the file is not one a renderer wrote: let OpenEXR judge


class Declined(Exception):
    """This module does not handle the file (the caller uses the OpenEXR library)."""


@dataclass(frozen=True)
class RawAttribute:
    """One header attribute as stored: name, type name and value bytes."""

    name: str
    type: str
    value: bytes


@dataclass(frozen=True)
class ChannelSpec:
    """One entry of a ``chlist``."""

    name: str
    dtype: np.dtype
    p_linear: bool = False


@dataclass(frozen=True)
class RawHeader:
    """A single-part file's attributes in file order and where they end."""

    attributes: tuple[RawAttribute, ...]
    end: int


# -- the header ------------------------------------------------------------------------------


def _cstring(data: bytes | bytearray, at: int) -> tuple[str, int]:
    end = data.index(b"\0", at, at + _MAX_NAME + 1)
    return data[at:end].decode("utf-8"), end + 1


def read_raw_header(fh: BinaryIO) -> RawHeader:
    """Parse a single-part file's header (magic, version, attributes up to the null byte).

    Raises Declined for anything else: multi-part, deep, or a header that does not parse."""
    head = fh.read(8)
    if len(head) < 8:
        raise Declined("short file")
    magic, version = struct.unpack("<ii", head)
    if magic != MAGIC or version & 0xFF != VERSION:
        raise Declined("not an OpenEXR 2 file")
    if version & (MULTIPART | NON_IMAGE):
        raise Declined("multi-part or deep")
    data = bytearray()

    def need(end: int) -> None:
        while len(data) < end:
            more = fh.read(max(1 << 16, end - len(data)))
            if not more:
                raise Declined("truncated header")
            data.extend(more)

    def name_at(at: int) -> tuple[str, int]:
        need(at + 1)
        while data.find(b"\0", at, at + _MAX_NAME + 1) < 0 and len(data) < at + _MAX_NAME + 1:
            need(len(data) + 1)
        return _cstring(data, at)

    attributes: list[RawAttribute] = []
    at = 0
    try:
        while True:
            need(at + 1)
            if data[at] == 0:
                return RawHeader(tuple(attributes), 8 + at + 1)
            name, at = name_at(at)
            kind, at = name_at(at)
            need(at + 4)
            (size,) = struct.unpack_from("<i", data, at)
            at += 4
            if size < 0:
                raise Declined("negative attribute size")
            need(at + size)
            attributes.append(RawAttribute(name, kind, bytes(data[at:at + size])))
            at += size
    except (ValueError, struct.error, UnicodeDecodeError):
        raise Declined("header does not parse") from None


def encode_channels(specs: Sequence[ChannelSpec]) -> bytes:
    """A ``chlist`` value (channels in the byte order of their names, as OpenEXR stores them)."""
    out = bytearray()
    for spec in sorted(specs, key=lambda s: s.name.encode("utf-8")):
        out += spec.name.encode("utf-8") + b"\0"
        out += struct.pack("<iB3xii", TYPE_CODES[np.dtype(spec.dtype).newbyteorder("<")],
                           int(spec.p_linear), 1, 1)
    return bytes(out + b"\0")


def encode_value(value: Any) -> tuple[str, bytes] | None:
    """(type, bytes) of a new attribute value this module can encode (str, int), else None."""
    if isinstance(value, str):
        return "string", value.encode("utf-8")
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        return "int", struct.pack("<i", int(value))
    return None


def encode_header(attributes: Sequence[RawAttribute], channel_names: Sequence[str]) -> bytes:
    """Magic, version (long-names flag where a name needs it) and the attributes, sorted by
    name as OpenEXR writes them, then the terminating null byte."""
    longest = max([len(a.name.encode()) for a in attributes]
                  + [len(a.type.encode()) for a in attributes]
                  + [len(n.encode()) for n in channel_names] + [0])
    version = VERSION | (LONG_NAMES if longest > 31 else 0)
    out = bytearray(struct.pack("<ii", MAGIC, version))
    for attr in sorted(attributes, key=lambda a: a.name.encode("utf-8")):
        out += attr.name.encode() + b"\0" + attr.type.encode() + b"\0"
        out += struct.pack("<i", len(attr.value)) + attr.value
    return bytes(out + b"\0")


def scanline_attributes(
    width: int, height: int, codec: int = ZIP, strings: Mapping[str, str] | None = None
) -> list[RawAttribute]:
    """The attributes every scanline file needs (windows at the origin, increasing y, square
    pixels, the default screen window), the codec, and ``strings`` as string attributes:
    a new file's header, for `ChunkWriter`."""
    box = struct.pack("<iiii", 0, 0, width - 1, height - 1)
    attributes = [
        RawAttribute("compression", "compression", bytes([codec])),
        RawAttribute("dataWindow", "box2i", box),
        RawAttribute("displayWindow", "box2i", box),
        RawAttribute("lineOrder", "lineOrder", b"\0"),
        RawAttribute("pixelAspectRatio", "float", struct.pack("<f", 1.0)),
        RawAttribute("screenWindowCenter", "v2f", struct.pack("<ff", 0.0, 0.0)),
        RawAttribute("screenWindowWidth", "float", struct.pack("<f", 1.0)),
    ]
    for name, value in (strings or {}).items():
        attributes.append(RawAttribute(name, "string", value.encode("utf-8")))
    return attributes


def data_window(attributes: Mapping[str, RawAttribute]) -> tuple[int, int, int, int]:
    """(x_min, y_min, width, height) of the ``dataWindow`` attribute."""
    attr = attributes.get("dataWindow")
    if attr is None or attr.type != "box2i" or len(attr.value) != 16:
        raise Declined("no dataWindow")
    x0, y0, x1, y1 = struct.unpack("<iiii", attr.value)
    width, height = x1 - x0 + 1, y1 - y0 + 1
    if width < 1 or height < 1 or width * height > _MAX_PIXELS:
        raise Declined("data window")
    return x0, y0, width, height


def codec_of(attributes: Mapping[str, RawAttribute]) -> int:
    """The ``compression`` attribute's code (ZIPS or ZIP), or Declined."""
    attr = attributes.get("compression")
    code = attr.value[0] if attr is not None and len(attr.value) == 1 else -1
    if code not in LINES_PER_CHUNK:
        raise Declined("codec")
    return code


# -- the chunks' byte order (OpenEXR's ZIP: halves interleaved, then a delta predictor) -------


@numba.njit(nogil=True, cache=True, boundscheck=False)
def reorder_predict(raw: np.ndarray, out: np.ndarray) -> None:
    """out = delta(t) with t = raw[0::2] ++ raw[1::2]: out[0] = t[0],
    out[j] = (t[j] - t[j-1] + 128) mod 256 (OpenEXR's ZIP predictor)."""
    n = raw.size
    if n == 0:
        return
    half = (n + 1) // 2
    out[0] = raw[0]
    for j in range(1, half):
        out[j] = np.uint8((np.int32(raw[2 * j]) - np.int32(raw[2 * j - 2]) + 128) & 0xFF)
    if n > 1:
        out[half] = np.uint8((np.int32(raw[1]) - np.int32(raw[2 * half - 2]) + 128) & 0xFF)
    for j in range(half + 1, n):
        k = 2 * (j - half)
        out[j] = np.uint8((np.int32(raw[k + 1]) - np.int32(raw[k - 1]) + 128) & 0xFF)


# -- planes <-> rows of a chunk ---------------------------------------------------------------


def _byte_rows(plane: np.ndarray) -> np.ndarray:
    """A (H, W) plane as (H, W * itemsize) little-endian bytes (a view when it can be)."""
    plane = np.ascontiguousarray(plane, dtype=plane.dtype.newbyteorder("<"))
    return plane.view(np.uint8).reshape(plane.shape[0], -1)


def _layout(specs: Sequence[ChannelSpec], width: int) -> tuple[list[int], int]:
    offsets, at = [], 0
    for spec in specs:
        offsets.append(at)
        at += width * spec.dtype.itemsize
    return offsets, at


def deflate_pieces(data: np.ndarray) -> list[bytes]:
    """One zlib stream of ``data`` (uint8) at ``DEFLATE_LEVEL``, in the pieces the compressor
    gave it out in (input fed ``DEFLATE_PIECE`` bytes at a time); joined, they inflate to
    ``data``, and they are the same bytes every time."""
    deflate = zlib_ng.compressobj(DEFLATE_LEVEL)
    pieces = [deflate.compress(data[start:start + DEFLATE_PIECE])
              for start in range(0, data.size, DEFLATE_PIECE)]
    pieces.append(deflate.flush())
    return [piece for piece in pieces if piece]


def _map_ordered(fn: Callable[[int], Any], count: int, threads: int) -> Iterator[Any]:
    """fn(0..count-1) in order, on ``threads`` threads (at most 4 results ahead per thread)."""
    if threads <= 1:
        yield from (fn(i) for i in range(count))
        return
    window = 4 * threads
    with ThreadPoolExecutor(threads, thread_name_prefix="zipchunks") as pool:
        pending = [pool.submit(fn, i) for i in range(min(window, count))]
        for i in range(count):
            result = pending[i].result()
            pending[i] = None  # type: ignore[call-overload]
            if i + window < count:
                pending.append(pool.submit(fn, i + window))
            yield result


# -- writing ---------------------------------------------------------------------------------


class ChunkWriter:
    """A single-part scanline file ready to encode: ``attributes`` (all but ``channels``;
    ``dataWindow``, ``compression`` ZIP or ZIPS, ``lineOrder`` INCREASING_Y or absent) and
    ``planes`` (name -> (H, W) uint32/half/float at full resolution). Raises Declined for
    anything else, before a byte is written."""

    def __init__(
        self,
        attributes: Sequence[RawAttribute],
        planes: Mapping[str, np.ndarray],
        p_linear: Mapping[str, bool],
    ) -> None:
        by_name = {a.name: a for a in attributes if a.name != "channels"}
        self.codec = codec_of(by_name)
        line_order = by_name.get("lineOrder")
        if line_order is not None and line_order.value != b"\0":
            raise Declined("line order")
        _, self.y_min, self.width, self.height = data_window(by_name)
        specs = []
        for name, plane in planes.items():
            dtype = np.dtype(plane.dtype).newbyteorder("<")
            if dtype not in TYPE_CODES or plane.shape != (self.height, self.width):
                raise Declined(f"channel {name}")
            specs.append(ChannelSpec(name, dtype, bool(p_linear.get(name, False))))
        if not specs:
            raise Declined("no channels")
        self.specs = sorted(specs, key=lambda s: s.name.encode("utf-8"))
        chlist = RawAttribute("channels", "chlist", encode_channels(self.specs))
        self.head = encode_header([*by_name.values(), chlist], [s.name for s in self.specs])
        self.planes = planes

    def write(self, fh: BinaryIO, threads: int = 0) -> None:
        """Header, chunk offset table, then the chunks in increasing y (``threads`` encode)."""
        rows = [_byte_rows(self.planes[s.name]) for s in self.specs]
        offsets, row_bytes = _layout(self.specs, self.width)
        lines = LINES_PER_CHUNK[self.codec]
        count = (self.height + lines - 1) // lines

        # Each thread reuses its two chunk buffers: fresh ones per chunk (6 MB each for a
        # 16-line production chunk) cost more in page faults than the copies themselves.
        scratch = threading.local()

        def encode(index: int) -> tuple[bytes, list[bytes]]:
            if not hasattr(scratch, "raw"):
                scratch.raw = np.empty((lines, row_bytes), np.uint8)
                scratch.packed = np.empty(lines * row_bytes, np.uint8)
            y0 = index * lines
            y1 = min(y0 + lines, self.height)
            raw = scratch.raw[:y1 - y0]
            for offset, source in zip(offsets, rows, strict=True):
                raw[:, offset:offset + source.shape[1]] = source[y0:y1]
            flat = raw.reshape(-1)
            packed = scratch.packed[:flat.size]
            reorder_predict(flat, packed)
            pieces = deflate_pieces(packed)
            size = sum(len(piece) for piece in pieces)
            # OpenEXR stores a chunk that does not shrink as it is.
            if size >= flat.size:
                pieces, size = [flat.tobytes()], flat.size
            return struct.pack("<ii", self.y_min + y0, size), pieces

        # The kernel's first call (numba loading it from its cache) in this thread, not in
        # two pool threads at once.
        reorder_predict(np.zeros(2, np.uint8), np.empty(2, np.uint8))
        fh.write(self.head)
        table_at = fh.tell()
        fh.write(b"\0" * (8 * count))
        positions = []
        for prefix, pieces in _map_ordered(encode, count, threads):
            positions.append(fh.tell())
            fh.write(prefix)
            for piece in pieces:
                fh.write(piece)
        end = fh.tell()
        fh.seek(table_at)
        fh.write(struct.pack(f"<{count}Q", *positions))
        fh.seek(end)
