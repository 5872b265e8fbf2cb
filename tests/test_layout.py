"""The house rules of the source tree: no import cycle, small modules, plots as a leaf.

The import graph is built from the source with the standard library's ``ast``:
every ``import`` counts, at module level or inside a function (a lazy import is
still a dependency); only imports under ``if TYPE_CHECKING:`` are left out, as
they never run. ``from package import name`` points to the submodule when
``name`` is one, otherwise to the package.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGE = "dischargelab"

#: Most lines a module under src/ may hold.
MAX_MODULE_LINES = 900

#: Modules that compute (the physics, fitting, simulation, logs, storage): none of them may
#: import matplotlib or the plotting module at module level.
PLOT_LEAF = f"{PACKAGE}.plot"


def _modules() -> dict[str, Path]:
    found = {}
    for path in sorted((SRC / PACKAGE).rglob("*.py")):
        parts = list(path.relative_to(SRC).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        found[".".join(parts)] = path
    return found


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _imports(tree: ast.AST, top_level_only: bool = False):
    """Yield (node, at_module_level) for every import that can run."""
    def walk(node, top):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and _is_type_checking(child.test):
                for sub in child.orelse:
                    yield from walk_one(sub, top)
                continue
            yield from walk_one(child, top)

    def walk_one(child, top):
        if isinstance(child, (ast.Import, ast.ImportFrom)):
            if top or not top_level_only:
                yield child, top
            return
        inner = top and not isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef,
                                                ast.Lambda))
        yield from walk(child, inner)

    yield from walk(tree, True)


def _target(name: str, modules: dict[str, Path]) -> str | None:
    while name:
        if name in modules:
            return name
        name = name.rpartition(".")[0]
    return None


def import_graph(top_level_only: bool = False) -> dict[str, set[str]]:
    """``{module: {modules it imports}}`` for every module of the package."""
    modules = _modules()
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for module, path in modules.items():
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node, _top in _imports(tree, top_level_only):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            else:
                if node.level:
                    base = package.split(".")
                    base = base[:len(base) - (node.level - 1)]
                    source = ".".join(base + ([node.module] if node.module else []))
                else:
                    source = node.module or ""
                names = [f"{source}.{alias.name}" for alias in node.names]
            for name in names:
                if name.split(".")[0] != PACKAGE:
                    continue
                target = _target(name, modules)
                if target is not None and target != module:
                    graph[module].add(target)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []
    counter = 0
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


def test_the_cycle_finder_finds_a_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert cycles(graph) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_the_graph_sees_lazy_imports_and_skips_type_checking(tmp_path):
    tree = ast.parse("from typing import TYPE_CHECKING\n"
                     "if TYPE_CHECKING:\n    from .model import Battery\n"
                     "def f():\n    from .plot import x\n")
    seen = [(n.module, top) for n, top in _imports(tree)]
    assert ("plot", False) in seen
    assert all(module != "model" for module, _ in seen)


def test_no_import_cycle():
    found = cycles(import_graph())
    assert not found, "import cycles: " + "; ".join(" <-> ".join(c) for c in found)


def test_modules_are_small():
    big = {name: n for name, path in _modules().items()
           if (n := len(path.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES}
    assert not big, f"modules over {MAX_MODULE_LINES} lines: {big}"


def test_plots_are_a_leaf():
    graph = import_graph()
    # formatting: how a number is written (the bottom layer, beside cell)
    allowed = ("errors", "atomic", "cell", "formatting")
    assert graph[PLOT_LEAF] <= {f"{PACKAGE}.{m}" for m in allowed} | {
        m for m in graph if m.startswith(f"{PACKAGE}.models")}, graph[PLOT_LEAF]
    top = import_graph(top_level_only=True)
    offenders = sorted(m for m, targets in top.items() if PLOT_LEAF in targets)
    assert not offenders, f"modules importing plot at module level: {offenders}"


@pytest.mark.parametrize("module", sorted(_modules()))
def test_no_matplotlib_at_module_level(module):
    path = _modules()[module]
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node, _top in _imports(tree, top_level_only=True):
        names = [a.name for a in node.names] if isinstance(node, ast.Import) else [
            node.module or ""]
        assert not any(n.split(".")[0] == "matplotlib" for n in names), module
