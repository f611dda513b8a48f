"""What `read_info` says about a file's structure (what `svgf inspect` shows and what decides
refusals), and attribute types `write_exr` chooses."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenEXR
from exr_fixtures import PartSpec, gbuffer, write_parts

from svgf_cli.io.exr import read_info, write_exr


def _tiles(size: int) -> OpenEXR.TileDescription:
    description = OpenEXR.TileDescription()
    description.xSize = description.ySize = size
    description.mode, description.roundingMode = OpenEXR.ONE_LEVEL, OpenEXR.ROUND_DOWN
    return description


def test_each_part_says_whether_it_is_tiled(tmp_path: Path) -> None:
    data = gbuffer()
    beauty = {c: data.pop(c) for c in "RGB"}
    path = write_parts(tmp_path / "mixed.exr", [
        PartSpec(beauty, "rgba"),
        PartSpec(data, "data", {"type": OpenEXR.tiledimage, "tiles": _tiles(8)}),
    ])
    info = read_info(path)
    assert [(p.name, p.tiled) for p in info.part_info] == [("rgba", False), ("data", True)]


def test_the_file_compression_is_its_first_part_s(tmp_path: Path) -> None:
    # `svgf inspect` prints one compression for the file (the first part's, where a
    # single-part reader looks) and each part's own.
    data = gbuffer()
    beauty = {c: data.pop(c) for c in "RGB"}
    path = write_parts(tmp_path / "mixed.exr", [
        PartSpec(beauty, "rgba", {"compression": OpenEXR.PIZ_COMPRESSION}),
        PartSpec(data, "data", {"compression": OpenEXR.ZIP_COMPRESSION}),
    ])
    info = read_info(path)
    assert info.compression == "piz"
    assert [p.compression for p in info.part_info] == ["piz", "zip"]


def test_only_two_distinct_views_make_a_multi_view_file(tmp_path: Path) -> None:
    # A part tagged with a view (one view in the whole file) is an ordinary file; two
    # distinct views are stereo, which `svgf denoise` refuses.
    data = gbuffer()
    beauty = {c: data.pop(c) for c in "RGB"}
    one = write_parts(tmp_path / "one.exr", [PartSpec(beauty, "rgba", {"view": "left"}),
                                             PartSpec(data, "data", {"view": "left"})])
    assert read_info(one).views == []
    beauty_right = {c: v.copy() for c, v in beauty.items()}
    two = write_parts(tmp_path / "two.exr", [PartSpec(beauty, "left", {"view": "left"}),
                                             PartSpec(beauty_right, "right", {"view": "right"})])
    assert read_info(two).views == ["left", "right"]


def test_a_sixteen_number_attribute_is_written_as_a_matrix(tmp_path: Path) -> None:
    # svgf trace hands its camera matrices to write_exr as 16-tuples.
    matrix = tuple(float(v) for v in range(16))
    path = tmp_path / "m.exr"
    plane = np.zeros((4, 4), np.float32)
    write_exr(path, {"R": plane, "G": plane, "B": plane}, attributes={"worldToCamera": matrix})
    with OpenEXR.File(str(path)) as written:
        stored = np.asarray(written.header()["worldToCamera"])
    assert stored.shape == (4, 4)
    assert np.array_equal(stored.ravel(), np.arange(16, dtype=stored.dtype))
