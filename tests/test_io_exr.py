"""EXR reading and writing: round trips, channel lookup, bad files, input hygiene."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import OpenEXR
import OpenImageIO as oiio
import pytest

from svgf_cli.errors import InputError, UsageError
from svgf_cli.io import exr
from svgf_cli.io.exr import (
    ExrWriteError,
    check_compression,
    read_frame,
    read_info,
    read_rgb,
    write_exr,
)
from svgf_cli.io.layers import build_mapping
from svgf_cli.io.output import write_output

H, W = 6, 8


def gbuffer(seed: int = 0, split: bool = False) -> dict[str, np.ndarray]:
    """A small, valid svgf-convention frame with distinct values per channel."""
    rng = np.random.default_rng(seed)
    channels: dict[str, np.ndarray] = {}
    layers = ("direct", "indirect", "albedo") if split else ("albedo",)
    for layer in layers:
        for c in "RGB":
            channels[f"{layer}.{c}"] = rng.uniform(0.1, 1.0, (H, W))
    for c in "RGB":
        channels[c] = rng.uniform(0.1, 1.0, (H, W))
    normal = rng.normal(size=(3, H, W))
    normal /= np.linalg.norm(normal, axis=0)
    for c, plane in zip("XYZ", normal, strict=True):
        channels[f"N.{c}"] = plane
    channels["Z"] = rng.uniform(1.0, 10.0, (H, W))
    channels["motion.X"] = rng.uniform(-2, 2, (H, W))
    channels["motion.Y"] = rng.uniform(-2, 2, (H, W))
    return {k: v.astype(np.float32) for k, v in channels.items()}


def planes(channels: dict[str, np.ndarray], *names: str) -> np.ndarray:
    return np.stack([channels[n] for n in names])


def test_round_trip_half_float_and_attributes(tmp_path: Path) -> None:
    channels = gbuffer()
    matrix = np.arange(16, dtype=np.float32).reshape(4, 4) / 7
    attributes = {"worldToCamera": matrix, "owner": "svgf test", "framesPerSecond": 24.0}
    half = {"R": True, "G": True, "B": True}
    path = tmp_path / "rt.exr"
    write_exr(path, channels, attributes=attributes, half=half, compression="piz")

    info = read_info(path)
    assert (info.width, info.height) == (W, H)
    assert sorted(info.channels) == sorted(channels)
    assert info.channel_type("R") == "half" and info.channel_type("Z") == "float"
    assert info.compression == "piz"
    assert np.array_equal(info.attributes["worldToCamera"], matrix)
    assert info.attributes["Copyright"] == "svgf test"  # OIIO's name for EXR "owner"
    assert not any(k.startswith("oiio:") or k == "compression" for k in info.attributes)

    colour, _ = read_rgb(path)
    expected = planes(channels, "R", "G", "B")
    assert colour.shape == (3, H, W) and colour.dtype == np.float32
    assert np.allclose(colour, expected, rtol=1e-3) and not np.array_equal(colour, expected)

    # Attributes read back can be written again unchanged (pass-through).
    again = tmp_path / "again.exr"
    write_exr(again, {"R": colour[0]}, attributes=info.attributes)
    carried = read_info(again).attributes
    assert np.array_equal(carried["worldToCamera"], matrix)
    assert carried["screenWindowCenter"] == info.attributes["screenWindowCenter"]


def test_writes_are_deterministic_and_atomic(tmp_path: Path) -> None:
    channels = gbuffer()
    write_exr(tmp_path / "a.exr", channels)
    write_exr(tmp_path / "b.exr", channels)
    assert (tmp_path / "a.exr").read_bytes() == (tmp_path / "b.exr").read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.exr", "b.exr"]


def test_read_frame_by_name_regardless_of_order(tmp_path: Path) -> None:
    channels = gbuffer(split=True)
    shuffled = dict(reversed(list(channels.items())))
    path = tmp_path / "f.exr"
    write_exr(path, shuffled)
    result = read_frame(path, build_mapping())
    frame = result.frame
    frame.validate()
    assert result.warnings == []
    assert frame.names == ("direct", "indirect")
    direct, indirect = (s.radiance for s in frame.signals)
    assert np.array_equal(direct, planes(channels, "direct.R", "direct.G", "direct.B"))
    assert np.array_equal(indirect, planes(channels, "indirect.R", "indirect.G", "indirect.B"))
    assert np.array_equal(frame.albedo, planes(channels, "albedo.R", "albedo.G", "albedo.B"))
    assert np.allclose(frame.normal, planes(channels, "N.X", "N.Y", "N.Z"), atol=1e-6)
    assert np.array_equal(frame.depth, channels["Z"])
    assert np.array_equal(frame.motion, planes(channels, "motion.X", "motion.Y"))
    assert np.array_equal(frame.mesh_id, np.zeros((H, W), np.int32))  # no id: 0 on geometry
    assert result.alpha is None


def test_normal_rgb_fallback_and_cycles_motion(tmp_path: Path) -> None:
    channels = gbuffer()
    for a, b in zip("XYZ", "RGB", strict=True):
        channels[f"N.{b}"] = channels.pop(f"N.{a}")
    channels["Vector.X"] = channels.pop("motion.X")
    channels["Vector.Y"] = channels.pop("motion.Y")
    path = tmp_path / "f.exr"
    write_exr(path, channels)
    mapping = build_mapping("svgf", ["motion=Vector.X,Vector.Y"], motion_convention="cycles")
    frame = read_frame(path, mapping).frame
    assert np.allclose(frame.normal, planes(channels, "N.R", "N.G", "N.B"), atol=1e-6)
    assert np.array_equal(frame.motion[0], channels["Vector.X"])
    assert np.array_equal(frame.motion[1], -channels["Vector.Y"])
    # An explicit convention wins over the mapping's.
    forward = read_frame(path, mapping, "forward-pixels").frame
    assert np.array_equal(forward.motion[0], -channels["Vector.X"])


def test_scrubbing_counts_and_g_buffer_rules(tmp_path: Path) -> None:
    channels = gbuffer(split=True)
    channels["direct.G"][0, :3] = [np.nan, np.inf, -np.inf]
    channels["indirect.B"][1, :2] = [-0.5, -2.0]
    channels["albedo.R"][2, 0] = np.nan
    channels["motion.Y"][3, 3] = np.nan
    channels["N.X"][0, 0], channels["N.Y"][0, 0], channels["N.Z"][0, 0] = np.nan, 3.0, 4.0
    channels["N.X"][0, 1], channels["N.Y"][0, 1], channels["N.Z"][0, 1] = 0.0, 0.0, 0.0
    channels["N.X"][0, 2], channels["N.Y"][0, 2], channels["N.Z"][0, 2] = 0.0, 0.3, 0.4
    channels["Z"][5, :4] = [np.nan, -1.0, 0.0, np.inf]
    channels["Z"][5, 4] = 1e10  # Cycles' background depth
    channels["id"] = np.full((H, W), 2.6, np.float32)
    channels["id"][4, 0] = np.nan
    channels["id"][4, 1] = -1.0
    path = tmp_path / "dirty.exr"
    write_exr(path, channels)

    result = read_frame(path, build_mapping())
    frame = result.frame
    joined = "\n".join(result.warnings)
    assert f"{path}: 3 NaN/Inf values in direct scrubbed to 0" in joined
    assert f"{path}: 2 negative values in indirect clamped to 0" in joined
    assert f"{path}: 1 NaN/Inf values in albedo scrubbed to 0" in joined
    assert f"{path}: 1 NaN/Inf values in motion scrubbed to 0" in joined
    assert f"{path}: 1 NaN/Inf values in normal scrubbed to 0" in joined
    # NaN depth is a broken pixel, not a background convention: counted (Inf, <= 0 are not).
    assert f"{path}: 1 NaN values in depth treated as background" in joined
    assert len(result.warnings) == 6
    direct, indirect = (s.radiance for s in frame.signals)
    for plane in (direct, indirect, frame.albedo, frame.motion, frame.normal):
        assert np.isfinite(plane).all()
    assert (direct >= 0).all() and (indirect >= 0).all()
    assert direct[1, 0, 0] == 0 and indirect[2, 1, 1] == 0
    assert np.allclose(frame.normal[:, 0, 0], [0.0, 0.6, 0.8])  # NaN -> 0, renormalised
    assert np.array_equal(frame.normal[:, 0, 1], [0.0, 0.0, 0.0])  # zero stays zero
    assert np.allclose(frame.normal[:, 0, 2], [0.0, 0.6, 0.8])  # too short: lengthened
    assert np.array_equal(frame.depth[5, :5], np.zeros(5, np.float32))
    assert frame.depth[5, 5] == channels["Z"][5, 5]
    assert frame.mesh_id[0, 0] == 3 and frame.mesh_id.dtype == np.int32
    assert frame.mesh_id[4, 0] == -1 and frame.mesh_id[4, 1] == -1


def test_absent_id_is_minus_one_on_background(tmp_path: Path) -> None:
    channels = gbuffer()
    channels["Z"][0, :2] = 0.0
    channels["A"] = np.full((H, W), 0.5, np.float32)
    path = tmp_path / "bg.exr"
    write_exr(path, channels)
    result = read_frame(path, build_mapping())
    assert list(result.frame.mesh_id[0, :3]) == [-1, -1, 0]
    assert result.alpha is not None and np.all(result.alpha == 0.5)
    assert result.frame.names == ("color",)


def test_multipart_channels_found_in_every_part(tmp_path: Path) -> None:
    channels = gbuffer()
    beauty = ["R", "G", "B"]
    data = [n for n in channels if n not in beauty]
    path = tmp_path / "multi.exr"
    _write_multipart(path, [("beauty", beauty, (W, H)), ("data", data, (W, H))], channels)
    info = read_info(path)
    assert info.parts == ["beauty", "data"]
    frame = read_frame(path, build_mapping()).frame
    assert np.array_equal(frame.signal("color").radiance, planes(channels, "R", "G", "B"))
    assert np.array_equal(frame.depth, channels["Z"])

    bad = tmp_path / "windows.exr"
    small = {n: v[: H - 2, : W - 2].copy() for n, v in channels.items()}
    _write_multipart(bad, [("beauty", beauty, (W, H))], channels, extra=("data", data, small))
    with pytest.raises(InputError, match="different data windows") as err:
        read_frame(bad, build_mapping())
    assert str(bad) in str(err.value)


def _write_multipart(path, parts, channels, extra=None) -> None:
    specs, buffers = [], []
    for name, names, (width, height) in parts:
        spec = oiio.ImageSpec(width, height, len(names), "float")
        spec.channelnames = tuple(names)
        spec.attribute("oiio:subimagename", name)
        specs.append(spec)
        buffers.append(np.ascontiguousarray(np.stack([channels[n] for n in names], -1)))
    if extra is not None:
        name, names, source = extra
        height, width = source[names[0]].shape
        spec = oiio.ImageSpec(width, height, len(names), "float")
        spec.full_width, spec.full_height = W, H  # same display window, smaller data window
        spec.channelnames = tuple(names)
        spec.attribute("oiio:subimagename", name)
        specs.append(spec)
        buffers.append(np.ascontiguousarray(np.stack([source[n] for n in names], -1)))
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), specs)
    for index, (spec, buffer) in enumerate(zip(specs, buffers, strict=True)):
        if index:
            assert out.open(str(path), spec, "AppendSubimage")
        assert out.write_image(buffer)
    assert out.close()


def test_truncated_file_is_an_input_error(tmp_path: Path) -> None:
    good = tmp_path / "good.exr"
    write_exr(good, gbuffer(), compression="zip")
    data = good.read_bytes()
    mapping = build_mapping()
    for cut in (len(data) // 2, 120):
        path = tmp_path / f"cut{cut}.exr"
        path.write_bytes(data[:cut])
        with pytest.raises(InputError) as err:
            read_frame(path, mapping)
        message = str(err.value)
        assert message.startswith(f"{path}: ") and "\n" not in message
        assert err.value.exit_code == 3
        with pytest.raises(InputError):
            read_rgb(path)


def test_missing_and_non_exr_files(tmp_path: Path) -> None:
    text = tmp_path / "notes.exr"
    text.write_text("not an image")
    with pytest.raises(InputError, match="not an OpenEXR file"):
        read_info(text)
    with pytest.raises(InputError, match="file not found"):
        read_frame(tmp_path / "nope.exr", build_mapping())
    with pytest.raises(InputError, match="directory"):
        read_info(tmp_path)
    path = tmp_path / "no_rgb.exr"
    write_exr(path, {"Z": np.ones((H, W), np.float32)})
    with pytest.raises(InputError, match="missing channel"):
        read_rgb(path)
    with pytest.raises(InputError, match=r"missing channel\(s\) for albedo"):
        read_frame(path, build_mapping())


def test_compression_rules() -> None:
    colour = ["R", "G", "B", "A", "diffuse.R", "diffuse.A"]
    for lossy in ("dwaa", "DWAB:45", "b44", "b44a"):
        check_compression(lossy, colour)
        with pytest.raises(UsageError, match="N.Y"):
            check_compression(lossy, [*colour, "N.X", "N.Y"])
    with pytest.raises(UsageError, match="motion.X"):
        check_compression("pxr24", ["R", "motion.X"])
    check_compression("pxr24", ["R", "motion.X"], float_channels=["R"])
    for lossless in ("zip", "zips", "piz", "none", "rle", "zip:4"):
        check_compression(lossless, [*colour, "Z", "N.X"])
    with pytest.raises(UsageError, match="unknown EXR compression"):
        check_compression("jpeg", colour)


def test_lossy_write_refused_leaves_nothing(tmp_path: Path) -> None:
    with pytest.raises(UsageError):
        write_exr(tmp_path / "o.exr", gbuffer(), compression="dwaa")
    write_exr(tmp_path / "rgb.exr", {c: np.ones((H, W)) for c in "RGB"}, compression="dwaa")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rgb.exr"]


def test_failed_write_leaves_no_temp_file(tmp_path: Path, monkeypatch) -> None:
    real_create = oiio.ImageOutput.create

    class FailingOutput:
        def __init__(self, name: str) -> None:
            self.inner = real_create(name)

        def open(self, *args):
            return self.inner.open(*args)

        def write_image(self, pixels) -> bool:
            return False  # as OIIO does for a non-contiguous buffer

        def geterror(self) -> str:
            return "simulated failure"

        def close(self) -> bool:
            return self.inner.close()

    monkeypatch.setattr(exr.oiio.ImageOutput, "create", staticmethod(FailingOutput))
    target = tmp_path / "out.exr"
    target.write_bytes(b"previous")
    with pytest.raises(ExrWriteError, match="simulated failure"):
        write_exr(target, {"R": np.ones((H, W))})
    assert sorted(os.listdir(tmp_path)) == ["out.exr"]
    assert target.read_bytes() == b"previous"  # the old file is untouched


def test_write_into_missing_directory_fails_cleanly(tmp_path: Path) -> None:
    with pytest.raises(ExrWriteError) as err:
        write_exr(tmp_path / "missing" / "o.exr", {"R": np.ones((H, W))})
    assert "o.exr" in str(err.value)
    assert list(tmp_path.iterdir()) == []


def test_without_an_id_every_surface_pixel_is_one_mesh(tmp_path: Path) -> None:
    # No id channel: mesh 0 wherever there is a surface, at any depth; -1 on background.
    channels = gbuffer(seed=4)
    channels["Z"][0, :3] = [0.25, 1.0, 0.0]
    write_exr(tmp_path / "f.exr", channels)
    frame = read_frame(tmp_path / "f.exr", build_mapping()).frame
    assert frame.mesh_id[0, :3].tolist() == [0, 0, -1]
    assert np.all(frame.mesh_id[1:] == 0)


@pytest.mark.parametrize("tiled", [False, True])
def test_offset_data_window_and_tiled(tmp_path: Path, tiled: bool) -> None:
    channels = gbuffer(seed=3)
    names = list(channels)
    spec = oiio.ImageSpec(W, H, len(names), "float")
    spec.channelnames = tuple(names)
    spec.x, spec.y, spec.full_width, spec.full_height = 3, 5, W + 10, H + 10
    if tiled:
        spec.tile_width = spec.tile_height = 16
    path = tmp_path / "window.exr"
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec)
    assert out.write_image(np.ascontiguousarray(np.stack([channels[n] for n in names], -1)))
    assert out.close()
    result = read_frame(path, build_mapping())
    frame = result.frame
    assert np.array_equal(frame.signal("color").radiance, planes(channels, "R", "G", "B"))
    assert np.array_equal(frame.depth, channels["Z"])
    assert np.array_equal(frame.motion, planes(channels, "motion.X", "motion.Y"))
    # Written back: one-level tiles (or scanlines) stay as they are, nothing to note.
    colour = {c: channels[c] for c in "RGB"}
    assert write_output(tmp_path / "o.exr", result.source, part_index=0, channels=colour,
                        attributes={}) == []


def test_half_colour_and_uint_id_channels_decode_exactly(tmp_path: Path) -> None:
    """Mixed channel types as renderers write them: half radiance, float data, uint ids
    (written with the OpenEXR bindings: OpenImageIO would normalise a float buffer into a
    uint channel)."""
    import OpenEXR

    channels = gbuffer(seed=5, split=True)
    ids = (np.arange(H * W, dtype=np.uint32).reshape(H, W) % 7) * 1000 + 5
    ids[0, 0] = 2**32 - 1  # beyond int32: clamped, not wrapped
    half = {n for n in channels if n.split(".")[0] in ("R", "G", "B", "direct", "indirect")}
    data: dict[str, np.ndarray] = {
        n: (v.astype(np.float16) if n in half else v) for n, v in channels.items()
    }
    data["id"] = ids
    path = tmp_path / "mixed.exr"
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, data) as out:
        out.write(str(path))
    frame = read_frame(path, build_mapping()).frame
    as_half = channels["direct.R"].astype(np.float16).astype(np.float32)
    assert np.array_equal(frame.signal("direct").radiance[0], as_half)
    assert np.array_equal(frame.depth, channels["Z"])  # float data stays exact
    assert frame.mesh_id[0, 0] == np.iinfo(np.int32).max
    assert np.array_equal(frame.mesh_id.ravel()[1:], ids.ravel()[1:].astype(np.int32))


def test_lossy_refusal_lists_at_most_six_data_channels() -> None:
    six = ["Z", "N.X", "N.Y", "N.Z", "motion.X", "motion.Y"]
    with pytest.raises(UsageError) as refused:
        check_compression("dwaa", ["R", *six])
    assert "motion.Y; use zip" in str(refused.value) and "..." not in str(refused.value)
    with pytest.raises(UsageError) as refused:
        check_compression("dwaa", ["R", *six, "id"])
    assert "motion.Y ...; use zip" in str(refused.value) and "id" not in str(refused.value)


def test_io_threads_grow_the_openexr_pool_to_what_was_asked() -> None:
    # `--threads N` decodes with N threads: the library's global pool must hold them.
    pool, asked = OpenEXR.global_thread_count(), exr.io_threads()
    settings = [oiio.get_int_attribute(name) for name in ("threads", "exr_threads")]
    try:
        exr.set_io_threads(pool + 2)
        assert exr.io_threads() == pool + 2
        assert OpenEXR.global_thread_count() == pool + 2
    finally:
        OpenEXR.set_global_thread_count(pool)
        exr.set_io_threads(asked)
        for name, value in zip(("threads", "exr_threads"), settings, strict=True):
            oiio.attribute(name, value)


def test_the_colour_input_is_not_held_after_the_read(tmp_path: Path) -> None:
    # The writer replaces the colour: its input pixels are let go as soon as the frame is
    # read (a 1080p float colour layer is 25 MB per frame in flight).
    path = tmp_path / "in.exr"
    write_exr(path, gbuffer())
    result = read_frame(path, build_mapping())
    for name in result.colour_channels:
        assert result.source.part_holding(name).channels[name].pixels is None
    assert result.source.part_holding("albedo.R").channels["albedo.R"].pixels is not None


def test_a_minus_infinity_in_motion_is_scrubbed(tmp_path: Path) -> None:
    # Only the lowest value is off (no NaN, nothing above): still found and set to 0.
    channels = gbuffer()
    channels["motion.X"] = np.asarray(channels["motion.X"], np.float32).copy()
    channels["motion.X"][1, 2] = -np.inf
    path = tmp_path / "in.exr"
    write_exr(path, channels)
    result = read_frame(path, build_mapping())
    assert np.isfinite(result.frame.motion).all()
    assert result.warnings == [f"{path}: 1 NaN/Inf values in motion scrubbed to 0"]


def test_decoding_is_single_threaded_until_threads_are_set() -> None:
    # A library user who never calls set_io_threads decodes in the calling thread (0), and
    # the OpenEXR pool is left as the library made it. A fresh interpreter: tests set it.
    code = ("import OpenEXR; before = OpenEXR.global_thread_count(); "
            "from svgf_cli.io import exr; "
            "print(exr.io_threads(), OpenEXR.global_thread_count() == before)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    assert done.stdout.split() == ["0", "True"]


@pytest.mark.parametrize("scale", [3.0, 1e7, 2.1e9, 3e9])
@pytest.mark.parametrize("broken", [None, np.nan, np.inf, -np.inf])
def test_mesh_ids_match_a_float64_rounding(scale: float, broken: float | None) -> None:
    rng = np.random.default_rng(7)
    raw = (rng.standard_normal((9, 11)) * scale).astype(np.float32)
    edge = float(np.nextafter(np.float32(2**31), np.float32(0)))  # largest float32 < 2^31
    raw.ravel()[:7] = [0.5, 1.5, 2.5, -0.5, -2.5, edge, -edge]
    if broken is not None:
        raw[4, 4] = broken
    finite = np.isfinite(raw)
    rounded = np.rint(raw.astype(np.float64))
    expected = np.where(finite, np.clip(np.nan_to_num(rounded), -(2**31 - 1), 2**31 - 1), -1)
    ids = exr.mesh_ids(raw)
    assert ids.dtype == np.int32
    assert np.array_equal(ids, expected.astype(np.int32))


def _cycles_channels(
    depth: np.ndarray | None, denoising_depth: np.ndarray
) -> dict[str, np.ndarray]:
    """A Cycles-named frame: Combined, Denoising Albedo, Normal, Vector and the depths."""
    svgf = gbuffer()
    channels = {}
    for c in "RGB":
        channels[f"ViewLayer.Combined.{c}"] = svgf[c]
        channels[f"ViewLayer.Denoising Albedo.{c}"] = svgf[f"albedo.{c}"]
    for c in "XYZ":
        channels[f"ViewLayer.Normal.{c}"] = svgf[f"N.{c}"]
    channels["ViewLayer.Vector.X"] = svgf["motion.X"]
    channels["ViewLayer.Vector.Y"] = svgf["motion.Y"]
    if depth is not None:
        channels["ViewLayer.Depth.Z"] = depth.astype(np.float32)
    channels["ViewLayer.Denoising Depth.Z"] = denoising_depth.astype(np.float32)
    return channels


def test_a_depth_with_no_surface_falls_back_to_the_next_candidate(tmp_path: Path) -> None:
    # Cycles writes Depth from sample 0 only: rendered with a sample offset, every pixel
    # holds its background value 1e10, while Denoising Depth averages the samples.
    surface = np.random.default_rng(3).uniform(1.0, 10.0, (H, W))
    path = tmp_path / "offset.exr"
    write_exr(path, _cycles_channels(np.full((H, W), 1e10), surface))
    result = read_frame(path, build_mapping("cycles"))
    assert np.array_equal(result.frame.depth, surface.astype(np.float32))
    assert result.resolved["depth"] == ("ViewLayer.Denoising Depth.Z",)
    assert [w for w in result.warnings if "background on every pixel" in w] == [
        f"{path}: depth ViewLayer.Depth.Z is background on every pixel (Cycles writes Depth "
        "from sample 0 only); using ViewLayer.Denoising Depth.Z"
    ]
    # The file's own channels pass through untouched.
    assert np.all(result.source.parts[0].channels["ViewLayer.Depth.Z"].pixels == 1e10)


def test_a_depth_with_a_surface_is_kept_and_an_empty_one_is_announced(tmp_path: Path) -> None:
    surface = np.random.default_rng(4).uniform(1.0, 10.0, (H, W))
    one_pixel = np.full((H, W), 1e10)
    one_pixel[2, 3] = 4.0
    path = tmp_path / "sample0.exr"
    write_exr(path, _cycles_channels(one_pixel, surface))
    result = read_frame(path, build_mapping("cycles"))
    assert result.resolved["depth"] == ("ViewLayer.Depth.Z",)
    assert result.frame.depth[2, 3] == 4.0 and np.count_nonzero(result.frame.depth) == 1
    assert not any("every pixel" in w for w in result.warnings)
    # Nothing to fall back to: said once, and the frame keeps its (all background) depth.
    empty = tmp_path / "empty.exr"
    write_exr(empty, _cycles_channels(None, np.zeros((H, W))))
    result = read_frame(empty, build_mapping("cycles"))
    assert not np.any(result.frame.depth)
    assert [w for w in result.warnings if "every pixel" in w] == [
        f"{empty}: depth ViewLayer.Denoising Depth.Z is background on every pixel: "
        "nothing is filtered"
    ]


@pytest.mark.parametrize(
    ("attributes", "expected"),
    [
        ({"cycles.ViewLayer.samples": "1"}, True),  # Cycles' sample 0: the pixel centre
        ({"cycles.ViewLayer.samples": "2"}, False),  # a sample offset: jittered
        ({"cycles.ViewLayer.samples": "128"}, False),
        ({"Software": "Arnold"}, False),
        ({}, False),
    ],
)
def test_centre_sampled_frames_are_told_by_their_header(
    tmp_path: Path, attributes: dict[str, str], expected: bool
) -> None:
    path = tmp_path / "frame.exr"
    write_exr(path, gbuffer(), attributes=attributes)
    assert read_frame(path, build_mapping()).frame.centre_sampled is expected


@pytest.mark.parametrize(
    ("attributes", "expected"),
    [
        ({"cycles.ViewLayer.samples": "1"}, 1),
        ({"cycles.ViewLayer.samples": "4"}, 4),
        ({"cycles.RenderLayer.samples": " 16 "}, 16),
        ({"cycles.ViewLayer.samples": "many"}, 1),  # not a count: the premise, 1
        ({"cycles.ViewLayer.samples": "0"}, 1),
        ({"Software": "Arnold"}, 1),
        ({}, 1),
    ],
)
def test_samples_per_pixel_are_read_from_the_header(
    tmp_path: Path, attributes: dict[str, str], expected: int
) -> None:
    path = tmp_path / "frame.exr"
    write_exr(path, gbuffer(), attributes=attributes)
    assert read_frame(path, build_mapping()).frame.samples_per_pixel == expected


def test_an_alternative_depth_in_a_part_of_another_window_is_not_needed(tmp_path: Path) -> None:
    # Cycles-named frame in one part; a second, smaller part holds another Denoising Depth
    # candidate's channel. The chosen Depth has surfaces: the file reads, the other part is
    # never asked for. Were the chosen Depth empty, the alternative could not serve either.
    surface = np.random.default_rng(5).uniform(1.0, 10.0, (H, W))
    channels = _cycles_channels(surface, surface)
    alternative = {"ViewLayer.Denoising Depth.Z": channels.pop("ViewLayer.Denoising Depth.Z")}
    path = tmp_path / "parts.exr"
    small = {n: v[: H - 2, : W - 2].copy() for n, v in alternative.items()}
    _write_multipart(path, [("main", list(channels), (W, H))], channels,
                     extra=("more", list(small), small))
    result = read_frame(path, build_mapping("cycles"))
    assert np.array_equal(result.frame.depth, surface.astype(np.float32))
    empty = tmp_path / "empty.exr"
    channels["ViewLayer.Depth.Z"] = np.full((H, W), 1e10, np.float32)
    _write_multipart(empty, [("main", list(channels), (W, H))], channels,
                     extra=("more", list(small), small))
    result = read_frame(empty, build_mapping("cycles"))
    assert not np.any(result.frame.depth)
    assert any("nothing is filtered" in w for w in result.warnings)
