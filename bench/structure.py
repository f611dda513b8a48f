"""Every structure offender at once: import cycles, classes over 300 lines, plain functions over
80 lines (svgf_cli and svgf_trace, numba kernels exempt) and the length of
``svgf denoise --help``. The checks are those of ``tests/test_structure.py``.

Run: ``.venv/bin/python bench/structure.py``; exit status 1 while anything is over its limit.
"""

from __future__ import annotations

import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))

import test_structure as structure  # noqa: E402


def main() -> int:
    cycles = structure.import_cycles(REPO)
    functions, classes = structure.long_definitions(REPO)
    help_lines = structure.denoise_help_lines()
    print(f"import cycles: {len(cycles)}")
    for cycle in cycles:
        print(f"  {cycle}")
    print(f"classes over {structure.MAX_CLASS_LINES} lines: {len(classes)}")
    for span in sorted(classes, key=lambda span: -span.lines):
        print(f"  {span}")
    print(f"plain functions over {structure.MAX_FUNCTION_LINES} lines: {len(functions)}")
    for span in sorted(functions, key=lambda span: -span.lines):
        print(f"  {span}")
    over = help_lines > structure.MAX_HELP_LINES
    print(
        f"svgf denoise --help: {help_lines} lines at width {structure.HELP_WIDTH} "
        f"(limit {structure.MAX_HELP_LINES}){' OVER' if over else ''}"
    )
    return 1 if cycles or classes or functions or over else 0


if __name__ == "__main__":
    sys.exit(main())
