"""The bidirectional scratch files: exact round trip, stored uncompressed, deleted once read."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenEXR

from svgf_cli.io.spill import ScratchFolder


def test_a_state_comes_back_bit_for_bit_from_an_uncompressed_file(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    planes = {
        "direct.R": rng.exponential(1.0, (6, 10)).astype(np.float16),
        "direct.sd": np.array(rng.standard_normal((6, 10)), dtype=np.float16),
        "direct.h": rng.uniform(0, 32, (6, 10)).astype(np.float32),
    }
    planes["direct.R"][0, 0] = np.float16(65504.0)
    factors = {"direct.R": 0.25, "direct.sd": 3.5}
    with ScratchFolder(tmp_path) as scratch:
        scratch.write(7, planes, factors)
        stored = scratch.path / "7.exr"
        with OpenEXR.File(str(stored), header_only=True) as exr:
            assert exr.header()["compression"] == OpenEXR.NO_COMPRESSION
        back, back_factors = scratch.read(7)
        assert not stored.exists()
    assert back_factors == factors
    assert set(back) == set(planes)
    for name, plane in planes.items():
        assert back[name].dtype == plane.dtype
        assert np.array_equal(back[name].view(np.uint8), plane.view(np.uint8))
