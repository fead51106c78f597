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
    "cache": set(),  # the set-up cache: stdlib and numpy only
    "sh": {"errors"},
    "data_formats": {"errors", "sh"},
    "runtime": {"errors", "tasks", "sh", "data_formats"},
    "geometry": {"errors", "progress", "cache", "tasks", "sh", "data_formats", "runtime"},
    "fields": {"errors", "progress", "cache", "tasks", "sh", "data_formats", "runtime",
               "geometry"},
    "lighting": {"errors", "progress", "cache", "sh", "data_formats", "runtime"},
    "reference": {"errors", "progress", "cache", "tasks", "sh", "data_formats", "runtime",
                  "geometry", "fields", "lighting"},
    "export": {"errors", "progress", "cache", "tasks", "sh", "data_formats", "runtime",
               "geometry", "fields", "lighting", "reference"},
    "scene": {"errors", "progress", "cache", "tasks", "sh", "data_formats", "runtime",
              "geometry", "fields", "lighting", "reference", "export"},
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
