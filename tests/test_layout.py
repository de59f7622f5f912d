"""The layout of the package (DESIGN.md): no import cycle between binpick's modules, the real
pick loop loads neither the emulators nor the simulator, and no source file is over 800 lines."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path
from typing import Optional

import pytest

# The repository's own sources, wherever the tests import binpick from: installed by `pip install .`
# binpick lives in site-packages, and a root found from it held no sources, so nothing was checked.
ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "python" / "binpick"
MAX_LINES = 800
SOURCE_SUFFIXES = (".py", ".pyi", ".rs")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


NATIVE = {"binpick._core"}  # the extension module: a leaf, imports nothing of binpick


def _is_type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _import_nodes(tree: ast.AST, *, lazy_getattr: bool) -> list[ast.stmt]:
    """Every import statement, top-level or inside functions; not those under ``if TYPE_CHECKING:``
    (never run) nor, in ``binpick/__init__.py``, those of the lazy ``__getattr__``."""
    found: list[ast.stmt] = []

    def visit(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and _is_type_checking(child):
                continue
            if lazy_getattr and isinstance(child, ast.FunctionDef) and child.name == "__getattr__":
                continue
            if isinstance(child, (ast.Import, ast.ImportFrom)):
                found.append(child)
            visit(child)

    visit(tree)
    return found


def _resolve(module: str, is_package: bool, node: ast.ImportFrom) -> str:
    if node.level == 0:
        return node.module or ""
    base = module.split(".") if is_package else module.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def import_graph() -> dict[str, set[str]]:
    """module → the binpick modules it imports (a ``from X import Y`` of a submodule Y is an edge to X.Y)."""
    modules = _modules()
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        edges: set[str] = set()
        for node in _import_nodes(tree, lazy_getattr=(name == "binpick")):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            else:
                base = _resolve(name, path.name == "__init__.py", node)
                known = set(modules) | NATIVE
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base for a in node.names]
            edges.update(t for t in targets if t in modules and t != name)
        graph[name] = edges
    return graph


def find_cycle(graph: dict[str, set[str]]) -> Optional[list[str]]:
    """One import cycle as a list of modules (first repeated at the end), or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> Optional[list[str]]:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt) :] + [nxt]
            if nxt not in state:
                cycle = visit(nxt)
                if cycle:
                    return cycle
        stack.pop()
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state:
            cycle = visit(start)
            if cycle:
                return cycle
    return None


def test_the_cycle_finder_finds_a_cycle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


def test_the_import_graph_sees_the_package():
    graph = import_graph()
    assert "binpick.cell.loop" in graph["binpick.sim.twin"]
    assert "binpick._validate" in graph["binpick.transforms"]
    assert "binpick.sim.camera" in graph["binpick.cell.cell_file"]  # a function-level import


def test_no_import_cycle_between_binpick_modules():
    cycle = find_cycle(import_graph())
    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


@pytest.mark.parametrize("leaf", ["binpick.transforms", "binpick.camera"])
def test_leaf_modules_import_only_errors_and_validation(leaf):
    assert import_graph()[leaf] <= {"binpick.errors", "binpick._validate"}


def test_the_real_pick_loop_loads_neither_the_emulators_nor_the_simulator():
    code = (
        "import sys, binpick.cell.loop; "
        "print('\\n'.join(m for m in sys.modules if m.startswith(('binpick.devices.emulators', 'binpick.sim'))))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == [], f"importing binpick.cell.loop loaded {out}"


def _oversized(root: str) -> list[str]:
    files = [
        p for p in (ROOT / root).rglob("*") if p.is_file() and p.suffix in SOURCE_SUFFIXES and "target" not in p.parts
    ]
    counts = {p: len(p.read_text(encoding="utf-8", errors="replace").splitlines()) for p in files}
    return [f"{p.relative_to(ROOT)}: {n} lines" for p, n in sorted(counts.items()) if n > MAX_LINES]


@pytest.mark.parametrize("root", ["python", "tests", "benches"])
def test_no_python_source_file_is_over_800_lines(root):
    assert _oversized(root) == []


def test_no_rust_source_file_is_over_800_lines():
    assert _oversized("rust") == []
