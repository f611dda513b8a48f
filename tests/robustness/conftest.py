"""Fixtures of the fault suite: a tiny good sequence and the outputs of an undisturbed run."""

from __future__ import annotations

from pathlib import Path

import pytest
from faults import FRAMES, HEIGHT, WIDTH
from test_cli_support import reference_run, sequence_folder


@pytest.fixture(scope="session")
def clean_sequence(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Three good frames (svgf convention, ZIP)."""
    return sequence_folder(tmp_path_factory, FRAMES, WIDTH, HEIGHT)


@pytest.fixture(scope="session")
def clean_outputs(clean_sequence: Path, tmp_path_factory: pytest.TempPathFactory) -> dict:
    """Output file name -> bytes of an undisturbed run over `clean_sequence`."""
    outputs = reference_run(tmp_path_factory, clean_sequence)
    return {p.name: p.read_bytes() for p in outputs.values()}


@pytest.fixture(scope="session")
def cold_outputs(clean_sequence: Path, tmp_path_factory: pytest.TempPathFactory) -> dict:
    """As `clean_outputs`, without the warm start (``--warm-start 0``): what the frames
    before a bad one within the warm start's look-ahead are (run.warm_start)."""
    outputs = reference_run(tmp_path_factory, clean_sequence, "--warm-start", 0)
    return {p.name: p.read_bytes() for p in outputs.values()}
