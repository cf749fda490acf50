"""Named registries: the one place where a kind of plug-in (a quality index, an object) is listed.

Adding an entry to a registry is all it takes to make it known everywhere: the lookups, the
lists of valid names in error messages and the command-line choices read the registry, never a
copy of its names. Only the standard library is imported here, so that a parser can list a
registry's names without loading numpy.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Generic, TypeVar, overload

from sahgrasp.core.errors import SahGraspError

__all__ = ["Registry", "RegistryNames"]

T = TypeVar("T")


class RegistryNames(Sequence[str]):
    """The names of a registry's entries, in registration order, read when used (a live view).

    A view taken at import time still lists the entries added later. ``filter`` keeps only the
    names whose entry it accepts.
    """

    def __init__(self, registry: Registry[T], filter: Callable[[T], bool] | None = None) -> None:
        self._registry = registry
        self._filter = filter

    def _names(self) -> tuple[str, ...]:
        entries = self._registry.items()
        return tuple(name for name, entry in entries if self._filter is None or self._filter(entry))

    @overload
    def __getitem__(self, index: int) -> str: ...
    @overload
    def __getitem__(self, index: slice) -> tuple[str, ...]: ...
    def __getitem__(self, index: int | slice) -> str | tuple[str, ...]:
        return self._names()[index]

    def __len__(self) -> int:
        return len(self._names())

    def __iter__(self) -> Iterator[str]:
        return iter(self._names())

    def __contains__(self, name: object) -> bool:
        return name in self._names()

    def __eq__(self, other: object) -> bool:
        if isinstance(other, RegistryNames | tuple | list):
            return self._names() == tuple(other)
        return NotImplemented

    __hash__ = None  # type: ignore[assignment]  # a live view changes: not a dictionary key

    def __repr__(self) -> str:
        return repr(self._names())


class Registry(Mapping[str, T], Generic[T]):
    """Entries by name, in registration order; lookups raise ``error`` listing the valid names.

    Args:
        kind: What an entry is, for messages (``"quality index"``).
        error: The :class:`~sahgrasp.core.errors.SahGraspError` subclass raised for an unknown name
            or a bad registration.
    """

    def __init__(self, kind: str, error: type[SahGraspError]) -> None:
        self.kind = kind
        self.error = error
        self._entries: dict[str, T] = {}

    def register(self, name: str, entry: T) -> T:
        """Add ``entry`` as ``name`` and return it.

        Raises:
            SahGraspError: (``error``) ``name`` is not a non-empty string or is already taken.
        """
        if not isinstance(name, str) or not name:
            raise self.error(f"a {self.kind} needs a non-empty name, got {name!r}")
        if name in self._entries:
            raise self.error(f"{self.kind} {name!r} is already registered")
        self._entries[name] = entry
        return entry

    def unregister(self, name: str) -> T:
        """Remove ``name`` and return its entry (a test's or a session's own entries).

        Raises:
            SahGraspError: (``error``) ``name`` is not registered.
        """
        entry = self.lookup(name)
        del self._entries[name]
        return entry

    def lookup(self, name: str) -> T:
        """The entry ``name``.

        Raises:
            SahGraspError: (``error``) no such entry; the message lists the valid names.
        """
        if not isinstance(name, str) or name not in self._entries:
            valid = ", ".join(self._entries)
            raise self.error(f"unknown {self.kind} {name!r}; valid: {valid}")
        return self._entries[name]

    def names(self, filter: Callable[[T], bool] | None = None) -> RegistryNames:
        """A live view of the names (of the entries that ``filter`` accepts)."""
        return RegistryNames(self, filter)

    def __getitem__(self, name: str) -> T:
        return self._entries[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}: {', '.join(self._entries)})"
