"""The import-layer contract of docs/architecture.md: no package imports a layer above it.

Every ``import shtools.X`` / ``from shtools.X import`` in the package's source
(module level and inside functions) is checked against the table below.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "shtools"

#: package -> the shtools packages it may import (itself always allowed);
#: the table of docs/architecture.md "Layers"
ALLOWED = {
    "errors": set(),
    "progress": set(),  # the progress protocol, a leaf like errors
    "tasks": {"errors"},
    "sh": {"errors"},
    "data_formats": {"errors", "sh"},
    "runtime": {"errors", "tasks", "sh", "data_formats"},
    "geometry": {"errors", "progress", "tasks", "sh", "data_formats", "runtime"},
    "fields": {"errors", "progress", "tasks", "sh", "data_formats", "runtime", "geometry"},
    "lighting": {"errors", "progress", "sh", "data_formats", "runtime"},
    "reference": {"errors", "progress", "tasks", "sh", "data_formats", "runtime", "geometry",
                  "fields", "lighting"},
    "export": {"errors", "progress", "tasks", "sh", "data_formats", "runtime", "geometry",
               "fields", "lighting", "reference"},
    "scene": {"errors", "progress", "tasks", "sh", "data_formats", "runtime", "geometry",
              "fields",
              "lighting", "reference", "export"},
    "cli": {"*"},
    "demo": {"*"},
    "__init__": {"errors"},
    "__main__": {"*"},
}


def _package_of(path: Path) -> str:
    rel = path.relative_to(ROOT)
    return rel.parts[0].removesuffix(".py")


def _imports(path: Path):
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            yield node.lineno, node.module


def _violations():
    out = []
    for path in sorted(ROOT.rglob("*.py")):
        pkg = _package_of(path)
        allowed = ALLOWED.get(pkg)
        for line, name in _imports(path):
            parts = name.split(".")
            if parts[0] != "shtools" or len(parts) < 2:
                continue
            target = parts[1]
            if allowed is None:
                out.append(f"{path.relative_to(ROOT.parent)}: package '{pkg}' is not in the "
                           "layer table of docs/architecture.md")
                break
            if target != pkg and "*" not in allowed and target not in allowed \
                    and target != "__version__":
                out.append(f"{path.relative_to(ROOT.parent)}:{line}: {pkg} imports {name}")
    return out


def test_no_package_imports_a_layer_above_it():
    assert _violations() == []


@pytest.mark.parametrize("pkg", sorted(ALLOWED))
def test_every_layer_exists_or_is_planned(pkg):
    # a renamed package must be renamed here too (planned: fields)
    assert (ROOT / pkg).exists() or (ROOT / f"{pkg}.py").exists() or pkg in ("fields",)


# --------------------------------------------------------------------------- import cycles

#: Import cycles known today, each a group of modules (fnmatch patterns) that a cycle
#: may stay inside; every other cycle fails the test.  Entries only ever go: when a
#: cycle is broken, delete its entry.
KNOWN_CYCLES = {
    "scene: the kinds registry (scene/kinds.py) and the modules registering into it":
        ("shtools.scene.*",),
    "runtime: evaluator <-> parallel": ("shtools.runtime.evaluator", "shtools.runtime.parallel"),
    "export: writer <-> vat": ("shtools.export.writer", "shtools.export.vat"),
}


def _module_name(path: Path, root: Path) -> str:
    rel = path.relative_to(root.parent).with_suffix("")
    parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
    return ".".join(parts)


def _import_graph(root: Path = ROOT) -> dict[str, set[str]]:
    """Module of the package at ``root`` -> the package's modules it imports, at module
    level or inside functions; ``from package import name`` counts the submodule
    ``name`` if there is one, else the package."""
    paths = {_module_name(p, root): p for p in root.rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for mod, path in paths.items():
        is_package = path.name == "__init__.py"
        out = graph.setdefault(mod, set())
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = mod.split(".")[: len(mod.split(".")) - node.level + is_package]
                    name = ".".join(base + ([node.module] if node.module else []))
                else:
                    name = node.module
                targets = [f"{name}.{alias.name}" if f"{name}.{alias.name}" in paths else name
                           for alias in node.names]
            else:
                continue
            out.update(t for t in targets if t in paths and t != mod)
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[set[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[set[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.add(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(component)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_cycle_finder_counts_imports_inside_functions(tmp_path):
    """The finder itself, on a package written here: a cycle closed only by an
    import inside a function, and one through a relative ``from . import``, are
    found; a chain without a back-edge is not."""
    pkg = tmp_path / "demo_pkg"
    (pkg / "sub").mkdir(parents=True)
    files = {
        "__init__.py": "",
        "a.py": "from demo_pkg import b\n",
        "b.py": "import os\n\ndef f():\n    from demo_pkg.a import g\n",
        "c.py": "import demo_pkg.a\n",
        "sub/__init__.py": "",
        "sub/x.py": "from . import y\n",
        "sub/y.py": "from .x import h\n",
        "sub/z.py": "from demo_pkg.sub import x\n",
    }
    for name, text in files.items():
        (pkg / name).write_text(text)
    cycles = sorted(sorted(c) for c in _cycles(_import_graph(pkg)))
    assert cycles == [["demo_pkg.a", "demo_pkg.b"], ["demo_pkg.sub.x", "demo_pkg.sub.y"]]


def test_no_import_cycles_between_shtools_modules():
    import fnmatch

    unknown = []
    for cycle in _cycles(_import_graph()):
        if not any(all(any(fnmatch.fnmatchcase(m, p) for p in patterns) for m in cycle)
                   for patterns in KNOWN_CYCLES.values()):
            unknown.append(sorted(cycle))
    assert unknown == [], ("import cycles (imports inside functions count); break them, "
                           f"or if they are known, name them in KNOWN_CYCLES: {unknown}")
