"""The in-memory layout of an EXR file (io/source.py) and the C-level stderr capture that keeps
OpenEXR's own error lines out of the log."""

from __future__ import annotations

import os

import numpy as np
import OpenEXR

from svgf_cli.io.output import synthetic_source, write_output
from svgf_cli.io.source import capture_c_stderr


def test_c_stderr_keeps_library_errors_and_passes_every_other_line_through(capfd) -> None:
    with capture_c_stderr() as captured:
        os.write(2, b"another thread's warning\n")
        os.write(2, b"EXR Error (EXR_ERR_CORRUPT_CHUNK): bad chunk\n")
        os.write(2, b"last line\n")
    assert captured == ["EXR Error (EXR_ERR_CORRUPT_CHUNK): bad chunk"]
    assert capfd.readouterr().err == "another thread's warning\nlast line\n"


def test_synthetic_source_writes_scalar_attributes_and_the_alpha(tmp_path) -> None:
    alpha = np.linspace(0.0, 1.0, 12, dtype=np.float32).reshape(3, 4)
    source = synthetic_source(tmp_path / "in.exr", (3, 4),
                              {"owner": "lighting", "frameNumber": 7, "notes": ["a", "b"]},
                              alpha=alpha)
    header = source.parts[0].header
    assert header["owner"] == "lighting" and header["frameNumber"] == 7
    assert "notes" not in header  # not an EXR attribute type: never written
    colour = np.full((3, 4), 0.5, np.float32)
    out = tmp_path / "out.exr"
    write_output(out, source, part_index=0, attributes={},
                 channels={"R": colour, "G": colour, "B": colour})
    with OpenEXR.File(str(out), separate_channels=True) as written:
        channels = written.channels()
        assert np.array_equal(channels["A"].pixels, alpha)
        assert (channels["A"].xSampling, channels["A"].ySampling) == (1, 1)
        assert written.header()["owner"] == "lighting"
