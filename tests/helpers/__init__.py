"""Helpers the tests share: procedural rigs (:mod:`helpers.rig`), scene files written
from Python dicts (:mod:`helpers.scenes`) and child-process checks
(:mod:`helpers.processes`).

``pythonpath = ["tests"]`` in pyproject.toml's pytest settings makes this package
importable as ``helpers`` from every test module (no ``sys.path`` edits in tests).
"""
