"""Counting the calls a test makes of a library function."""

from __future__ import annotations


def count_calls(monkeypatch, owner, name: str) -> list:
    """Replace ``owner.name`` for the test by a wrapper that calls it and appends 1 to
    the returned list each time: ``len(calls)`` is the number of calls so far."""
    calls = []
    real = getattr(owner, name)

    def counting(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(owner, name, counting)
    return calls
