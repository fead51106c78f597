"""No file of the repository carries a leftover merge-conflict marker."""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: git's markers: seven '<' or '>' followed by a space and a label, or '=' alone.
MARKER = re.compile(r"^(<{7} |>{7} |={7}$)", re.MULTILINE)
TEXT = {".py", ".md", ".toml", ".cfg", ".txt", ".yml", ".yaml", ""}


def test_no_conflict_markers():
    bad = []
    for path in REPO.rglob("*"):
        if (not path.is_file() or path.suffix not in TEXT or
                any(part.startswith(".") or part in ("out", "build") for part in
                    path.relative_to(REPO).parts)):
            continue
        try:
            text = path.read_text(encoding="utf-8")
        except (UnicodeDecodeError, OSError):
            continue
        if MARKER.search(text):
            bad.append(str(path.relative_to(REPO)))
    assert bad == []
