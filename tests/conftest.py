"""Shared pytest fixtures. Synthetic frame builders live in ``tests/synthetic.py``
(import them as ``from synthetic import make_frame``; pytest puts ``tests/`` on sys.path)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

from svgf_cli.filters.params import SVGFParams, resolve_params  # noqa: E402


@pytest.fixture
def paper_params() -> SVGFParams:
    """The paper preset (the default parameters)."""
    return resolve_params("paper")
