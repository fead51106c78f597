"""One registry mechanism: named entries of one kind, in the order they were registered.

Blocker kinds (:mod:`shtools.scene.blockers`), visibility methods and light-shadow
ways (:mod:`shtools.scene.shadows`) and SH product kernels
(:mod:`shtools.sh._kernels`) are each a :class:`Registry`.  The module that defines a
protocol owns its registry and registers its built-in entries; an entry in a module of
its own registers itself there, and one module imports every such plugin
(:mod:`shtools.scene.kinds` for the scene's registries), so a registry never imports
its users and no import cycle closes through it (``docs/architecture.md``,
"Protocols").

A package's public names can also be a registry of modules: :func:`lazy_attributes`
binds each name on first use (PEP 562), so a caller of one part of a package does not
pay for importing the rest.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Iterator, Mapping, MutableMapping
from typing import Generic, TypeVar

T = TypeVar("T")


class UnknownName(KeyError, ValueError):
    """A name no entry of a :class:`Registry` has; the message lists the choices.

    A :class:`KeyError` (so ``in``, ``get`` and mappings behave as usual) and a
    :class:`ValueError` (an unknown name is a bad value)."""

    def __str__(self) -> str:
        return str(self.args[0])


class Registry(MutableMapping[str, T], Generic[T]):
    """``name -> entry`` of one kind of plugin, iterated in registration order.

    Parameters
    ----------
    what : str
        What an entry is, for messages (``"blocker kind"``).
    check : callable, optional
        ``check(entry)`` raises :class:`ValueError` for an entry that breaks the
        protocol, before it is added.

    Examples
    --------
    >>> colours = Registry("colour")
    >>> colours.register("#f00", "red")
    '#f00'
    >>> colours["blue"]
    Traceback (most recent call last):
    ...
    shtools.registry.UnknownName: unknown colour 'blue'; use one of ('red',)
    """

    def __init__(self, what: str, *, check: Callable[[T], None] | None = None):
        self.what = what
        self._check = check
        self._entries: dict[str, T] = {}

    def register(self, entry: T, name: str | None = None) -> T:
        """Add ``entry`` under ``name`` (default: its ``name`` attribute); returns it.

        Raises
        ------
        ValueError
            The entry breaks the protocol, or the name is taken.
        """
        if self._check is not None:
            self._check(entry)
        name = entry.name if name is None else name
        if name in self._entries:
            raise ValueError(f"{self.what} '{name}' is already registered")
        self._entries[name] = entry
        return entry

    def names(self) -> tuple[str, ...]:
        """The registered names, in registration order."""
        return tuple(self._entries)

    def __getitem__(self, name: str) -> T:
        try:
            return self._entries[name]
        except KeyError:
            raise UnknownName(f"unknown {self.what} {name!r}; use one of "
                              f"{self.names()}") from None

    def __contains__(self, name) -> bool:
        return name in self._entries

    def __setitem__(self, name: str, entry: T) -> None:
        self.register(entry, name)

    def __delitem__(self, name: str) -> None:
        del self._entries[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def __repr__(self) -> str:
        return f"Registry({self.what!r}: {', '.join(self._entries)})"


def lazy_attributes(package: str, modules: Mapping[str, str]) -> tuple[Callable, Callable]:
    """A package's ``__getattr__`` and ``__dir__`` (PEP 562) for names loaded on first use.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    modules : mapping of str to str
        Public name -> the module that defines it.

    Returns
    -------
    getattr, dir : callable
        Assign them to the package's ``__getattr__`` and ``__dir__``.  A name is
        imported from its module once and then bound in the package, so later
        lookups are plain attribute reads.
    """
    def __getattr__(name: str):
        if name in modules:
            value = getattr(importlib.import_module(modules[name]), name)
            setattr(sys.modules[package], name, value)
            return value
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__():
        return sorted([*vars(sys.modules[package]), *modules])

    return __getattr__, __dir__
