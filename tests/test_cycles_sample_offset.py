"""A Cycles render with a sample offset, as Blender wrote it (testdata/cycles/offset/roll:
frames 1-3 of ``roll`` rendered by ``testdata/cycles/render.py --scene roll --what inputs
--frames 1 3 --sample-offset 1 --out testdata/cycles/offset``; docs/cycles.md).

Its one sample per pixel is jittered, so Cycles writes no ``Depth`` (1e10 everywhere) and no
``IndexOB`` (0 everywhere): svgf must take ``Denoising Depth``, say so, and denoise; its
header does not claim pixel-centre samples, so the default preset's pixel filter stays off.
The committed default render of the same frames is the counterpart.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenEXR
import pytest
from test_cli_support import run_cli

from svgf_cli.evaluate.metrics import relmse
from svgf_cli.io.exr import read_frame, read_rgb
from svgf_cli.io.layers import build_mapping

CYCLES = Path(__file__).resolve().parent.parent / "testdata" / "cycles"
OFFSET = CYCLES / "offset" / "roll"
DEFAULT = CYCLES / "roll"


def test_the_offset_render_has_no_depth_and_no_object_index() -> None:
    with OpenEXR.File(str(OFFSET / "in.0001.exr"), separate_channels=True) as f:
        channels = f.channels()
        assert np.all(channels["ViewLayer.Depth.Z"].pixels == 1e10)
        assert np.all(channels["ViewLayer.IndexOB.X"].pixels == 0)
        assert np.count_nonzero(channels["ViewLayer.Denoising Depth.Z"].pixels) > 0.5 * 128 * 72
        assert f.header()["cycles.ViewLayer.samples"] == "2"


def test_svgf_reads_the_denoising_depth_and_no_pixel_centre_claim() -> None:
    mapping = build_mapping("cycles")
    offset = read_frame(OFFSET / "in.0001.exr", mapping)
    assert offset.resolved["depth"] == ("ViewLayer.Denoising Depth.Z",)
    assert any("ViewLayer.Depth.Z is background on every pixel" in w for w in offset.warnings)
    assert np.count_nonzero(offset.frame.depth) > 0.5 * offset.frame.depth.size
    assert not offset.frame.centre_sampled
    default = read_frame(DEFAULT / "in.0001.exr", mapping)
    assert default.resolved["depth"] == ("ViewLayer.Depth.Z",)
    assert default.frame.centre_sampled
    assert not any("every pixel" in w for w in default.warnings)


def test_the_offset_render_is_denoised(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out.####.exr"
    code, _, err = run_cli(["denoise", str(OFFSET / "in.####.exr"), "-o", str(out),
                            "--preset-aovs", "cycles", "--quiet"], capsys)
    assert code == 0
    assert err.count("using ViewLayer.Denoising Depth.Z") == 3
    mapping = build_mapping("cycles")
    reference, _ = read_rgb(DEFAULT / "ref.0003.exr")
    noisy, _ = read_rgb(OFFSET / "in.0003.exr", mapping)
    denoised, _ = read_rgb(tmp_path / "out.0003.exr", mapping)
    # Unfiltered (what svgf wrote before it read Denoising Depth), the output would be the
    # input: relMSE 0.48 here. Denoised at frame 3: 0.10.
    assert relmse(denoised, reference) < 0.35 * relmse(noisy, reference)
