"""``--set NAME=VALUE`` parameter overrides, shared by the bench scripts."""

from __future__ import annotations

import ast
from typing import Any


def parse_overrides(items: list[str]) -> dict[str, Any]:
    """``NAME=VALUE`` strings as SVGFParams overrides (values are Python literals)."""
    return {name: ast.literal_eval(value)
            for name, _, value in (item.partition("=") for item in items)}
