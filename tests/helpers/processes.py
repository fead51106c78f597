"""Child processes of a test, read from /proc (Linux): what a stopped or refused
command may have left running; and what a fresh interpreter imports."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

#: Packages a pipeline embedding shtools.runtime must not need (docs/architecture.md,
#: "Layers").
RUNTIME_FORBIDDEN = ("trimesh", "pymeshlab", "igl", "scipy", "embreex", "matplotlib", "click")


def alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, reaped by no one yet, does not)."""
    try:
        # the state follows the command name in parentheses, which may hold spaces
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in ("Z", "X")


def children(pid: int | None = None) -> list[int]:
    """Live child processes of ``pid`` (default this process), of any of its threads."""
    pid = os.getpid() if pid is None else pid
    out = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        with contextlib.suppress(OSError):
            out += [int(c) for c in (task / "children").read_text().split()]
    return [c for c in out if alive(c)]


def cmdline(pid: int) -> bytes | None:
    """The NUL-separated command line of ``pid``, or None once it is gone."""
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return None


def unprivileged_prefix() -> list[str]:
    """The command prefix that runs a child as an unprivileged user: nothing when this
    process is not root, ``setpriv`` to ``nobody`` when it is.  Root without ``setpriv``
    skips the calling test: root may write any read-only file, so there is nothing to
    refuse."""
    import pytest

    if os.geteuid() != 0:
        return []  # already unprivileged
    if shutil.which("setpriv") is None:
        pytest.skip("root without setpriv: cannot run as an unprivileged user, and root "
                    "may write any read-only file")
    return ["setpriv", "--reuid=nobody", "--regid=nogroup", "--clear-groups"]


def forbidden_imports(code: str, forbidden=RUNTIME_FORBIDDEN) -> list[str]:
    """The ``forbidden`` top-level packages a fresh interpreter has imported once it has
    run ``code`` (Python source), sorted."""
    done = subprocess.run([sys.executable, "-c", code + "\nimport json, sys\n"
                           "print(json.dumps(sorted(sys.modules)))\n"],
                          capture_output=True, text=True, check=True, timeout=120)
    loaded = json.loads(done.stdout.strip().splitlines()[-1])
    return sorted({m.split(".")[0] for m in loaded} & set(forbidden))
