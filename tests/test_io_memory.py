"""The read/write path's memory (issue 32): pass-through channels go to the writer as read
(never converted or copied), the input pixels the output writes anew are let go of as soon
as the filter has its copies, and a causal run holds a bounded number of decoded files
whatever its length. None of it changes a bit of the output.

On the committed Cycles production shot (80 channels: 55 half, 25 float, light passes,
light groups, Cryptomatte), with the light layers denoised (the CLI's default).
"""

from __future__ import annotations

import io
import threading
import weakref
from pathlib import Path
from typing import Any

import numpy as np
import OpenEXR
import pytest

from svgf_cli.filters import composable
from svgf_cli.filters.composable import LayeredDenoiser
from svgf_cli.filters.params import resolve_params
from svgf_cli.io import zipchunks
from svgf_cli.io.exr import read_frame
from svgf_cli.io.layers import build_mapping
from svgf_cli.io.output import prepare_colour, write_output
from svgf_cli.io.source import SourceFile
from svgf_cli.progress import Progress
from svgf_cli.run import light as run_light
from svgf_cli.run import output as run_output
from svgf_cli.run.chunk import run_sequence
from svgf_cli.run.output import light_replaced
from svgf_cli.run.tasks import FrameTask, RunConfig
from svgf_cli.run.workers import default_reader

ROOT = Path(__file__).resolve().parents[1]
SHOT = ROOT / "testdata/cycles/production"
FRAMES = range(1, 9)


def _pixels(path: Path) -> dict[str, np.ndarray]:
    with OpenEXR.File(str(path), separate_channels=True) as exr:
        return {name: channel.pixels.copy()
                for part in exr.parts for name, channel in part.channels.items()}


def _held_bytes(source: SourceFile) -> int:
    """Bytes of the pixels a decoded file still holds (views of one array counted once)."""
    bases: dict[int, int] = {}
    for part in source.parts:
        for channel in part.channels.values():
            if channel.pixels is not None:
                base = channel.pixels
                while isinstance(base.base, np.ndarray):
                    base = base.base
                bases[id(base)] = base.nbytes
    return sum(bases.values())


def _run(out: Path, frames: range = FRAMES, read: Any = default_reader,
         low_memory: bool = False) -> None:
    """A causal run (no warm start) of the shot's ``frames`` into ``out``, light layers
    denoised, with the cycles preset's mapping."""
    out.mkdir(parents=True, exist_ok=True)
    mapping = build_mapping("cycles")
    config = RunConfig(params=resolve_params("default", warm_start=0), preset="default",
                       mapping=mapping, light_layers="denoised", low_memory=low_memory)
    tasks = [FrameTask(f, SHOT / f"in.{f:04d}.exr", out / f"o.{f:04d}.exr") for f in frames]
    quiet = Progress("lines", len(tasks), quiet=True, out=io.StringIO(), err=io.StringIO())
    stats = run_sequence(tasks, config, quiet, read=read)
    assert stats.frames_written == len(tasks)


def test_pass_through_channels_reach_the_writer_as_read(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Every channel the output passes through is handed to the writer (the OpenEXR
    library's, or `zipchunks` for this ZIP shot) as the very array decoded (half stays half:
    no conversion, no copy), and is written bit for bit."""
    path = SHOT / "in.0002.exr"
    result = read_frame(path, build_mapping("cycles"))
    assert result.source is not None and result.colour_channels is not None
    names = result.colour_channels
    part = result.source.part_holding(names[0])
    assert part is not None
    colour = prepare_colour(result.frame.total_radiance(), half=True).planes
    stored = {name: channel.pixels for name, channel in part.channels.items()}
    handed: dict[str, np.ndarray] = {}
    real_channel = OpenEXR.Channel

    def recording(name: str, pixels: Any = None, *args: Any) -> Any:
        handed[name] = pixels
        return real_channel(name, pixels, *args)

    class RecordingChunkWriter(zipchunks.ChunkWriter):
        def __init__(self, attributes: Any, planes: Any, p_linear: Any) -> None:
            handed.update(planes)
            super().__init__(attributes, planes, p_linear)

    monkeypatch.setattr(OpenEXR, "Channel", recording)
    monkeypatch.setattr(zipchunks, "ChunkWriter", RecordingChunkWriter)
    write_output(tmp_path / "o.exr", result.source, part_index=part.index,
                 channels=dict(zip(names, colour, strict=True)), attributes={})
    passed = [n for n in stored if n not in names]
    assert sum(stored[n].dtype == np.float16 for n in passed) >= 50  # the shot's half layers
    for name in passed:
        assert handed[name] is stored[name], name
    written, read_back = _pixels(tmp_path / "o.exr"), _pixels(path)
    for name in passed:
        assert written[name].dtype == read_back[name].dtype, name
        assert written[name].tobytes() == read_back[name].tobytes(), name


def test_the_input_pixels_the_output_replaces_are_let_go_before_filtering(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A frame reaches the filter with its light layers not yet read (a loader: the colour
    filter runs without their float32 planes); once they are made its file no longer holds
    the light passes, the emission passes and the light groups (the filter has float32
    copies; the output writes them anew), and while it is written it holds none of the
    channels the output replaces; every pass-through channel keeps its pixels throughout."""
    results: list[Any] = []
    entering: list[tuple[set[str], bool]] = []  # (released, light not yet read)
    filtering: list[tuple[set[str], set[str]]] = []  # (released, light channels)
    writing: list[tuple[set[str], set[str], set[str]]] = []  # (released, replaced, held)

    def read(path: Path, mapping: Any, **kwargs: Any) -> Any:
        result = default_reader(path, mapping, **kwargs)
        results.append(result)
        return result

    def released(source: SourceFile) -> set[str]:
        return {n for p in source.parts for n, c in p.channels.items() if c.pixels is None}

    process = LayeredDenoiser.process

    def watched(self: LayeredDenoiser, frame: Any) -> Any:
        result = next(r for r in results if r.frame is frame)
        entering.append((released(result.source),
                         frame.light is None and frame.light_loader is not None))
        return process(self, frame)

    made = composable.frame_light

    def read_light(frame: Any) -> Any:
        light = made(frame)
        result = next(r for r in results if r.frame is frame)
        filtering.append((released(result.source), set(light_replaced(light))))
        return light

    write = run_output.OutputFrame

    def recorded(source: SourceFile, part_index: int, channels: dict[str, np.ndarray],
                 *args: Any) -> Any:
        held = {n for p in source.parts for n, c in p.channels.items() if c.pixels is not None}
        writing.append((released(source), set(channels), held))
        return write(source, part_index, channels, *args)

    monkeypatch.setattr(LayeredDenoiser, "process", watched)
    monkeypatch.setattr(composable, "frame_light", read_light)
    monkeypatch.setattr(run_output, "OutputFrame", recorded)
    _run(tmp_path, range(1, 4), read)
    assert len(entering) == len(filtering) == len(writing) == 3
    colour = {"ViewLayer.Combined.R", "ViewLayer.Combined.G", "ViewLayer.Combined.B"}
    for gone, deferred in entering:
        assert deferred
        assert gone <= colour
    for gone, light in filtering:
        assert len(light) >= 30  # 8 passes, 2 emission passes, 3 groups: R, G, B each
        assert light <= gone
        assert gone <= light | colour
    for gone, replaced, held in writing:
        assert gone == replaced
        assert {"ViewLayer.Denoising Albedo.R", "ViewLayer.CryptoObject00.r",
                "ViewLayer.Depth.Z", "ViewLayer.Combined.A"} <= held


def test_letting_go_of_replaced_pixels_changes_no_output_bit(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    _run(tmp_path / "lean", range(1, 5))
    monkeypatch.setattr(run_light, "release_light_inputs", lambda *args: 0)
    monkeypatch.setattr(run_output, "release_replaced", lambda *args: 0)
    _run(tmp_path / "held", range(1, 5))
    for frame in range(1, 5):
        lean = _pixels(tmp_path / "lean" / f"o.{frame:04d}.exr")
        held = _pixels(tmp_path / "held" / f"o.{frame:04d}.exr")
        assert list(lean) == list(held)
        for name, plane in held.items():
            assert lean[name].dtype == plane.dtype, name
            assert lean[name].tobytes() == plane.tobytes(), (frame, name)


def _counting_reader() -> tuple[Any, list[int], list[int]]:
    """A reader that notes, when each read ends, how many decoded files are alive and how
    many bytes of pixels they hold: ``(read, counts, held)``."""
    alive: list[weakref.ref[SourceFile]] = []
    counts: list[int] = []
    held: list[int] = []
    lock = threading.Lock()

    def read(path: Path, mapping: Any, **kwargs: Any) -> Any:
        result = default_reader(path, mapping, **kwargs)
        with lock:
            alive.append(weakref.ref(result.source))
            sources = [s for r in alive if (s := r()) is not None]
            counts.append(len(sources))
            held.append(sum(_held_bytes(s) for s in sources))
        return result

    return read, counts, held


def test_a_causal_run_holds_a_bounded_number_of_decoded_bytes(tmp_path: Path) -> None:
    """When each read ends, the decoded files alive (the one read, the one filtered, the one
    written) hold less than three files' pixels, whatever the run's length: the frame
    written has let go of what the output writes anew (before it is handed to the writer),
    and nothing is kept per frame. The frame being filtered lets go right after its light
    layers are attached, which the next read may finish before (a race): so the bound is
    two files plus a released one (measured 2.5-2.59 files; 3.0 without the releases)."""
    read, counts, held = _counting_reader()
    _run(tmp_path, FRAMES, read)
    one_file = _held_bytes(read_frame(SHOT / "in.0001.exr", build_mapping("cycles")).source)
    assert len(held) == len(FRAMES)
    assert max(counts) <= 3
    assert max(held) <= 2.75 * one_file


def test_low_memory_holds_two_decoded_files_and_writes_the_same_bits(tmp_path: Path) -> None:
    """--low-memory: a frame is read only once the one before is filtered and handed to the
    writer (the write before it done), so when each read ends the decoded files alive are
    that one and the one being written (which let go of what it writes anew): at most two,
    under two files' pixels; the outputs are the default run's, bit for bit."""
    read, counts, held = _counting_reader()
    frames = range(1, 5)
    _run(tmp_path / "low", frames, read, low_memory=True)
    _run(tmp_path / "default", frames)
    one_file = _held_bytes(read_frame(SHOT / "in.0001.exr", build_mapping("cycles")).source)
    assert len(counts) == len(frames) and max(counts) <= 2, counts
    assert max(held) < 2 * one_file
    for frame in frames:
        name = f"o.{frame:04d}.exr"
        low, default = _pixels(tmp_path / "low" / name), _pixels(tmp_path / "default" / name)
        assert low.keys() == default.keys()
        for channel, pixels in low.items():
            assert np.array_equal(pixels.view(np.uint8), default[channel].view(np.uint8)), channel
