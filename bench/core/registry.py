"""Named registries of methods and systems.

A registry maps a unique name to an object (a class) and a set of tags.
Entries are added with a decorator, never discovered by globbing files::

    METHODS = Registry("method")

    @METHODS.add("mlp", "neural", "baseline")
    class MLP(Method):
        ...

An entry may declare itself unavailable (a missing optional dependency, a
runtime that cannot start) through a class method ``unavailable_reason()``
that returns ``None`` when it can run and a human-readable reason otherwise.
Unavailable entries stay listed, with their reason; they are never dropped.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass, field
from typing import Any, Callable, Generic, Iterator, TypeVar

from bench.core.errors import UserError

T = TypeVar("T")


class RegistryError(UserError, KeyError):
    """An unknown or duplicate name in a registry."""

    def __str__(self) -> str:  # KeyError quotes its message; keep it readable
        return str(self.args[0])


@dataclass(frozen=True)
class Entry(Generic[T]):
    name: str
    obj: T
    tags: frozenset[str] = field(default_factory=frozenset)

    def unavailable_reason(self) -> str | None:
        """``None`` when the entry can run, else why it cannot."""
        check = getattr(self.obj, "unavailable_reason", None)
        if check is None:
            return None
        try:
            return check()
        except Exception as exc:  # an availability probe must never crash a listing
            return f"availability check raised {type(exc).__name__}: {exc}"

    @property
    def available(self) -> bool:
        return self.unavailable_reason() is None


class Registry(Generic[T]):
    """A name -> object map filled by a decorator, with tags and subsets."""

    def __init__(self, kind: str):
        self.kind = kind
        self._entries: dict[str, Entry[T]] = {}

    def add(self, name: str, *tags: str) -> Callable[[T], T]:
        """Register the decorated object under ``name`` with ``tags``.

        Refuses a name that is already taken. The object's ``name`` attribute
        is set to the registered name when the object allows it.
        """
        if not name or not name.replace("_", "").isalnum():
            raise ValueError(f"{self.kind} name {name!r} must be a non-empty identifier")

        def decorator(obj: T) -> T:
            if name in self._entries:
                raise RegistryError(
                    f"{self.kind} {name!r} is already registered "
                    f"(by {self._entries[name].obj!r})"
                )
            try:
                setattr(obj, "name", name)
                setattr(obj, "tags", frozenset(tags))
            except (AttributeError, TypeError):
                pass
            self._entries[name] = Entry(name, obj, frozenset(tags))
            return obj

        return decorator

    def remove(self, name: str) -> None:
        """Drop an entry (used by tests that register toys)."""
        self._entries.pop(name, None)

    def entry(self, name: str) -> Entry[T]:
        try:
            return self._entries[name]
        except KeyError:
            close = difflib.get_close_matches(name, list(self._entries), n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            known = ", ".join(sorted(self._entries)) or "none"
            raise RegistryError(f"unknown {self.kind} {name!r}{hint} (known: {known})") from None

    def __getitem__(self, name: str) -> T:
        return self.entry(name).obj

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(sorted(self._entries))

    def __len__(self) -> int:
        return len(self._entries)

    def names(self, *tags: str) -> list[str]:
        """Sorted names carrying every one of ``tags`` (all names if none)."""
        want = set(tags)
        return sorted(n for n, e in self._entries.items() if want <= e.tags)

    def entries(self, *tags: str) -> list[Entry[T]]:
        return [self._entries[n] for n in self.names(*tags)]

    def tagged(self, *tags: str) -> dict[str, Any]:
        return {n: self._entries[n].obj for n in self.names(*tags)}
