"""Named registries of methods and systems.

A registry maps a unique name to an object (a class) and a set of tags.
Entries are added with a decorator, never discovered by globbing files::

    METHODS = Registry("method")

    @METHODS.add("mlp", "neural", "baseline")
    class MLP(Method):
        ...

The registry's own package names the modules that register its built-in
entries (:attr:`Registry.built_in`), and the registry imports them, once, the
first time it is asked for a name or a listing (the package's ``__getattr__``
asks as it hands the registry out), so that importing the package costs
nothing until then. Modules outside the registry's own
package that register entries (the suite's residual loop, another installed
package's methods) are declared as entry points of the registry's group in
their package's metadata (``[project.entry-points."syrenets_bench.methods"]``
in ``pyproject.toml``), never registered by a side effect of some other
import: the registry imports them, once, at the same moment, after its own.

An entry may declare itself unavailable (a missing optional dependency, a
runtime that cannot start) through a class method ``unavailable_reason()``
that returns ``None`` when it can run and a human-readable reason otherwise.
Unavailable entries stay listed, with their reason; they are never dropped.
"""

from __future__ import annotations

import difflib
from importlib.metadata import entry_points
from dataclasses import dataclass, field
from typing import Any, Callable, Generic, Iterator, TypeVar

from bench.core.errors import UserError
from bench.core.names import is_name

T = TypeVar("T")


class RegistryError(UserError, KeyError):
    """An unknown or duplicate name in a registry."""

    def __str__(self) -> str:  # KeyError quotes its message; keep it readable
        return str(self.args[0])


class UnknownName(RegistryError):
    """A name that no entry holds: :attr:`name` is the part of it that a plugin could register (a hybrid's
    residual, for a hybrid whose residual is unknown)."""

    def __init__(self, message: str, name: str):
        super().__init__(message)
        self.name = name


@dataclass(frozen=True)
class Entry(Generic[T]):
    name: str
    obj: T
    tags: frozenset[str] = field(default_factory=frozenset)
    #: the entries a composed entry is made of (its object's ``made_of``)
    made_of: tuple[str, ...] = ()

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
    """A name -> object map filled by a decorator, with tags and subsets.

    A registry may compose entries on demand: ``composer(name)`` returns an
    object for a name no decorator registered (a method made of two others,
    ``standard+gp``), or ``None``; the object is registered under that name
    the first time it is asked for, and raises :class:`RegistryError` itself
    for a composed name that is wrong. An object's ``made_of`` names the entries
    it is made of, so that removing one removes it.
    """

    def __init__(self, kind: str, group: str | None = None):
        self.kind = kind
        self._entries: dict[str, Entry[T]] = {}
        self.composer: Callable[[str], T | None] | None = None
        self._composed: dict[str, Entry[T]] = {}  # not listed by names(): made on demand
        #: the entry-point group whose modules register entries (see the module docstring)
        self.group = group
        #: what imports the modules of the registry's own package that register its entries: set by that package
        self.built_in: Callable[[], None] | None = None
        self._own_loaded = self._declared_loaded = False

    def load_built_in(self) -> None:
        """Import, once, the registry's own modules (:attr:`built_in`)."""
        if not self._own_loaded and self.built_in is not None:
            self._own_loaded = True
            self.built_in()

    def load_declared(self) -> None:
        """Import, once, the registry's own modules (:attr:`built_in`), then those that installed packages declare
        in :attr:`group`; one of the latter that fails to import is a :class:`RegistryError` naming it."""
        self.load_built_in()
        if self._declared_loaded:
            return
        self._declared_loaded = True
        for point in entry_points(group=self.group) if self.group else ():
            try:
                point.load()
            except Exception as exc:
                raise RegistryError(f"the {self.kind} module {point.value!r} that entry point {point.name!r} "
                                    f"declares ({self.group}) failed to import: {type(exc).__name__}: {exc}") from None

    def add(self, name: str, *tags: str) -> Callable[[T], T]:
        """Register the decorated object under ``name`` with ``tags``.

        Refuses a name that is already taken. The object's ``name`` attribute
        is set to the registered name when the object allows it.
        """
        if not is_name(name):
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
        """Drop an entry (used by tests that register toys), and what was composed of it."""
        self._entries.pop(name, None)
        self._composed = {k: v for k, v in self._composed.items() if k != name and name not in v.made_of}

    def entry(self, name: str) -> Entry[T]:
        self.load_declared()
        try:
            return self._entries.get(name) or self._composed[name]
        except KeyError:
            composed = self.composer(name) if self.composer is not None else None
            if composed is not None:
                tags = frozenset(getattr(composed, "tags", ()))
                try:
                    setattr(composed, "name", name)
                except (AttributeError, TypeError):
                    pass
                self._composed[name] = Entry(name, composed, tags, tuple(getattr(composed, "made_of", ())))
                return self._composed[name]
            close = difflib.get_close_matches(name, list(self._entries), n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            known = ", ".join(sorted(self._entries)) or "none"
            raise UnknownName(f"unknown {self.kind} {name!r}{hint} (known: {known})", name) from None

    def __getitem__(self, name: str) -> T:
        return self.entry(name).obj

    def __contains__(self, name: object) -> bool:
        self.load_declared()
        if name in self._entries or name in self._composed:
            return True
        if not isinstance(name, str) or self.composer is None:
            return False
        try:
            self.entry(name)
        except RegistryError:
            return False
        return True

    def __iter__(self) -> Iterator[str]:
        self.load_declared()
        return iter(sorted(self._entries))

    def __len__(self) -> int:
        self.load_declared()
        return len(self._entries)

    def names(self, *tags: str) -> list[str]:
        """Sorted names carrying every one of ``tags`` (all names if none)."""
        self.load_declared()
        want = set(tags)
        return sorted(n for n, e in self._entries.items() if want <= e.tags)

    def entries(self, *tags: str) -> list[Entry[T]]:
        return [self._entries[n] for n in self.names(*tags)]

    def tagged(self, *tags: str) -> dict[str, Any]:
        return {n: self._entries[n].obj for n in self.names(*tags)}
