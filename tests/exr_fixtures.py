"""Tiny EXR files with real-world structure, written with the OpenEXR bindings; reading a
file's channels by name (`read_exr`); a channel-by-channel, attribute-by-attribute comparison
of two files.

Used by the CLI, passthrough and ground-truth tests and the fault suite (import as
``from exr_fixtures import ...``; ``tests/`` is on sys.path).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import OpenEXR

W, H = 12, 8


def box(x: int, y: int, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """An EXR box2i (min, max corners) from an origin and a size."""
    return (np.array([x, y], np.int32), np.array([x + width - 1, y + height - 1], np.int32))


def gbuffer(
    frame: int = 1, width: int = W, height: int = H, *, seed: int = 3, layer: str = ""
) -> dict[str, np.ndarray]:
    """An svgf-convention frame (colour, albedo, normal, depth, motion, id) as float32.

    ``layer`` prefixes the colour (``ViewLayer.Combined.`` style names are built by the
    callers that need them). The camera pans one pixel per frame: backward motion -1 in x.
    """
    rng = np.random.default_rng(seed * 1000 + frame)
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float32)
    albedo = (0.5 + 0.3 * np.sin((xs + frame) * 0.5))[None] * np.array([1.0, 0.8, 0.6])[
        :, None, None
    ]
    colour = albedo * rng.exponential(1.0, (3, height, width))
    channels: dict[str, np.ndarray] = {}
    for i, c in enumerate("RGB"):
        channels[f"{layer}{c}"] = colour[i]
        channels[f"albedo.{c}"] = albedo[i]
    channels["N.X"] = np.zeros((height, width))
    channels["N.Y"] = np.zeros((height, width))
    channels["N.Z"] = np.ones((height, width))
    channels["Z"] = 2.0 + 0.1 * ys
    channels["motion.X"] = np.full((height, width), -1.0 if frame > 1 else 0.0)
    channels["motion.Y"] = np.zeros((height, width))
    channels["id"] = np.where(xs < width / 2, 1.0, 2.0)
    return {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in channels.items()}


@dataclass
class PartSpec:
    """One part to write: channels (name -> pixels in their stored type) and its header."""

    channels: Mapping[str, np.ndarray]
    name: str = ""
    header: dict[str, Any] = field(default_factory=dict)


def write_parts(path: Path, parts: Iterable[PartSpec]) -> Path:
    """Write ``parts`` with the OpenEXR bindings (defaults: ZIP, scanline, windows from the
    pixel shape at the origin)."""
    exr_parts = []
    for spec in parts:
        first = next(iter(spec.channels.values()))
        height, width = first.shape
        header: dict[str, Any] = {
            "compression": OpenEXR.ZIP_COMPRESSION,
            "type": OpenEXR.scanlineimage,
            "dataWindow": box(0, 0, width, height),
            "displayWindow": box(0, 0, width, height),
        }
        header.update(spec.header)
        channels = {
            n: OpenEXR.Channel(n, np.ascontiguousarray(p)) for n, p in spec.channels.items()
        }
        exr_parts.append(OpenEXR.Part(header, channels, spec.name))
    OpenEXR.File(exr_parts).write(str(path))
    return path


def read_parts(path: Path) -> list[tuple[str, dict[str, Any], dict[str, np.ndarray]]]:
    """(name, header, channel pixels) of every part, as the bindings read them."""
    with OpenEXR.File(str(path), separate_channels=True) as exr:
        return [
            (
                part.name(),
                dict(part.header),
                {n: np.array(c.pixels) for n, c in part.channels.items()},
            )
            for part in exr.parts
        ]


@dataclass
class ExrImage:
    """A file's channels by name, across its parts, with pixels as stored (half, float,
    uint), and the header of its first part."""

    channels: dict[str, np.ndarray]
    header: dict[str, Any]

    def planes(self, *names: str) -> np.ndarray:
        """The named channels as one (len(names), H, W) float32 array."""
        return np.stack([self.channels[name].astype(np.float32) for name in names])

    def rgb(self, layer: str = "") -> np.ndarray:
        """``layer.R/G/B`` (or ``R,G,B``) as (3, H, W) float32."""
        prefix = f"{layer}." if layer else ""
        return self.planes(*(f"{prefix}{c}" for c in "RGB"))

    def same_pixels(self, other: ExrImage) -> bool:
        """The same channel names, types and bits (NaN payloads included)."""
        return self.channels.keys() == other.channels.keys() and all(
            bits_equal(plane, other.channels[name]) for name, plane in self.channels.items()
        )


def read_exr(path: Path) -> ExrImage:
    """Every channel of ``path`` by name (a name in two parts is refused: ambiguous here)."""
    parts = read_parts(path)
    channels: dict[str, np.ndarray] = {}
    for part_name, _, pixels in parts:
        twice = channels.keys() & pixels.keys()
        assert not twice, f"{path}: channel(s) {sorted(twice)} in two parts ({part_name!r})"
        channels.update(pixels)
    return ExrImage(channels, parts[0][1])


def same_value(a: Any, b: Any) -> bool:
    """Header values compared exactly (arrays element-wise, tuples recursively)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.array_equal(np.asarray(a), np.asarray(b))
    if isinstance(a, (tuple, list)) and isinstance(b, (tuple, list)):
        return len(a) == len(b) and all(same_value(x, y) for x, y in zip(a, b, strict=True))
    return repr(a) == repr(b)


def bits_equal(a: np.ndarray, b: np.ndarray) -> bool:
    """Same dtype, shape and bytes (NaN payloads included)."""
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


# Header keys the writer may legitimately change in the colour's part.
PROVENANCE = ("svgf/", "Software", "chunkCount")


def assert_passthrough(
    source: Path,
    output: Path,
    *,
    changed: Mapping[str, Iterable[str]] = (),  # part name -> channels that were replaced
    added: Mapping[str, Iterable[str]] = (),  # part name -> channels that were added
    header_changes: Iterable[str] = (),
) -> None:
    """Every part, attribute, window and channel of ``source`` is in ``output`` unchanged,
    except the named channels (same type unless ``--float``) and the provenance keys."""
    changed = {k: set(v) for k, v in dict(changed).items()}
    added = {k: set(v) for k, v in dict(added).items()}
    before, after = read_parts(source), read_parts(output)
    assert [p[0] for p in before] == [p[0] for p in after], "part names or order differ"
    for (name, header_in, pixels_in), (_, header_out, pixels_out) in zip(
        before, after, strict=True
    ):
        skip = tuple(PROVENANCE) + tuple(header_changes)
        keys_in = {k for k in header_in if k != "channels" and not k.startswith(skip)}
        keys_out = {k for k in header_out if k != "channels" and not k.startswith(skip)}
        assert keys_in == keys_out, (name, keys_in ^ keys_out)
        for key in keys_in:
            assert same_value(header_in[key], header_out[key]), (name, key)
        expected_names = set(pixels_in) | added.get(name, set())
        assert set(pixels_out) == expected_names, (name, set(pixels_out) ^ expected_names)
        for channel, plane in pixels_in.items():
            if channel in changed.get(name, set()):
                assert plane.shape == pixels_out[channel].shape
                assert not np.array_equal(plane, pixels_out[channel]), (name, channel)
            else:
                assert bits_equal(plane, pixels_out[channel]), (name, channel)
