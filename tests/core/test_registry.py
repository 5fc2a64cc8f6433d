"""Registries: decorator registration, duplicates, tags, availability."""

from __future__ import annotations

import pytest

from bench.core.registry import Registry, RegistryError


def test_add_get_tags_and_subsets():
    reg = Registry("widget")

    @reg.add("a", "fast", "neural")
    class A:
        pass

    @reg.add("b", "fast")
    class B:
        pass

    assert reg["a"] is A and A.name == "a" and A.tags == {"fast", "neural"}
    assert reg.names() == ["a", "b"]
    assert reg.names("fast") == ["a", "b"]
    assert reg.names("fast", "neural") == ["a"]
    assert list(reg.tagged("neural")) == ["a"]
    assert "a" in reg and "c" not in reg and len(reg) == 2


def test_duplicate_names_are_refused():
    reg = Registry("widget")
    reg.add("a")(type("A", (), {}))
    with pytest.raises(RegistryError, match="already registered"):
        reg.add("a")(type("A2", (), {}))


def test_unknown_name_suggests_the_closest():
    reg = Registry("method")
    reg.add("sysid")(type("S", (), {}))
    with pytest.raises(RegistryError, match="unknown method 'sysidd'; did you mean 'sysid'"):
        reg["sysidd"]


def test_unavailable_entries_are_listed_with_their_reason():
    reg = Registry("method")

    @reg.add("needs_julia", "needs-julia")
    class NeedsJulia:
        @classmethod
        def unavailable_reason(cls):
            return "no Julia runtime"

    @reg.add("broken_probe")
    class BrokenProbe:
        @classmethod
        def unavailable_reason(cls):
            raise RuntimeError("probe exploded")

    assert reg.names() == ["broken_probe", "needs_julia"]
    assert reg.entry("needs_julia").unavailable_reason() == "no Julia runtime"
    assert not reg.entry("needs_julia").available
    assert "probe exploded" in reg.entry("broken_probe").unavailable_reason()


def test_suite_registries_hold_the_foundation_entries():
    from methods import METHODS
    from systems import SYSTEMS

    assert {"mlp", "sysid"} <= set(METHODS)
    assert "double_pendulum" in SYSTEMS
    assert all(METHODS.entry(n).available for n in ("mlp", "sysid"))


class _Point:
    """An entry point as importlib.metadata gives it: a name, a module, and what importing it does."""

    def __init__(self, name, value, load):
        self.name, self.value, self.load = name, value, load


def test_modules_declared_in_the_registrys_group_are_imported_once_on_the_first_question(monkeypatch):
    reg = Registry("thing", group="example.things")
    loads = []

    def load():
        loads.append(1)
        reg.add("declared", "tag")(type("Declared", (), {}))

    asked = []
    monkeypatch.setattr("bench.core.registry.entry_points",
                        lambda group: asked.append(group) or [_Point("declared", "pkg.things", load)])
    reg.add("own")(type("Own", (), {}))
    assert loads == []  # nothing imported before a question
    assert reg.names() == ["declared", "own"] and "declared" in reg and reg["declared"].__name__ == "Declared"
    assert loads == [1] and asked == ["example.things"]


def test_a_declared_module_that_fails_to_import_is_one_line_naming_it(monkeypatch):
    reg = Registry("thing", group="example.things")

    def load():
        raise ImportError("No module named 'pkg'")

    monkeypatch.setattr("bench.core.registry.entry_points", lambda group: [_Point("broken", "pkg.things", load)])
    with pytest.raises(RegistryError, match=r"'pkg\.things' that entry point 'broken' declares \(example\.things\) "
                                            r"failed to import: ImportError"):
        reg.names()
