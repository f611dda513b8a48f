"""Real files made by others (the OpenEXR project's sample images): the writer hands every
structure back as read, and what svgf cannot denoise is refused with one line.

Skipped unless ``OPENEXR_IMAGES`` points at a checkout of
AcademySoftwareFoundation/openexr-images (the files are too big to commit; the structures
they exercise are also built as tiny fixtures in test_io_passthrough.py).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from exr_fixtures import assert_passthrough
from test_cli_support import run_cli

from svgf_cli.errors import InputError
from svgf_cli.io.exr import read_info
from svgf_cli.io.output import write_output
from svgf_cli.io.source import decode_source

ROOT = Path(os.environ.get("OPENEXR_IMAGES", "/nonexistent"))
pytestmark = pytest.mark.skipif(
    not (ROOT / "DisplayWindow").is_dir(),
    reason="set OPENEXR_IMAGES to a checkout of AcademySoftwareFoundation/openexr-images",
)

PASSED_THROUGH = [
    "DisplayWindow/t09.exr",  # data window beside the display window
    "DisplayWindow/t01.exr",
    "Tiles/GoldenGate.exr",  # tiled, preview image, camera attributes
    "Chromaticities/Rec709.exr",
    "TestImages/WideColorGamut.exr",  # chromaticities attribute
    "ScanLines/Cannon.exr",  # B44 (lossy) colour-only part
]


@pytest.mark.parametrize("name", PASSED_THROUGH)
def test_real_structures_are_written_back_as_read(name: str, tmp_path: Path) -> None:
    path = ROOT / name
    if not path.is_file():
        pytest.skip(f"{name} absent from the checkout")
    source = decode_source(path)
    part = source.part_holding("R")
    assert part is not None
    colour = {c: (part.channels[c].pixels * 0.5).astype(part.channels[c].pixels.dtype)
              for c in "RGB"}
    out = tmp_path / "o.exr"
    write_output(out, source, part_index=part.index, channels=colour, attributes={})
    assert_passthrough(path, out, changed={part.name: {"R", "G", "B"}})


def test_real_mipmapped_tiles_keep_level_zero(tmp_path: Path) -> None:
    """Mip-mapped tiled input (not a render output): level 0 is written, one level, noted."""
    path = ROOT / "MultiResolution/ColorCodedLevels.exr"
    source = decode_source(path)
    part = source.parts[0]
    colour = {c: part.channels[c].pixels.copy() for c in "RGB"}
    notes = write_output(tmp_path / "o.exr", source, part_index=0, channels=colour,
                         attributes={})
    assert notes == ["part 0: mip/rip-map levels are not written (level 0 only)"]
    assert_passthrough(path, tmp_path / "o.exr", header_changes=("tiles",))


def test_real_wide_gamut_weights() -> None:
    weights = read_info(ROOT / "TestImages/WideColorGamut.exr").luminance_weights
    assert "from chromaticities" in weights.source
    assert np.isclose(sum(weights.weights), 1.0)


def test_real_subsampled_chroma_is_refused_for_passthrough(tmp_path: Path) -> None:
    path = ROOT / "Chromaticities/Rec709_YC.exr"
    source = decode_source(path)
    with pytest.raises(InputError, match="BY, RY are subsampled") as raised:
        write_output(tmp_path / "o.exr", source, part_index=0,
                     channels={"Y": source.parts[0].channels["Y"].pixels}, attributes={})
    assert raised.value.exit_code == 3 and not (tmp_path / "o.exr").exists()


@pytest.mark.parametrize(
    ("name", "fragment"),
    [
        ("MultiView/Fog.exr", "multi-view (stereo) file with views left, right"),
        ("Beachball/singlepart.0001.exr", "multi-view (stereo) file with views right, left"),
        ("Beachball/multipart.0001.exr", "multi-view (stereo) file with views right, left"),
        ("v2/LowResLeftView/Balls.exr", "deep EXR parts are not supported"),
    ],
)
def test_real_files_svgf_refuses(
    name: str, fragment: str, capsys: pytest.CaptureFixture[str]
) -> None:
    path = ROOT / name
    if not path.is_file():
        pytest.skip(f"{name} absent from the checkout")
    code, _, err = run_cli(["inspect", path, "--check"], capsys)
    assert code == 3 and err.startswith(f"ERROR: {path}: ") and fragment in err, err
