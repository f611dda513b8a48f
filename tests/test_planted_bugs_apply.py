"""The planted-bug list (``tests/mutants/plant.py``) still fits the code it patches.

A mutant whose text no longer occurs exactly once stops the whole planting run, so a
refactor that moves a line must update its mutant; this catches that in ``make test``
instead of at the next planting run (which takes minutes)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _plant_module():  # noqa: ANN202 - the module object
    spec = importlib.util.spec_from_file_location("plant", ROOT / "tests" / "mutants" / "plant.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("plant", module)  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def test_every_planted_bug_applies_once_and_names_existing_tests() -> None:
    plant = _plant_module()
    names = [mutant.name for mutant in plant.MUTANTS]
    assert len(names) == len(set(names)), "duplicate mutant names"
    for mutant in plant.MUTANTS:
        text = (ROOT / mutant.path).read_text()
        for old, new in mutant.edits:
            assert old != new, mutant.name
            assert text.count(old) == 1, f"{mutant.name}: its text occurs {text.count(old)} times"
            text = text.replace(old, new)
        assert mutant.owner in ("filters", "io", "farm"), mutant.name
        assert mutant.tests and all((ROOT / test).is_file() for test in mutant.tests), mutant.name
