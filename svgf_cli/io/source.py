"""A decoded EXR file as the OpenEXR library sees it: every part's header and every channel.

`decode_source` decodes a whole file once (the reader needs some channels for the filter; the
writer needs all of them to write a drop-in replacement). Pixels stay in their stored type
(half, float, uint) and headers stay as the OpenEXR bindings return them, so the writer can
hand both back unchanged.
"""

from __future__ import annotations

import contextlib
import os
import re
import sys
import tempfile
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import OpenEXR

from svgf_cli.errors import InputError
from svgf_cli.io import zipchunks

PIXEL_TYPE_NAMES = {"f2": "half", "f4": "float", "u4": "uint"}


@dataclass
class SourceChannel:
    """One channel's pixels in their stored type, and its sampling.

    ``pixels`` is None once released (`SourceFile.release`): a channel the writer replaces
    (the colour) need not be held until the frame is written.
    """

    pixels: np.ndarray | None
    x_sampling: int = 1
    y_sampling: int = 1
    p_linear: bool = False
    type_name: str = ""

    def __post_init__(self) -> None:
        if not self.type_name and self.pixels is not None:
            dtype = self.pixels.dtype.str[1:]
            self.type_name = PIXEL_TYPE_NAMES.get(dtype, str(self.pixels.dtype))


@dataclass
class SourcePart:
    """One part: its name, its header (OpenEXR bindings' dict) and its channels.

    ``raw`` holds a single-part file's header attributes as stored (`zipchunks`), so the
    writer can copy them byte for byte when it encodes the chunks itself; None otherwise."""

    index: int
    name: str
    header: dict[str, Any]
    channels: dict[str, SourceChannel] = field(default_factory=dict)
    raw: tuple[zipchunks.RawAttribute, ...] | None = None

    @property
    def data_window(self) -> tuple[int, int, int, int]:
        """(x, y, width, height) of the data window."""
        low, high = self.header["dataWindow"]
        return (int(low[0]), int(low[1]), int(high[0] - low[0] + 1), int(high[1] - low[1] + 1))


@dataclass
class SourceFile:
    """Every part of a decoded EXR file."""

    path: Path
    parts: list[SourcePart]

    def part_holding(self, channel: str) -> SourcePart | None:
        """The first part that has ``channel`` (channel names are unique per part only)."""
        for part in self.parts:
            if channel in part.channels:
                return part
        return None

    def subsampled(self) -> list[str]:
        """Channels stored at less than full resolution (``part:name``)."""
        return [
            f"{part.name or part.index}:{name}"
            for part in self.parts
            for name, channel in part.channels.items()
            if channel.x_sampling != 1 or channel.y_sampling != 1
        ]

    def release(self, channel: str) -> None:
        """Drop the pixels of ``channel`` (its name, part and type stay known)."""
        part = self.part_holding(channel)
        if part is not None:
            part.channels[channel].pixels = None


# -- capturing the bindings' printed warnings ------------------------------------------------


class _ThreadRoutedStream:
    """Stands in for ``sys.stdout``: text written by threads that are capturing goes to their
    buffer, everything else to the real stream."""

    def __init__(self, target: Any) -> None:
        self.target = target
        self.buffers: dict[int, list[str]] = {}

    def write(self, text: str) -> int:
        buffer = self.buffers.get(threading.get_ident())
        if buffer is not None:
            buffer.append(text)
            return len(text)
        return self.target.write(text)

    def flush(self) -> None:
        self.target.flush()

    def __getattr__(self, name: str) -> Any:
        return getattr(self.target, name)


_route_lock = threading.Lock()


@contextlib.contextmanager
def capture_library_output() -> Iterator[list[str]]:
    """Collect what the OpenEXR bindings print from this thread (they print, rather than
    raise, when a part's pixels fail to decode), leaving other threads' output alone."""
    with _route_lock:
        router = sys.stdout if isinstance(sys.stdout, _ThreadRoutedStream) else None
        if router is None:
            router = _ThreadRoutedStream(sys.stdout)
            sys.stdout = router
        buffer: list[str] = []
        router.buffers[threading.get_ident()] = buffer
    try:
        yield buffer
    finally:
        with _route_lock:
            router.buffers.pop(threading.get_ident(), None)
            if not router.buffers and sys.stdout is router:
                sys.stdout = router.target


_fd_lock = threading.Lock()


@contextlib.contextmanager
def capture_c_stderr() -> Iterator[list[str]]:
    """Collect what C code writes to file descriptor 2 meanwhile (OpenEXR's core library
    prints its own error lines there), then hand back every other line written in the
    window (another thread's warning) to the real stderr, in order."""
    captured: list[str] = []
    with _fd_lock, tempfile.TemporaryFile() as sink:
        with contextlib.suppress(Exception):
            sys.stderr.flush()
        try:
            saved = os.dup(2)
        except OSError:  # no stderr at all (a daemon): nothing to keep clean
            yield captured
            return
        os.dup2(sink.fileno(), 2)
        try:
            yield captured
        finally:
            with contextlib.suppress(Exception):
                sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            text = sink.read().decode("utf-8", "replace")
            for line in text.splitlines(keepends=True):
                if "(EXR_ERR_" in line:
                    captured.append(line.strip())
                else:
                    os.write(2, line.encode("utf-8", "replace"))


# -- decoding -------------------------------------------------------------------------------


def one_line(message: str, limit: int = 300) -> str:
    """A library's (often repeated, multi-line) error text as one short line."""
    text = " ".join(str(message).split())
    pieces = [p.strip(" :;-") for p in re.split(r"EXR Error \([^)]*\):?|Warning:", text)]
    unique = list(dict.fromkeys(p for p in pieces if p))
    text = "; ".join(unique)
    if len(text) > limit:
        text = text[: limit - 3] + "..."
    return text or "unknown error"


def _reason(printed: list[str]) -> str:
    """The bindings print "Warning: Exception raised reading pixel data for part N - WHY"."""
    text = " ".join("".join(printed).split())
    _, dash, why = text.partition(" - ")
    return one_line(why if dash else text)


def decode_source(
    path: str | os.PathLike[str], threads: int = 0, expected_parts: int | None = None
) -> SourceFile:
    """Decode every part and channel of ``path`` (deep parts are refused by the caller).

    ``expected_parts`` is the part count the header promised (read again when None): the
    bindings skip a part whose pixels fail to decode, printing why, instead of raising.

    Raises InputError with the decoder's own reason, on one line, when any part's pixels
    cannot be decoded (truncated file, corrupt chunk, bad chunk table).
    """
    path = Path(path)
    raw = _raw_attributes(path)
    try:
        with capture_c_stderr() as library_lines, capture_library_output() as printed:
            exr = OpenEXR.File(str(path), separate_channels=True, num_threads=threads)
        with exr:
            if expected_parts is None:
                expected_parts = _part_count(path)
            if printed or library_lines or len(exr.parts) != expected_parts:
                reason = _reason(printed) if printed else "a part could not be decoded"
                if library_lines:  # the core library's own, more precise words
                    reason = one_line(library_lines[0].split(": ", 1)[-1])
                raise InputError(f"cannot read pixels: {reason}", str(path))
            parts = []
            for index, part in enumerate(exr.parts):
                channels = {
                    name: SourceChannel(
                        channel.pixels, channel.xSampling, channel.ySampling, channel.pLinear
                    )
                    for name, channel in part.channels.items()
                }
                parts.append(SourcePart(index, part.name(), dict(part.header), channels,
                                        raw if len(exr.parts) == 1 else None))
    except InputError:
        raise
    except UnicodeDecodeError as exc:
        raise InputError(f"header holds text that is not UTF-8 ({exc.reason})", str(path)) from None
    except Exception as exc:  # the bindings raise RuntimeError/ValueError/... on bad data
        raise InputError(f"cannot read pixels: {one_line(str(exc))}", str(path)) from None
    return SourceFile(path, parts)


def _raw_attributes(path: Path) -> tuple[zipchunks.RawAttribute, ...] | None:
    """A single-part file's header attributes as stored, or None (multi-part, unreadable)."""
    try:
        with open(path, "rb") as fh:
            return zipchunks.read_raw_header(fh).attributes
    except (OSError, zipchunks.Declined):
        return None


def _part_count(path: Path) -> int:
    with OpenEXR.File(str(path), separate_channels=True, header_only=True) as exr:
        return len(exr.parts)

