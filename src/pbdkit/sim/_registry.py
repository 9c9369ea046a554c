"""A registry of named variants (tasks, perturbations): name -> entry, in registration order.

One entry per name; registering the same entry again does nothing, another one of the same name
is refused. The command line's choices are :meth:`Registry.names`.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Generic, Protocol, TypeVar

from .._validation import short


class _Named(Protocol):
    @property
    def name(self) -> str: ...


E = TypeVar("E", bound=_Named)


class Registry(Generic[E]):
    """Entries of one kind by name.

    Parameters
    ----------
    kind : str
        What an entry is, in messages and in the name of the function that forgets one
        (``"task"``: ``unregister_task``).
    entry_type : type
        The class every entry must be an instance of.
    argument : str
        The name of the register function's argument, for its error message.
    option : str
        The name a user chooses an entry by (``--task``, ``perturb=``), for the message of an
        unknown name.
    hint : str
        Appended to that message (how to add an entry).
    """

    def __init__(
        self, kind: str, entry_type: type[E], argument: str, option: str, hint: str = ""
    ) -> None:
        self.kind, self.entry_type, self.argument = kind, entry_type, argument
        self.option, self.hint = option, hint
        self._entries: dict[str, E] = {}
        #: A read-only view of the entries, name -> entry.
        self.view: Mapping[str, E] = MappingProxyType(self._entries)

    def register(self, entry: E) -> E:
        """Make ``entry`` known by its name; returns it.

        Raises
        ------
        ValueError
            If ``entry`` is not of the registry's type, or another entry has the same name.
        """
        if not isinstance(entry, self.entry_type):
            raise ValueError(
                f"{self.argument} must be a {self.entry_type.__name__}, got {type(entry).__name__}"
            )
        known = self._entries.get(entry.name)
        if known is not None and known is not entry:
            raise ValueError(
                f"{self.kind} {short(entry.name)} is already registered; choose another name (or "
                f"unregister_{self.kind} it first)"
            )
        self._entries[entry.name] = entry
        return entry

    def unregister(self, name: str) -> E:
        """Forget the entry ``name`` and return it; ValueError if it is not registered."""
        entry = self.get(name)
        del self._entries[entry.name]
        return entry

    def names(self) -> tuple[str, ...]:
        """Names of the entries, in registration order."""
        return tuple(self._entries)

    def get(self, name: str) -> E:
        """The entry ``name``; ValueError naming the choices if there is none."""
        entry = self._entries.get(name) if isinstance(name, str) else None
        if entry is None:
            raise ValueError(
                f"{self.option} must be one of {list(self._entries)}, got {short(name)}{self.hint}"
            )
        return entry
