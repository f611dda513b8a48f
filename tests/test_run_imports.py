"""svgf_cli/run/ has no import cycle: no module of it imports, directly or through other
svgf_cli modules, one that imports it back. Imports inside functions count (a lazy import
is still a dependency), so do those under ``if TYPE_CHECKING:``.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "svgf_cli"


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def _imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The svgf_cli modules ``name`` imports, anywhere in its body."""
    is_package = path.name == "__init__.py"
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = name.split(".")
                anchor = anchor[: len(anchor) - node.level + (1 if is_package else 0)]
                base = ".".join([*anchor, *([base] if base else [])])
            # ``from pkg import mod`` imports the module pkg.mod; otherwise a name of pkg.
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base
                       for a in node.names]
        else:
            continue
        for target in targets:
            # The closest enclosing module that exists (``import a.b.c`` -> a.b.c).
            while target and target not in modules:
                target = target.rpartition(".")[0]
            if target and target != name:
                found.add(target)
    return found


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for other in sorted(graph[node]):
            if other not in index:
                visit(other)
                low[node] = min(low[node], low[other])
            elif other in on_stack:
                low[node] = min(low[node], index[other])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                components.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return components


def _in_run(module: str) -> bool:
    return module == "svgf_cli.run" or module.startswith("svgf_cli.run.")


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    return {name: _imports(name, path, modules) for name, path in modules.items()}


def test_the_run_package_has_no_import_cycle() -> None:
    graph = _graph()
    assert "svgf_cli.run.chunk" in graph
    cycles = [c for c in _cycles(graph) if any(_in_run(m) for m in c)]
    assert cycles == [], cycles


def test_the_run_package_init_imports_nothing_of_its_own() -> None:
    """Importing any module of the package runs its ``__init__`` first."""
    assert not {m for m in _graph()["svgf_cli.run"] if _in_run(m)}


def test_the_cycle_finder_finds_a_lazy_import_cycle(tmp_path: Path) -> None:
    """The checker itself: a lazy import back (inside a function) is a cycle."""
    a, b = tmp_path / "a.py", tmp_path / "b.py"
    a.write_text("from svgf_cli.run import b\n")
    b.write_text("def f():\n    from svgf_cli.run.a import x\n")
    modules = {"svgf_cli.run.a": a, "svgf_cli.run.b": b}
    graph = {name: _imports(name, path, modules) for name, path in modules.items()}
    assert _cycles(graph) == [["svgf_cli.run.a", "svgf_cli.run.b"]]
