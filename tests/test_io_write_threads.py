"""The drop-in writer's OpenEXR thread pool changes nothing in the file: a write with the
library's worker threads (chunks compressed in parallel) is byte-identical to a serial one,
for every lossless codec."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from svgf_cli.io.output import synthetic_source, write_output
from svgf_cli.io.source import SourceChannel, decode_source


def _source(path: Path, codec: str):  # noqa: ANN202 - a SourceFile
    rng = np.random.default_rng(7)
    source = synthetic_source(path, (67, 45), compression=codec)
    part = source.parts[0]
    for index in range(6):
        plane = rng.exponential(1.0, (67, 45)).astype(np.float32)
        part.channels[f"layer{index}.R"] = SourceChannel(plane)
    part.channels["half.Z"] = SourceChannel(rng.random((67, 45)).astype(np.float16))
    return source


@pytest.mark.parametrize("codec", ["zip", "zips", "piz", "rle", "none"])
def test_threaded_write_is_byte_identical_to_serial(tmp_path: Path, codec: str) -> None:
    source = _source(tmp_path / "in.exr", codec)
    colour = np.random.default_rng(3).random((3, 67, 45)).astype(np.float16)
    files = []
    for threads in (0, 2, 4):
        out = tmp_path / f"out{threads}.exr"
        write_output(out, source, part_index=0, channels=dict(zip("RGB", colour, strict=True)),
                     attributes={}, threads=threads)
        files.append(out.read_bytes())
    assert files[0] == files[1] == files[2]
    decoded = decode_source(tmp_path / "out2.exr").parts[0].channels
    for name, channel in source.parts[0].channels.items():
        assert np.array_equal(decoded[name].pixels, channel.pixels)
