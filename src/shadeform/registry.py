"""One kind of registry for every family of interchangeable parts: the solvers
(:mod:`shadeform.solvers`), the integrators (:mod:`shadeform.integration`), the mesh exporters
(:mod:`shadeform.io.exporters`) and the photometric-stereo models
(:mod:`shadeform.photometric.registry`) are each one :class:`Registry`.

An entry is a frozen record with a ``name`` (what users type), a one-line ``description`` and,
optionally, ``options``: a tuple of :class:`Option` (name, type, default, help) that the command
line (``--option NAME=VALUE``), the app's ``/api/options`` and ``shadeform solvers`` read. Entries
are looked up by name and listed in registration order; every listing is read from the registry
when asked, never copied at import, so an entry registered later (by a plug-in, by a test) is
everywhere at once.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

from shadeform._checks import check_choice, is_number
from shadeform.errors import InputError

__all__ = ["OPTION_TYPES", "Option", "Registry", "load"]

#: The types an option may have.
OPTION_TYPES = (bool, int, float, str)

_TRUE, _FALSE = ("true", "yes", "on", "1"), ("false", "no", "off", "0")

Entry = TypeVar("Entry")


@dataclass(frozen=True)
class Option:
    """One option of a registry entry, e.g. ``Option("strength", float, 1.0, "how strongly")``.

    Attributes
    ----------
    name : str
        A Python identifier: what users type (``--option strength=2``) and the key the entry
        reads (``problem.options["strength"]`` for a solver).
    type : {bool, int, float, str}
    default : bool, int, float or str
        The value when the user gives none (converted to ``type``).
    help : str
        One line in the user's words.
    """

    name: str
    type: type
    default: Any
    help: str

    def __post_init__(self):
        if not self.name.isidentifier():
            raise ValueError(f"option name must be a Python identifier, got {self.name!r}")
        if self.type not in OPTION_TYPES:
            raise ValueError(f"option type must be one of bool, int, float, str, got {self.type!r}")
        object.__setattr__(self, "default", self.parse(self.default))

    def parse(self, value: Any) -> Any:
        """``value`` as this option's type; text (from the command line) is read as that type.

        Raises
        ------
        InputError
            If ``value`` is not of the type nor text that reads as one.
        """
        if isinstance(value, str) and self.type is not str:
            value = _read(value.strip(), self.type)
        if self.type is bool and isinstance(value, bool):
            return value
        if self.type is int and is_number(value) and float(value).is_integer():
            return int(value)
        if self.type is float and is_number(value) and math.isfinite(value):
            return float(value)
        if self.type is str and isinstance(value, str):
            return value
        raise InputError(f"option {self.name!r} must be {_WORDS[self.type]}, got {value!r}")

    def describe(self) -> dict[str, Any]:
        """The option as JSON: ``{"name", "type", "default", "help"}``, ``type`` by its name."""
        return {"name": self.name, "type": self.type.__name__, "default": self.default, "help": self.help}


_WORDS = {bool: "true or false", int: "a whole number", float: "a finite number", str: "text"}


def _read(text: str, kind: type) -> Any:
    """Command-line text as ``kind``; the text itself when it does not read (the caller refuses it)."""
    if kind is bool:
        lowered = text.lower()
        return True if lowered in _TRUE else False if lowered in _FALSE else text
    try:
        return kind(text)
    except ValueError:
        return text


class Registry(Generic[Entry]):
    """Records of one kind by name, in registration order.

    Parameters
    ----------
    what : str
        What a name names, in the user's words, for errors: ``"method"`` gives "unknown method
        'x'; choose one of: ...".
    kind : type
        The record class every entry must be (with ``name``, ``description`` and, optionally,
        ``options`` attributes).
    """

    def __init__(self, what: str, kind: type) -> None:
        self.what = what
        self.kind = kind
        self._entries: dict[str, Entry] = {}

    def register(self, entry: Entry) -> Entry:
        """Add (or replace) ``entry`` under its name; returns it."""
        if not isinstance(entry, self.kind):
            name = self.kind.__name__
            article = "an" if name[0] in "AEIOU" else "a"
            raise TypeError(f"register expects {article} {name}, got {type(entry).__name__}")
        self._entries[entry.name] = entry
        return entry

    def get(self, name: str) -> Entry:
        """The entry called ``name``.

        Raises
        ------
        InputError
            If none is: the message lists the registered names.
        """
        return self._entries[check_choice(name, self.names(), self.what)]

    def names(self) -> tuple[str, ...]:
        """The registered names, in registration order."""
        return tuple(self._entries)

    def entries(self) -> tuple[Entry, ...]:
        """The registered entries, in registration order."""
        return tuple(self._entries.values())

    def descriptions(self) -> dict[str, str]:
        """Name to one-line description, in registration order."""
        return {name: entry.description for name, entry in self._entries.items()}

    def options(self, name: str) -> tuple[Option, ...]:
        """The options the entry called ``name`` declares (none for most)."""
        return tuple(getattr(self.get(name), "options", ()))

    def settle(self, name: str, given: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """Every option of the entry called ``name``: the user's values (``given``, read as their
        types) over the defaults.

        Raises
        ------
        InputError
            For an option the entry does not declare, or a value of the wrong type.
        """
        declared = {option.name: option for option in self.options(name)}
        for key in given or {}:
            if key not in declared:
                offered = ", ".join(declared) or "none"
                raise InputError(f"{self.what} {name!r} has no option {key!r}; its options: {offered}")
        given = given or {}
        return {
            key: option.parse(given[key]) if key in given else option.default
            for key, option in declared.items()
        }

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(tuple(self._entries))

    def __len__(self) -> int:
        return len(self._entries)

    @contextmanager
    def restored(self) -> Iterator[Registry[Entry]]:
        """Within the block entries may be added or replaced freely; on leaving it the registry is
        as it was (tests)."""
        saved = dict(self._entries)
        try:
            yield self
        finally:
            self._entries = saved


def load(target: Callable | str) -> Callable:
    """``target`` itself, or the function a ``"module:function"`` text names (its module imported
    the first time: listing a registry stays cheap)."""
    if isinstance(target, str):
        module, _, function = target.partition(":")
        return getattr(importlib.import_module(module), function)
    return target
