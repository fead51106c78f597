"""The import-layer contract of docs/architecture.md: no package imports a layer above it,
no import cycles, and the doc itself true (its layer table is this one, its paths exist).

Every ``import shtools.X`` / ``from shtools.X import`` in the package's source
(module level and inside functions) is checked against the table below.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "shtools"

#: package -> the shtools packages it may import (itself always allowed);
#: the table of docs/architecture.md "Layers"
ALLOWED = {
    "errors": set(),
    "registry": set(),  # the one registry mechanism (name -> entry), a leaf like errors
    "progress": set(),  # the progress protocol, a leaf like errors
    "tasks": {"errors", "registry"},  # a package: pool, workers, dask_cluster
    "cache": set(),  # the set-up cache: stdlib and numpy only
    "blend": set(),  # the one smoothstep of every continuous transition, a leaf
    "field_limits": set(),  # a shadow field's parameter bounds (the CLI's and the sampler's)
    "sh": {"errors", "registry", "blend"},
    "data_formats": {"errors", "registry", "sh"},
    "runtime": {"errors", "registry", "blend", "tasks", "sh", "data_formats"},
    "geometry": {"errors", "registry", "progress", "cache", "tasks", "sh", "data_formats",
                 "runtime"},
    "fields": {"errors", "registry", "progress", "cache", "tasks", "field_limits", "sh",
               "data_formats", "runtime", "geometry"},
    "lighting": {"errors", "registry", "progress", "cache", "sh", "data_formats", "runtime"},
    "reference": {"errors", "registry", "progress", "cache", "tasks", "sh", "data_formats",
                  "runtime", "geometry", "fields", "lighting"},
    "export": {"errors", "registry", "progress", "cache", "tasks", "sh", "data_formats",
               "runtime", "geometry", "fields", "lighting", "reference"},
    "scene": {"errors", "registry", "blend", "progress", "cache", "tasks", "sh", "data_formats",
              "runtime", "geometry", "fields", "lighting", "reference", "export"},
    "cli": {"*"},
    "demo": {"*"},
    "view": {"*"},  # the browser viewer, beside the CLI
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
    cycles = sorted(sorted(c) for c in _cycles(_import_graph()))
    assert cycles == [], f"import cycles (imports inside functions count): {cycles}"

# --------------------------------------------------------------------------- docs/architecture.md

REPO = ROOT.parent
DOC = REPO / "docs" / "architecture.md"


def _layer_rows() -> dict[str, set[str]]:
    """package -> the shtools packages its row of the "Layers" table allows."""
    text = DOC.read_text(encoding="utf-8")
    section = text.split("## Layers", 1)[1].split("\n## ", 1)[0]
    rows = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 4 or not cells[0].isdigit():
            continue
        allowed = set(re.findall(r"`(\w+)`", cells[2]))
        if cells[2].startswith("everything"):
            allowed = {"*"}
        for pkg in re.findall(r"`shtools\.(\w+)`", cells[1].split(" — ")[0]):
            rows[pkg] = allowed
    return rows


def test_layer_table_matches_the_enforced_one():
    assert _layer_rows() == {pkg: set(allowed) for pkg, allowed in ALLOWED.items()}


def _quoted() -> list[str]:
    return re.findall(r"`([^`\s]+)`", DOC.read_text(encoding="utf-8"))


def test_every_path_named_exists():
    paths = [q for q in _quoted()
             if re.match(r"(shtools|tests|docs|benchmarks|examples)/[\w./-]*$", q)]
    assert len(paths) >= 5  # the doc names paths; a parse that finds none is broken
    missing = [p for p in paths if not (REPO / p).exists()]
    assert missing == []


def _defines(module: Path, name: str) -> bool:
    tree = ast.parse(module.read_text(encoding="utf-8"))
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)) and node.name == name:
            return True
        if isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            if any(isinstance(t, ast.Name) and t.id == name for t in targets):
                return True
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            if any((a.asname or a.name.split(".")[-1]) == name for a in node.names):
                return True
    return False


def test_every_shtools_name_exists():
    """``shtools.a.b.C`` names a module ``shtools/a/b`` (or ``.py``) defining ``C``;
    an attribute after a class (``.method``) is not checked."""
    missing = []
    names = [q for q in _quoted() if re.match(r"shtools\.[\w.]+$", q)]
    assert len(names) >= 10
    for name in names:
        parts = name.split(".")
        for cut in range(len(parts), 0, -1):
            base = REPO.joinpath(*parts[:cut])
            module = base / "__init__.py" if base.is_dir() else base.with_suffix(".py")
            if module.exists():
                rest = parts[cut:]
                if rest and not _defines(module, rest[0]):
                    missing.append(name)
                break
        else:
            missing.append(name)
    assert missing == []


# --------------------------------------------------------------------------- module size

#: Longest module a reader should have to hold in their head (docs/architecture.md)
MAX_MODULE_LINES = 600


def test_no_module_is_longer_than_the_limit():
    long = {str(p.relative_to(REPO)): n for p in sorted(ROOT.rglob("*.py"))
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES}
    assert long == {}, f"split these by responsibility: {long}"
