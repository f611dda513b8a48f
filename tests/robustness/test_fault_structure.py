"""EXR structures: the ones a drop-in output must keep (overscan, region, multi-part,
tiled) run and pass through; the ones svgf cannot denoise (deep, multi-view, subsampled
passthrough) are refused with one line, exit 3, and nothing written."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenEXR
import pytest
from exr_fixtures import H, PartSpec, W, assert_passthrough, box, gbuffer, read_parts, write_parts
from faults import assert_one_error_line, denoise


def tiles(size: int) -> OpenEXR.TileDescription:
    description = OpenEXR.TileDescription()
    description.xSize = description.ySize = size
    description.mode, description.roundingMode = OpenEXR.ONE_LEVEL, OpenEXR.ROUND_DOWN
    return description


def single(header: dict) -> callable:
    return lambda frame: [PartSpec(gbuffer(frame), header=header)]


def split_parts(frame: int) -> list[PartSpec]:
    data = gbuffer(frame)
    beauty = {c: data.pop(c) for c in "RGB"}
    return [PartSpec(beauty, "rgba"), PartSpec(data, "data")]


STRUCTURES = {
    "overscan": single({"dataWindow": box(-2, -3, W, H), "displayWindow": box(0, 0, W - 4, H - 6)}),
    "region": single({"dataWindow": box(7, 5, W, H), "displayWindow": box(0, 0, W + 30, H + 20)}),
    "multi-part": split_parts,
    "tiled": single({"type": OpenEXR.tiledimage, "tiles": tiles(8)}),
    "lossy beauty codec": single({"compression": OpenEXR.DWAA_COMPRESSION}),
}


@pytest.mark.parametrize("structure", list(STRUCTURES))
def test_structures_run_and_pass_through(
    structure: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for frame in (1, 2):
        write_parts(tmp_path / f"in.{frame:04d}.exr", STRUCTURES[structure](frame))
    code, _, err = denoise([tmp_path / "in.####.exr", "-o", tmp_path / "o.####.exr"], capsys)
    assert code == 0, err
    part = "rgba" if structure == "multi-part" else ""
    changes = ("compression",) if structure == "lossy beauty codec" else ()
    assert_passthrough(
        tmp_path / "in.0002.exr",
        tmp_path / "o.0002.exr",
        changed={part: {"R", "G", "B"}},
        header_changes=changes,
    )
    if changes:  # DWAA would damage N.Y, motion.Y, Z a second time: written exactly (zip)
        (_, header, _), = read_parts(tmp_path / "o.0002.exr")
        assert header["compression"] == OpenEXR.ZIP_COMPRESSION


def deep_file(path: Path) -> Path:
    samples = np.empty((H, W), dtype=object)
    for y in range(H):
        for x in range(W):
            samples[y, x] = np.array([0.5, 0.25], np.float32) if (x + y) % 2 else None
    header = {"type": OpenEXR.deepscanline, "compression": OpenEXR.ZIPS_COMPRESSION,
              "dataWindow": box(0, 0, W, H), "displayWindow": box(0, 0, W, H)}
    channels = {name: OpenEXR.Channel(name, samples) for name in ("R", "G", "B", "A", "Z")}
    OpenEXR.File([OpenEXR.Part(header, channels, "deep")]).write(str(path))
    return path


def multiview_single_part(path: Path) -> Path:
    data = gbuffer(1)
    data.update({f"right.{c}": data[c] * 0.9 for c in "RGB"})
    return write_parts(path, [PartSpec(data, header={"multiView": ["left", "right"]})])


def multiview_parts(path: Path) -> Path:
    return write_parts(path, [
        PartSpec(gbuffer(1), "rgba_left", {"view": "left"}),
        PartSpec(gbuffer(1, seed=9), "rgba_right", {"view": "right"}),
    ])


STEREO = "multi-view (stereo) file with views left, right"
REFUSED = {
    "deep": (deep_file, "deep EXR parts are not supported"),
    "multi-view, one part": (multiview_single_part, STEREO),
    "multi-view, parts": (multiview_parts, STEREO),
}


@pytest.mark.parametrize("structure", list(REFUSED))
def test_refused_structures(
    structure: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    make, fragment = REFUSED[structure]
    path = make(tmp_path / "in.0001.exr")
    for argv in (["denoise", path, "-o", tmp_path / "o.exr"], ["inspect", path, "--check"]):
        from test_cli_support import run_cli

        code, _, err = run_cli(argv, capsys)
        assert code == 3, err
        assert_one_error_line(err, path, fragment)
    assert not (tmp_path / "o.exr").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.0001.exr"]
