"""Structure limits of the code base, checked on the source text (AST), not by importing it.

* no import cycle among the modules of ``svgf_cli`` and of ``svgf_trace``: ``import x``,
  ``from x import y`` (``y`` resolved to a submodule when it is one) and relative imports,
  imports inside functions included;
* no class in ``svgf_cli`` over ``MAX_CLASS_LINES`` lines;
* no plain function (not compiled by numba) in ``svgf_cli`` or ``svgf_trace`` over
  ``MAX_FUNCTION_LINES`` lines; a function counts as numba-compiled when a decorator is, or
  calls, a name imported from numba (``njit``, ``numba.njit``, ``intrinsic``...) or a project
  function that wraps one (``noalias_njit`` in ``svgf_cli/filters/noalias.py``);
* ``svgf denoise --help`` at most ``MAX_HELP_LINES`` lines at terminal width 80.

``bench/structure.py`` prints the same findings as one report.
"""

from __future__ import annotations

import ast
import textwrap
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("svgf_cli", "svgf_trace")
MAX_FUNCTION_LINES = 80
MAX_CLASS_LINES = 300
MAX_HELP_LINES = 120
HELP_WIDTH = 80


@dataclass(frozen=True)
class Span:
    """A function or class of the source tree and how many lines it spans (decorators excluded)."""

    path: str
    qualname: str
    lineno: int
    lines: int

    def __str__(self) -> str:
        return f"{self.path}:{self.lineno} {self.qualname} ({self.lines} lines)"


def module_files(root: Path, packages: tuple[str, ...] = PACKAGES) -> dict[str, Path]:
    """Module name -> source file for every ``.py`` file of ``packages`` under ``root``."""
    modules: dict[str, Path] = {}
    for package in packages:
        for path in sorted((root / package).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            modules[".".join(parts)] = path
    return modules


def _parse(path: Path) -> ast.Module:
    return ast.parse(path.read_text(encoding="utf-8"), filename=str(path))


def _relative_base(module: str, is_package: bool, level: int) -> str:
    """The package a ``from {'.' * level} import`` in ``module`` starts from."""
    parts = module.split(".")
    if not is_package:
        parts = parts[:-1]
    return ".".join(parts[: len(parts) - (level - 1)] if level > 1 else parts)


def imported_modules(module: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The project modules that ``module`` imports anywhere in its source, functions included."""
    is_package = path.name == "__init__.py"
    found: set[str] = set()
    for node in ast.walk(_parse(path)):
        if isinstance(node, ast.Import):
            for alias in node.names:
                name = alias.name
                while name and name not in modules:
                    name = name.rpartition(".")[0]
                if name:
                    found.add(name)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = _relative_base(module, is_package, node.level)
                source = f"{base}.{node.module}" if node.module else base
            else:
                source = node.module or ""
            for alias in node.names:
                submodule = f"{source}.{alias.name}"
                if submodule in modules:
                    found.add(submodule)
                elif source in modules:
                    found.add(source)
    found.discard(module)
    return found


def import_graph(root: Path, packages: tuple[str, ...] = PACKAGES) -> dict[str, set[str]]:
    """Module -> the project modules it imports."""
    modules = module_files(root, packages)
    return {name: imported_modules(name, path, modules) for name, path in modules.items()}


def _strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components (iterative), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []
    for start in sorted(graph):
        if start in index:
            continue
        work: list[tuple[str, Iterator[str]]] = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, successors = work[-1]
            advanced = False
            for successor in successors:
                if successor not in index:
                    index[successor] = low[successor] = len(index)
                    stack.append(successor)
                    on_stack.add(successor)
                    work.append((successor, iter(sorted(graph.get(successor, ())))))
                    advanced = True
                    break
                if successor in on_stack:
                    low[node] = min(low[node], index[successor])
            if advanced:
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                components.append(sorted(component))
    return components


def _cycle_through(start: str, members: set[str], graph: dict[str, set[str]]) -> list[str]:
    """A shortest import path start -> ... -> start inside one strongly connected component."""
    previous: dict[str, str] = {}
    frontier = [start]
    while frontier:
        following = []
        for node in frontier:
            for successor in sorted(graph[node] & members):
                if successor == start:
                    path = [node]
                    while path[-1] != start:
                        path.append(previous[path[-1]])
                    return [start, *reversed(path[:-1]), start] if node != start else [start, start]
                if successor not in previous:
                    previous[successor] = node
                    following.append(successor)
        frontier = following
    return [start]


def import_cycles(root: Path, packages: tuple[str, ...] = PACKAGES) -> list[str]:
    """One cycle per group of mutually importing modules, as ``a -> b -> a``."""
    graph = import_graph(root, packages)
    cycles = []
    for component in _strongly_connected(graph):
        if len(component) > 1:
            cycle = _cycle_through(component[0], set(component), graph)
            others = sorted(set(component) - set(cycle))
            also = f" (same cycle group: {', '.join(others)})" if others else ""
            cycles.append(" -> ".join(cycle) + also)
    return cycles


def _numba_names(tree: ast.Module, project_wrappers: dict[str, set[str]]) -> set[str]:
    """Names in a module that stand for numba decorators: imports from numba, the module
    ``numba`` itself, project functions that wrap one, imports of such wrappers and
    module-level aliases of any of these."""
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name == "numba" or alias.name.startswith("numba."):
                    names.add(alias.asname or alias.name.split(".")[0])
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            wrappers = project_wrappers.get(node.module, set())
            for alias in node.names:
                numba_module = node.module == "numba" or node.module.startswith("numba.")
                if numba_module or alias.name in wrappers:
                    names.add(alias.asname or alias.name)
    # Module-level aliases: ``kernel = njit(cache=True)`` or ``jit = numba.njit``.
    for node in tree.body:
        if isinstance(node, ast.Assign) and _uses_name(node.value, names):
            names.update(t.id for t in node.targets if isinstance(t, ast.Name))
    return names


def _decorator_root(decorator: ast.expr) -> str | None:
    """``njit`` for ``@njit``, ``@njit(...)``; ``numba`` for ``@numba.njit(...)``."""
    while isinstance(decorator, ast.Call):
        decorator = decorator.func
    while isinstance(decorator, ast.Attribute):
        decorator = decorator.value
    return decorator.id if isinstance(decorator, ast.Name) else None


def _uses_name(node: ast.AST, names: set[str]) -> bool:
    return any(isinstance(child, ast.Name) and child.id in names for child in ast.walk(node))


def numba_wrappers(modules: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> its top-level functions that wrap a numba decorator (``noalias_njit``)."""
    wrappers: dict[str, set[str]] = {}
    for name, path in modules.items():
        tree = _parse(path)
        numba = _numba_names(tree, {})
        if not numba:
            continue
        wrappers[name] = {
            node.name
            for node in tree.body
            if isinstance(node, ast.FunctionDef)
            and not node.decorator_list
            and _uses_name(node, numba)
        }
    return wrappers


def _spans(path: Path, rel: str, tree: ast.Module, numba: set[str]) -> Iterator[tuple[str, Span]]:
    """("function" | "class", Span) for every plain function and every class of a module."""

    def visit(node: ast.AST, prefix: str) -> Iterator[tuple[str, Span]]:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                qualname = f"{prefix}{child.name}"
                lines = (child.end_lineno or child.lineno) - child.lineno + 1
                span = Span(rel, qualname, child.lineno, lines)
                if isinstance(child, ast.ClassDef):
                    yield "class", span
                elif not any(_decorator_root(d) in numba for d in child.decorator_list):
                    yield "function", span
                yield from visit(child, f"{qualname}.")
            else:
                yield from visit(child, prefix)

    yield from visit(tree, "")


def long_definitions(
    root: Path,
    packages: tuple[str, ...] = PACKAGES,
    max_function: int = MAX_FUNCTION_LINES,
    max_class: int = MAX_CLASS_LINES,
    class_packages: tuple[str, ...] = ("svgf_cli",),
) -> tuple[list[Span], list[Span]]:
    """(plain functions over ``max_function`` lines, classes over ``max_class`` lines)."""
    modules = module_files(root, packages)
    wrappers = numba_wrappers(modules)
    functions: list[Span] = []
    classes: list[Span] = []
    for path in modules.values():
        tree = _parse(path)
        rel = path.relative_to(root).as_posix()
        for kind, span in _spans(path, rel, tree, _numba_names(tree, wrappers)):
            if kind == "function" and span.lines > max_function:
                functions.append(span)
            elif kind == "class" and span.lines > max_class and rel.split("/")[0] in class_packages:
                classes.append(span)
    return functions, classes


def denoise_help_lines() -> int:
    """Lines of ``svgf denoise --help`` at terminal width 80 (the click command in-process)."""
    from click.testing import CliRunner

    from svgf_cli.cli import cli

    result = CliRunner().invoke(
        cli, ["denoise", "--help"], prog_name="svgf", terminal_width=HELP_WIDTH
    )
    assert result.exit_code == 0, result.output
    return len(result.output.splitlines())


# --- the checks on this repository ------------------------------------------------------------


def test_no_import_cycles() -> None:
    cycles = import_cycles(REPO)
    assert not cycles, "import cycles:\n  " + "\n  ".join(cycles)


def test_the_run_package_init_imports_nothing_of_its_own() -> None:
    """Importing any module of ``svgf_cli.run`` runs its ``__init__`` first: it must not
    pull the drivers (or a cycle) in."""
    own = {m for m in import_graph(REPO)["svgf_cli.run"] if m.startswith("svgf_cli.run.")}
    assert not own, own


def test_no_class_over_limit() -> None:
    _, classes = long_definitions(REPO)
    assert not classes, f"classes over {MAX_CLASS_LINES} lines:\n  " + "\n  ".join(
        map(str, classes)
    )


def test_no_plain_function_over_limit() -> None:
    functions, _ = long_definitions(REPO)
    assert not functions, f"plain functions over {MAX_FUNCTION_LINES} lines:\n  " + "\n  ".join(
        map(str, functions)
    )


def test_denoise_help_fits() -> None:
    lines = denoise_help_lines()
    assert lines <= MAX_HELP_LINES, (
        f"svgf denoise --help is {lines} lines at width {HELP_WIDTH} (limit {MAX_HELP_LINES})"
    )


# --- the checker itself, on a synthetic tree ---------------------------------------------------


def _write(root: Path, files: dict[str, str]) -> None:
    for rel, text in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")


def _body(count: int) -> str:
    return "".join(f"    x{i} = {i}\n" for i in range(count))


@pytest.fixture
def synthetic(tmp_path: Path) -> Path:
    """pkg: a -> b at the top, b -> a lazily inside a function; c imports a submodule by name;
    d: an 81-line function, an 80-line one, two 100-line numba kernels (direct and through a
    wrapper); e: a 301-line class."""
    _write(
        tmp_path,
        {
            "pkg/__init__.py": "",
            "pkg/a.py": "from pkg import b\n",
            "pkg/b.py": "def late():\n    from .a import thing\n    return thing\n",
            "pkg/c.py": "from pkg import sub\nimport pkg.sub.deep\n",
            "pkg/sub/__init__.py": "from ..c import nothing\n",
            "pkg/sub/deep.py": "import os\n",
            "pkg/wrap.py": (
                "from numba import njit\n\n"
                "def fast(**options):\n    return njit(**options)\n"
            ),
            "pkg/d.py": (
                "import numba as nb\nfrom numba import njit as jit_it\n"
                "from pkg.wrap import fast\n\n"
                "def long_one():\n" + _body(80) + "\n"
                "def fine():\n" + _body(79) + "\n"
                "@jit_it(cache=True)\ndef kernel():\n" + _body(99) + "\n"
                "@fast(cache=True)\ndef wrapped():\n" + _body(99) + "\n"
                "@nb.vectorize\ndef vec():\n" + _body(99) + "\n"
                "kernel = jit_it(cache=True)\n\n"
                "@kernel\ndef aliased():\n" + _body(99) + "\n"
                "class Small:\n    def method(self):\n"
                + textwrap.indent(_body(81), "    ")
            ),
            "pkg/e.py": "class Big:\n" + _body(300),
        },
    )
    return tmp_path


def test_checker_finds_lazy_import_cycle(synthetic: Path) -> None:
    graph = import_graph(synthetic, ("pkg",))
    assert graph["pkg.b"] == {"pkg.a"}
    assert graph["pkg.c"] == {"pkg.sub", "pkg.sub.deep"}
    cycles = import_cycles(synthetic, ("pkg",))
    assert "pkg.a -> pkg.b -> pkg.a" in cycles
    assert any(cycle.startswith("pkg.c -> pkg.sub -> pkg.c") for cycle in cycles)
    assert len(cycles) == 2


def test_checker_finds_long_function_and_class_but_not_kernels(synthetic: Path) -> None:
    functions, classes = long_definitions(synthetic, ("pkg",), class_packages=("pkg",))
    assert sorted((span.path, span.qualname, span.lines) for span in functions) == [
        ("pkg/d.py", "Small.method", 82),
        ("pkg/d.py", "long_one", 81),
    ]
    assert list(map(str, classes)) == ["pkg/e.py:1 Big (301 lines)"]
    assert str(functions[0]) == "pkg/d.py:5 long_one (81 lines)"


def test_checker_passes_a_clean_tree(tmp_path: Path) -> None:
    _write(tmp_path, {"pkg/__init__.py": "", "pkg/a.py": "import pkg.b\n", "pkg/b.py": "x = 1\n"})
    assert import_cycles(tmp_path, ("pkg",)) == []
    assert long_definitions(tmp_path, ("pkg",)) == ([], [])
