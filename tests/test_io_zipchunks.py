"""`svgf_cli.io.zipchunks`: ZIP/ZIPS chunks encoded by hand must be the files the OpenEXR
library would write (every pixel and attribute as the library reads them back), and the
writer must take only what it handles."""

from __future__ import annotations

import io
import struct
import zlib
from pathlib import Path
from typing import Any

import numpy as np
import OpenEXR
import OpenImageIO as oiio
import pytest

from svgf_cli import heap
from svgf_cli.io import output as output_module
from svgf_cli.io import zipchunks
from svgf_cli.io.output import write_output
from svgf_cli.io.source import decode_source

REPO = Path(__file__).resolve().parents[1]
CYCLES = sorted((REPO / "testdata" / "cycles").glob("**/in.0002.exr"))


# -- the byte order and predictor, against the format's description --------------------------


def _reference_pack(raw: bytes) -> bytes:
    """OpenEXR's ZIP preprocessing written from its description, one byte at a time: bytes
    at even positions, then odd ones; then each byte minus the one before, plus 128."""
    t = list(raw[0::2]) + list(raw[1::2])
    return bytes([t[0]] + [(t[i] - t[i - 1] + 128) % 256 for i in range(1, len(t))])


def _reference_unpack(packed: bytes) -> bytes:
    """The reader's side of `_reference_pack`: running sums minus 128, halves back apart."""
    t = np.cumsum(np.frombuffer(packed, np.uint8).astype(np.int64) - 128) + 128
    t = (t % 256).astype(np.uint8)
    half = (len(packed) + 1) // 2
    raw = np.empty(len(packed), np.uint8)
    raw[0::2], raw[1::2] = t[:half], t[half:]
    return raw.tobytes()


@pytest.mark.parametrize("size", [0, 1, 2, 3, 4, 7, 64, 1001])
def test_reorder_predict_matches_the_format_and_inverts(size: int) -> None:
    raw = np.random.default_rng(size).integers(0, 256, size, dtype=np.uint8)
    packed = np.empty_like(raw)
    zipchunks.reorder_predict(raw, packed)
    if size == 0:
        return
    assert packed.tobytes() == _reference_pack(raw.tobytes())
    assert _reference_unpack(packed.tobytes()) == raw.tobytes()


# -- files written by hand against the library's --------------------------------------------


def _library_write(path: Path, header: dict[str, Any], planes: dict[str, np.ndarray],
                   linear: dict[str, bool] | None = None) -> None:
    linear = linear or {}
    channels = {n: OpenEXR.Channel(n, p, 1, 1, linear.get(n, False)) for n, p in planes.items()}
    OpenEXR.File([OpenEXR.Part(header, channels, "")]).write(str(path))


def _decoded(path: Path) -> tuple[dict[str, Any], dict[str, tuple[np.ndarray, bool]]]:
    with OpenEXR.File(str(path), separate_channels=True) as exr:
        assert len(exr.parts) == 1
        part = exr.parts[0]
        header = {k: v for k, v in part.header.items() if k != "channels"}
        channels = {n: (c.pixels.copy(), bool(c.pLinear)) for n, c in part.channels.items()}
    return header, channels


def _same_value(a: Any, b: Any) -> bool:
    if isinstance(a, tuple):
        return len(a) == len(b) and all(_same_value(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, np.ndarray):
        return bool(np.array_equal(a, b))
    return bool(a == b)


def assert_same_file(ours: Path, theirs: Path) -> None:
    """What the library reads back from the two files is the same, attribute by attribute
    and bit for bit; OpenImageIO reads the same pixels too."""
    h1, c1 = _decoded(ours)
    h2, c2 = _decoded(theirs)
    assert list(c1) == list(c2)
    for name, (pixels, linear) in c1.items():
        assert pixels.dtype == c2[name][0].dtype, name
        assert pixels.tobytes() == c2[name][0].tobytes(), name
        assert linear == c2[name][1], name
    assert set(h1) == set(h2)
    for key, value in h1.items():
        assert _same_value(value, h2[key]), key
    a, b = oiio.ImageBuf(str(ours)), oiio.ImageBuf(str(theirs))
    assert a.spec().nchannels == b.spec().nchannels
    assert np.array_equal(a.get_pixels(oiio.FLOAT), b.get_pixels(oiio.FLOAT), equal_nan=True)


def _hand_write(path: Path, template: Path, planes: dict[str, np.ndarray],
                linear: dict[str, bool] | None = None, threads: int = 0) -> None:
    """Write ``planes`` with ``template``'s header attributes as stored, by `zipchunks`."""
    with open(template, "rb") as fh:
        attributes = zipchunks.read_raw_header(fh).attributes
    writer = zipchunks.ChunkWriter(attributes, planes, linear or {})
    with open(path, "wb") as fh:
        writer.write(fh, threads)


def _mixed_planes(height: int, width: int, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    smooth = np.linspace(0, 4, height * width, dtype=np.float32).reshape(height, width)
    return {
        "R": (smooth * rng.exponential(1, (height, width))).astype(np.float16),
        "G": smooth.astype(np.float16),
        "B": np.zeros((height, width), np.float16),
        "Z": rng.random((height, width), dtype=np.float32) * 1e3,  # incompressible-ish
        "id": rng.integers(0, 2**32, (height, width), dtype=np.uint32),
        "a.much.longer.channel.name.than.thirty.one.bytes": smooth,
    }


@pytest.mark.parametrize("codec", [OpenEXR.ZIP_COMPRESSION, OpenEXR.ZIPS_COMPRESSION])
@pytest.mark.parametrize("window", [(0, 0, 37, 21), (-5, -9, 16, 35), (3, 17, 1, 1),
                                    (0, 0, 5, 32)])
def test_written_file_reads_back_as_the_library_writes_it(
    tmp_path: Path, codec: Any, window: tuple[int, int, int, int]
) -> None:
    """Half, float and uint channels, a long name, windows off the origin and a last chunk
    shorter than the others: the library and OpenImageIO read exactly what was given."""
    x0, y0, width, height = window
    box = (np.array([x0, y0], np.int32), np.array([x0 + width - 1, y0 + height - 1], np.int32))
    header = {
        "compression": codec, "type": OpenEXR.scanlineimage, "dataWindow": box,
        "displayWindow": box, "owner": "svgf tests", "frames": 12,
        "worldToCamera": np.arange(16, dtype=np.float32).reshape(4, 4),
        "strings": ["one", "two"], "pixelAspectRatio": 1.5, "empty": "",
    }
    planes = _mixed_planes(height, width)
    linear = {"G": True}
    theirs, ours = tmp_path / "lib.exr", tmp_path / "ours.exr"
    _library_write(theirs, header, planes, linear)
    _hand_write(ours, theirs, planes, linear)
    assert_same_file(ours, theirs)
    assert_chunk_table(ours, 16 if codec == OpenEXR.ZIP_COMPRESSION else 1)
    # Magic and version flags as the library's (the long-names flag: a 49-byte name).
    assert ours.read_bytes()[:8] == theirs.read_bytes()[:8]
    assert struct.unpack("<i", ours.read_bytes()[4:8])[0] & zipchunks.LONG_NAMES
    _, channels = _decoded(ours)
    for name, plane in planes.items():
        assert channels[name][0].tobytes() == plane.tobytes(), name


def _zip_pair(folder: Path, planes: dict[str, np.ndarray]) -> tuple[Path, Path]:
    """``planes`` (all of one shape, window at the origin) written by the library (ZIP) and,
    with its header, by `zipchunks`: (ours, theirs)."""
    height, width = next(iter(planes.values())).shape
    box = (np.array([0, 0], np.int32), np.array([width - 1, height - 1], np.int32))
    theirs, ours = folder / "lib.exr", folder / "ours.exr"
    _library_write(theirs, {"compression": OpenEXR.ZIP_COMPRESSION, "dataWindow": box,
                            "displayWindow": box}, planes)
    _hand_write(ours, theirs, planes)
    return ours, theirs


def assert_chunk_table(path: Path, lines: int) -> None:
    """The offset table holds one entry per chunk of ``lines`` lines, the first chunk
    starts right after it, each chunk right after the one before, and the file ends with
    the last one: nothing missing, nothing extra."""
    data = path.read_bytes()
    with open(path, "rb") as fh:
        header = zipchunks.read_raw_header(fh)
    box = next(a for a in header.attributes if a.name == "dataWindow").value
    _, y0, _, y1 = struct.unpack("<iiii", box)
    count = (y1 - y0 + lines) // lines
    positions = struct.unpack_from(f"<{count}Q", data, header.end)
    at = header.end + 8 * count
    for index, position in enumerate(positions):
        assert position == at, index
        y, size = struct.unpack_from("<ii", data, position)
        assert y == y0 + index * lines
        at = position + 8 + size
    assert at == len(data)


def _first_chunk(path: Path) -> tuple[int, bytes]:
    """The first chunk of a single-part scanline file: its y and its stored bytes."""
    with open(path, "rb") as fh:
        header = zipchunks.read_raw_header(fh)
        fh.seek(header.end)
        (position,) = struct.unpack("<Q", fh.read(8))
        fh.seek(position)
        y, size = struct.unpack("<ii", fh.read(8))
        return y, fh.read(size)


def test_chunks_that_do_not_shrink_are_stored_as_they_are(tmp_path: Path) -> None:
    """Random float bits do not deflate: the chunk is stored raw (size == its lines' bytes),
    as the library stores it, and still reads back."""
    planes = {"R": np.random.default_rng(3).random((16, 64), dtype=np.float32)}
    ours, theirs = _zip_pair(tmp_path, planes)
    _, data = _first_chunk(ours)
    assert data == planes["R"].tobytes()
    assert_same_file(ours, theirs)


def test_deflated_chunks_are_zlib_streams_of_the_predicted_bytes(tmp_path: Path) -> None:
    """The first chunk, inflated by zlib and undone by the format's description, is the
    channels' rows in name order."""
    planes = {"B": np.full((16, 8), 0.5, np.float16), "A": np.ones((16, 8), np.float16)}
    ours, _ = _zip_pair(tmp_path, planes)
    y, data = _first_chunk(ours)
    packed = zlib.decompress(data)
    raw = np.frombuffer(_reference_unpack(packed), np.uint8)
    assert _reference_pack(raw.tobytes()) == packed
    rows = raw.reshape(16, 2, 8 * 2)  # line, channel (A then B), bytes
    assert y == 0
    assert rows[:, 0].tobytes() == planes["A"].tobytes()
    assert rows[:, 1].tobytes() == planes["B"].tobytes()


def test_a_chunk_deflated_in_pieces_is_one_zlib_stream(tmp_path: Path) -> None:
    """A chunk of more than ``DEFLATE_PIECE`` bytes is deflated and written in pieces, each
    well below the heap's mapping threshold, that make one zlib stream of the chunk."""
    rng = np.random.default_rng(3)
    planes = {c: (rng.random((16, 6000)) * 4).round(2).astype(np.float32) for c in "RGB"}
    ours, theirs = _zip_pair(tmp_path, planes)
    _, data = _first_chunk(ours)
    raw = np.frombuffer(_reference_unpack(zlib.decompress(data)), np.uint8)
    assert raw.size == 16 * 6000 * 4 * 3 > 2 * zipchunks.DEFLATE_PIECE
    assert_same_file(ours, theirs)
    pieces = zipchunks.deflate_pieces(raw.copy())
    assert len(pieces) > 2
    assert max(len(piece) for piece in pieces) < heap.MMAP_THRESHOLD
    assert zlib.decompress(b"".join(pieces)) == raw.tobytes()
    assert zlib.decompress(b"".join(zipchunks.deflate_pieces(raw[:0].copy()))) == b""


def test_encoding_is_deterministic_and_thread_count_free(tmp_path: Path) -> None:
    planes = _mixed_planes(70, 33, seed=5)
    box = (np.array([0, 0], np.int32), np.array([32, 69], np.int32))
    template = tmp_path / "lib.exr"
    _library_write(template, {"compression": OpenEXR.ZIP_COMPRESSION, "dataWindow": box,
                              "displayWindow": box}, planes)
    files = []
    for threads in (0, 2, 3, 0):
        path = tmp_path / f"ours{len(files)}.exr"
        _hand_write(path, template, planes, threads=threads)
        files.append(path.read_bytes())
    assert all(f == files[0] for f in files)


def test_streams_of_noise_are_the_same_bytes_whatever_the_heap_held(tmp_path: Path) -> None:
    """A chunk of 1-spp-like noise deflated in many pieces (a production chunk's case) gives
    the same bytes every time, on any thread count and whatever freed memory the heap hands
    the compressor (ISA-L's deflate, used before, did not on 1080p production frames: two or
    three different files from ten writes of the same planes)."""
    rng = np.random.default_rng(11)
    planes = {}
    for name in ("A", "B", "G", "R", "Z", "N.X", "N.Y", "N.Z"):
        plane = rng.gamma(0.4, 1.0, (32, 6000)).astype(np.float16)
        plane[rng.random(plane.shape) < 0.4] = 0
        planes[name] = plane
    box = (np.array([0, 0], np.int32), np.array([5999, 31], np.int32))
    template = tmp_path / "lib.exr"
    _library_write(template, {"compression": OpenEXR.ZIP_COMPRESSION, "dataWindow": box,
                              "displayWindow": box}, planes)
    files = []
    for threads in (0, 2, 0, 2, 3):
        # Freed blocks full of other bytes, for the compressor's state to be carved from.
        litter = [bytearray(rng.bytes(size)) for size in (1 << 16, 300_000, 1 << 20, 5000)]
        del litter
        path = tmp_path / f"ours{len(files)}.exr"
        _hand_write(path, template, planes, threads=threads)
        files.append(path.read_bytes())
    assert all(f == files[0] for f in files)
    _, data = _first_chunk(tmp_path / "ours0.exr")
    raw = np.frombuffer(zlib.decompress(data), np.uint8)
    assert raw.size > 4 * zipchunks.DEFLATE_PIECE
    assert len(zipchunks.deflate_pieces(raw.copy())) > 4
    assert_same_file(tmp_path / "ours0.exr", template)


# -- what the writer declines -----------------------------------------------------------------


def _raw(attributes: dict[str, bytes | tuple[str, bytes]]) -> list[zipchunks.RawAttribute]:
    box = struct.pack("<iiii", 0, 0, 3, 1)
    base: dict[str, tuple[str, bytes]] = {"compression": ("compression", bytes([3])),
                                          "dataWindow": ("box2i", box),
                                          "displayWindow": ("box2i", box)}
    base.update({k: v for k, v in attributes.items() if isinstance(v, tuple)})
    return [zipchunks.RawAttribute(k, t, v) for k, (t, v) in base.items()]


@pytest.mark.parametrize(
    "change",
    [
        {"compression": ("compression", bytes([4]))},  # PIZ
        {"lineOrder": ("lineOrder", bytes([1]))},  # decreasing y
        {"dataWindow": ("box2i", struct.pack("<iiii", 0, 0, -1, 1))},  # empty
    ],
)
def test_writer_declines_what_it_does_not_encode(change: dict[str, tuple[str, bytes]]) -> None:
    planes = {"R": np.zeros((2, 4), np.float16)}
    with pytest.raises(zipchunks.Declined):
        zipchunks.ChunkWriter(_raw(change), planes, {})


def test_writer_declines_planes_off_the_window_or_of_other_types() -> None:
    with pytest.raises(zipchunks.Declined):
        zipchunks.ChunkWriter(_raw({}), {"R": np.zeros((3, 4), np.float16)}, {})
    with pytest.raises(zipchunks.Declined):
        zipchunks.ChunkWriter(_raw({}), {"R": np.zeros((2, 4), np.float64)}, {})
    zipchunks.ChunkWriter(_raw({}), {"R": np.zeros((2, 4), np.float16)}, {})  # accepted


def test_header_reader_declines_multipart_and_truncated_files(tmp_path: Path) -> None:
    box = (np.array([0, 0], np.int32), np.array([3, 1], np.int32))
    parts = [OpenEXR.Part({"compression": OpenEXR.ZIP_COMPRESSION, "dataWindow": box,
                           "displayWindow": box}, {"R": OpenEXR.Channel("R", np.zeros((2, 4),
                                                                                 np.float16))},
                          name) for name in ("a", "b")]
    path = tmp_path / "multi.exr"
    OpenEXR.File(parts).write(str(path))
    with open(path, "rb") as fh, pytest.raises(zipchunks.Declined):
        zipchunks.read_raw_header(fh)
    single = tmp_path / "single.exr"
    OpenEXR.File(parts[:1]).write(str(single))
    data = single.read_bytes()
    with open(single, "rb") as fh:
        end = zipchunks.read_raw_header(fh).end
    for cut in (4, 7, 12, end - 1):
        with pytest.raises(zipchunks.Declined):
            zipchunks.read_raw_header(io.BytesIO(data[:cut]))


# -- through write_output: the drop-in file is the library's, faster ------------------------


@pytest.mark.parametrize("path", CYCLES, ids=lambda p: str(p.parent.relative_to(REPO)))
def test_drop_in_output_matches_the_library_writer(
    tmp_path: Path, path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Every committed Cycles frame (ZIP, half and float, Cryptomatte manifests, Blender's
    attributes) with its colour replaced and svgf's attributes added: what `zipchunks`
    writes reads back exactly as what the library writes."""
    source = decode_source(path)
    part = source.parts[0]
    assert part.raw is not None
    names = [n for n in part.channels if n.endswith((".R", ".G", ".B")) and "Combined." in n]
    assert names
    colour = {n: (part.channels[n].pixels * 0.5).astype(part.channels[n].pixels.dtype)
              for n in names}
    attrs = {"svgf/preset": "default", "svgf/frame": 2}
    ours, theirs = tmp_path / "ours.exr", tmp_path / "lib.exr"
    write_output(ours, source, part_index=0, channels=colour, attributes=attrs, software="svgf")
    with monkeypatch.context() as patched:
        patched.setattr(output_module, "_chunk_writer", lambda out: None)
        write_output(theirs, source, part_index=0, channels=colour, attributes=attrs,
                     software="svgf")
    assert ours.read_bytes() != theirs.read_bytes()  # really two writers
    assert_same_file(ours, theirs)
    assert_chunk_table(ours, 16)
    header, _ = _decoded(ours)
    assert header["svgf/preset"] == "default" and header["svgf/frame"] == 2
    assert "svgf" in header["Software"]


def test_other_codecs_and_multipart_files_go_to_the_library(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    calls: list[int] = []
    real = zipchunks.ChunkWriter.write

    def counting(self: zipchunks.ChunkWriter, fh: Any, threads: int = 0) -> None:
        calls.append(1)
        real(self, fh, threads)

    monkeypatch.setattr(zipchunks.ChunkWriter, "write", counting)
    source = decode_source(CYCLES[0])
    colour = {"ViewLayer.Combined.R": source.parts[0].channels["ViewLayer.Combined.R"].pixels}
    for codec, expected in (("piz", 0), ("rle", 0), ("zips", 1), (None, 1)):
        calls.clear()
        out = tmp_path / f"{codec}.exr"
        write_output(out, source, part_index=0, channels=colour, attributes={},
                     compression=codec)
        assert len(calls) == expected, codec
        assert decode_source(out).parts[0].channels["ViewLayer.Combined.R"].pixels.tobytes() \
            == colour["ViewLayer.Combined.R"].tobytes()


def test_a_new_files_attributes_are_the_librarys_defaults(tmp_path: Path) -> None:
    """`scanline_attributes` (the bidirectional run's scratch files): a file the library
    reads back with the same header as its own file of the same planes, plus the string."""
    planes = {"a": np.full((5, 7), 0.25, np.float16), "b": np.arange(35, dtype=np.float32)
              .reshape(5, 7)}
    theirs, ours = tmp_path / "lib.exr", tmp_path / "ours.exr"
    _library_write(theirs, {"compression": OpenEXR.ZIP_COMPRESSION, "note": "x é"}, planes)
    writer = zipchunks.ChunkWriter(
        zipchunks.scanline_attributes(7, 5, strings={"note": "x é"}), planes, {})
    with open(ours, "wb") as fh:
        writer.write(fh)
    assert_same_file(ours, theirs)


def test_a_disk_that_fills_mid_write_leaves_nothing_half_written(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The chunk writer fails after some chunks (ENOSPC): one line naming the output and the
    system's reason, the earlier output untouched, no temporary left."""
    source = decode_source(CYCLES[0])
    colour = {"ViewLayer.Combined.R": source.parts[0].channels["ViewLayer.Combined.R"].pixels}
    target = tmp_path / "out" / "o.0001.exr"
    target.parent.mkdir()
    target.write_bytes(b"previous frame")
    real = zipchunks.ChunkWriter.write

    def filling(self: zipchunks.ChunkWriter, fh: Any, threads: int = 0) -> None:
        class Full(io.RawIOBase):
            written = 0

            def write(self, data: Any) -> int:
                Full.written += len(data)
                if Full.written > 4096:
                    raise OSError(28, "No space left on device")
                return fh.write(data)

            def tell(self) -> int:
                return fh.tell()

            def seek(self, *args: Any) -> int:
                return fh.seek(*args)

        real(self, Full(), threads)

    monkeypatch.setattr(zipchunks.ChunkWriter, "write", filling)
    with pytest.raises(Exception, match="No space left on device") as raised:
        write_output(target, source, part_index=0, channels=colour, attributes={})
    message = str(raised.value)
    assert message == f"{target}: cannot write: No space left on device", message
    assert target.read_bytes() == b"previous frame"
    assert [p.name for p in target.parent.iterdir()] == ["o.0001.exr"]


@pytest.mark.parametrize("length", [31, 32])
def test_the_long_names_flag_starts_at_32_bytes(tmp_path: Path, length: int) -> None:
    """Names of up to 31 bytes fit the original format; 32 need the long-names flag (the
    library's version bytes, for a channel and for an attribute name)."""
    name = "n" * length
    for planes, header in (({name: np.zeros((2, 3), np.float16)}, {}),
                           ({"R": np.zeros((2, 3), np.float16)}, {name: "x"})):
        box = (np.array([0, 0], np.int32), np.array([2, 1], np.int32))
        theirs, ours = tmp_path / "lib.exr", tmp_path / "ours.exr"
        _library_write(theirs, {"compression": OpenEXR.ZIP_COMPRESSION, "dataWindow": box,
                                "displayWindow": box, **header}, planes)
        _hand_write(ours, theirs, planes)
        assert ours.read_bytes()[:8] == theirs.read_bytes()[:8]
        flags = struct.unpack("<i", ours.read_bytes()[4:8])[0]
        assert bool(flags & zipchunks.LONG_NAMES) == (length > 31)


def test_writer_declines_a_header_without_codec_or_with_a_bad_window() -> None:
    planes = {"R": np.zeros((2, 4), np.float16)}
    attributes = [a for a in _raw({}) if a.name != "compression"]
    with pytest.raises(zipchunks.Declined):
        zipchunks.ChunkWriter(attributes, planes, {})
    for box in (("box2f", struct.pack("<iiii", 0, 0, 3, 1)), ("box2i", b"\0" * 12)):
        with pytest.raises(zipchunks.Declined):
            zipchunks.ChunkWriter(_raw({"dataWindow": box}), planes, {})
