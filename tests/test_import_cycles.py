"""The import graph of ``calib_core/`` and ``app/`` has no cycles, and no panel imports another panel.

The graph is read from the sources with :mod:`ast`, not by importing them:
every ``import`` and ``from ... import`` counts, at any depth (a function's
lazy import too), relative ones resolved against the importing module.  A
package's ``__init__`` is a module of its own (``calib_core.solve``); a
package that re-exports from its submodules is fine as long as none of them
imports the package back.  ``from pkg import name`` is an edge to ``pkg``
(even when ``name`` is a submodule, since it may be a name the package's
``__init__`` defines) and, when ``pkg.name`` is a module, an edge to it
too; names outside the two packages are ignored.

A cycle is a strongly connected component of more than one module (Tarjan's
algorithm); the test names every module of each one.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("calib_core", "app")


def module_files(root: Path = REPO, packages: tuple[str, ...] = PACKAGES) -> dict[str, Path]:
    """Dotted module name -> source file, for every ``.py`` file under ``packages`` (``__init__`` as the package)."""
    modules = {}
    for package in packages:
        for path in sorted((root / package).rglob("*.py")):
            parts = path.relative_to(root).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            modules[".".join(parts)] = path
    return modules


def _known(name: str, modules: dict[str, Path]) -> str | None:
    """The longest prefix of dotted ``name`` that is one of ``modules`` (``a.b.func`` -> ``a.b``), or None."""
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name or None


def imported_modules(module: str, node: ast.Import | ast.ImportFrom, modules: dict[str, Path]) -> set[str]:
    """The modules of ``modules`` that one import statement of ``module`` imports."""
    if isinstance(node, ast.Import):
        targets = [alias.name for alias in node.names]
    else:
        if node.level:  # relative: from the module's package (a package's __init__ is its own package)
            base = module.split(".")
            if modules[module].name != "__init__.py":
                base = base[:-1]
            base = base[: len(base) - (node.level - 1)]
            source = ".".join(base + ([node.module] if node.module else []))
        else:
            source = node.module or ""
        targets = [source] + [f"{source}.{alias.name}" for alias in node.names]
    found = {_known(name, modules) for name in targets}
    return {name for name in found if name is not None and name != module}


def import_graph(modules: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> the modules it imports anywhere in its source (top level, functions, classes)."""
    graph: dict[str, set[str]] = defaultdict(set)
    for module, path in modules.items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                graph[module] |= imported_modules(module, node, modules)
    return graph


def strongly_connected_components(graph: dict[str, set[str]], nodes) -> list[list[str]]:
    """Tarjan's algorithm, iterative (no recursion limit); every component, each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components = []
    for root in nodes:
        if root in index:
            continue
        work = [(root, iter(sorted(graph.get(root, ()))))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, edges = work[-1]
            for succ in edges:
                if succ not in index:
                    index[succ] = low[succ] = len(index)
                    stack.append(succ)
                    on_stack.add(succ)
                    work.append((succ, iter(sorted(graph.get(succ, ())))))
                    break
                if succ in on_stack:
                    low[node] = min(low[node], index[succ])
            else:
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
                    components.append(sorted(component))
    return components


def import_cycles(root: Path = REPO, packages: tuple[str, ...] = PACKAGES) -> list[list[str]]:
    """The strongly connected components of more than one module: each is one or more import cycles."""
    modules = module_files(root, packages)
    graph = import_graph(modules)
    return [c for c in strongly_connected_components(graph, sorted(modules)) if len(c) > 1]


def _write_package(root: Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


def test_the_analysis_finds_lazy_relative_and_package_cycles(tmp_path):
    """The analysis itself, on a made-up package with one cycle of each kind and some imports that are none."""
    _write_package(tmp_path, {
        "pkg/__init__.py": "from .models import Model\n",
        "pkg/models.py": "from . import Model as _again\n",  # back into the package: a cycle of two
        "pkg/low.py": "import os\n\ndef f():\n    from .high import g\n    return g\n",  # lazy import
        "pkg/high.py": "from pkg.low import f\n",
        "pkg/sub/__init__.py": "",
        "pkg/sub/leaf.py": "from ..low import f\nfrom .. import models\n",  # into a cycle, not part of one
        "other/__init__.py": "import pkg.sub.leaf\n",
    })
    assert sorted(import_cycles(tmp_path, ("pkg", "other"))) == [["pkg", "pkg.models"], ["pkg.high", "pkg.low"]]
    _write_package(tmp_path, {"pkg/models.py": "class Model:\n    pass\n", "pkg/high.py": "import os.path\n"})
    assert import_cycles(tmp_path, ("pkg", "other")) == []


def test_no_import_cycles_in_calib_core_and_app():
    cycles = import_cycles()
    assert cycles == [], "import cycles (strongly connected modules):\n" + "\n".join(
        f"  {len(c)}: {', '.join(c)}" for c in cycles)


def panel_modules(modules: dict[str, Path]) -> set[str]:
    """The app's panes and panels: ``app/*_panel.py``, ``app/render_pane.py``, ``app/loupes.py``."""
    return {m for m in modules if m.startswith("app.") and (m.endswith("_panel") or m in ("app.render_pane", "app.loupes"))}


def test_no_panel_imports_another_panel():
    """Panels talk through the app object (``app.render_pane``, ``app.loupes``, ...), never by importing each other;
    what several of them need (page keys, layout) lives in shared modules below them."""
    modules = module_files()
    graph = import_graph(modules)
    panels = panel_modules(modules)
    assert len(panels) >= 10  # the glob still finds them
    crossings = sorted(f"{m} imports {', '.join(sorted(graph[m] & panels))}" for m in panels if graph[m] & panels)
    assert crossings == [], "panel modules importing other panel modules:\n  " + "\n  ".join(crossings)
