"""Fixtures of the fault suite: a tiny good sequence and the outputs of an undisturbed run."""

from __future__ import annotations

from pathlib import Path

import pytest
from faults import FRAMES, HEIGHT, WIDTH
from test_cli_support import write_sequence


@pytest.fixture(scope="session")
def clean_sequence(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Three good frames (svgf convention, ZIP)."""
    folder = tmp_path_factory.mktemp("fault_seq")
    write_sequence(folder, FRAMES, width=WIDTH, height=HEIGHT)
    return folder


@pytest.fixture(scope="session")
def clean_outputs(clean_sequence: Path, tmp_path_factory: pytest.TempPathFactory) -> dict:
    """Output file name -> bytes of an undisturbed run over `clean_sequence`."""
    from svgf_cli.cli import main

    out = tmp_path_factory.mktemp("fault_ref")
    with pytest.raises(SystemExit) as exited:
        main(["denoise", str(clean_sequence / "in.####.exr"), "-o", str(out / "o.####.exr"),
              "-q"])
    assert exited.value.code == 0
    return {p.name: p.read_bytes() for p in sorted(out.glob("o.*.exr"))}
