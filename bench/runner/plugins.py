"""Plugins: methods and systems registered outside the suite, imported by
file path or module name before their names are resolved, robot arms given
as ``urdf:PATH`` (:func:`systems.urdf_arm.register_urdf`) and measured arms
as ``measured:PATH`` (:func:`systems.measured_arm.register_measured`)."""

from __future__ import annotations

import importlib
import importlib.util
import os
import sys
import zlib
from pathlib import Path
from typing import Iterable

import systems
from bench.core.errors import UserError
from bench.core.fileio import file_digest
from systems.measured import read_spec

#: a system given by its robot description: ``urdf:PATH``
URDF = "urdf:"
#: a measured arm given by its declaration file: ``measured:PATH``
MEASURED = "measured:"
#: the systems given by a file, by prefix: the module and function that register each
BY_FILE = {URDF: ("systems.urdf_arm", "register_urdf"), MEASURED: ("systems.measured_arm", "register_measured")}


def import_plugins(plugins: Iterable[str]) -> None:
    """Import each plugin once: a ``.py`` path, a module name, ``urdf:PATH`` or ``measured:PATH``."""
    for plugin in plugins:
        try:
            prefix = file_prefix(plugin)
            if prefix:
                register_by_file(plugin)
                continue
            _import_plugin(plugin)
        except UserError:
            raise
        except Exception as exc:
            raise UserError(f"plugin {plugin}: {type(exc).__name__}: {exc}") from exc


def code_plugins(plugins: Iterable[str]) -> list[str]:
    """The plugins among ``plugins`` that run code when imported: a ``.py`` file or a module (a ``urdf:`` or
    ``measured:`` file is read, not run)."""
    return [p for p in plugins if not file_prefix(p)]


def plugin_key(plugin: str) -> str:
    """What names one code plugin however it was written: a file's resolved path, a module's name."""
    return str(Path(plugin).expanduser().resolve()) if plugin.endswith(".py") else plugin


def plugin_digest(plugin: str) -> str | None:
    """The sha256 of a code plugin's file (a module's where its spec names one); ``None`` where it has none.
    A module is found, not imported (its parent packages are)."""
    if plugin.endswith(".py"):
        path = Path(plugin).expanduser()
    else:
        try:
            spec = importlib.util.find_spec(plugin)
        except (ImportError, ValueError):
            return None
        path = Path(spec.origin) if spec is not None and spec.has_location and spec.origin else None
    return file_digest(path) if path is not None and path.is_file() else None


def _import_plugin(plugin: str) -> None:
    if not plugin.endswith(".py"):
        importlib.import_module(plugin)
        return
    path = Path(plugin).resolve()
    if not path.is_file():
        raise UserError(f"plugin {plugin}: no such file")
    if _imported(path):
        return  # already imported (for instance by a test runner): do not register twice
    name = f"_bench_plugin_{path.stem}_{zlib.crc32(str(path).encode()):08x}"
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise UserError(f"plugin {plugin}: not an importable Python file")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise


def _imported(path: Path) -> bool:
    """Whether an imported module was loaded from the file ``path`` (the same file, by any name or link). Each
    module's file is compared by ``os.stat``: resolving every module's path, thousands once torch is imported,
    cost a third of a second in every run of a plugin's method."""
    target = os.stat(path)
    for module in list(sys.modules.values()):
        file = getattr(module, "__file__", None)
        if isinstance(file, str):
            try:
                st = os.stat(file)
            except OSError:
                continue
            if st.st_ino == target.st_ino and st.st_dev == target.st_dev:
                return True
    return False


def system_plugins(names: Iterable[str]) -> tuple[list[str], tuple[str, ...]]:
    """System names as given on a command line, with ``urdf:PATH`` entries
    registered and replaced by their names; returns the names and the
    plugins a run's own process needs to resolve them."""
    out, plugins = [], []
    for name in names:
        prefix = file_prefix(name)
        if prefix:
            plugin = prefix + str(Path(name[len(prefix):]).expanduser().resolve())
            out.append(register_by_file(plugin))
            plugins.append(plugin)
        else:
            out.append(name)
    return out, tuple(plugins)


def register_by_file(plugin: str) -> str:
    """Register the system of ``urdf:PATH`` or ``measured:PATH``; returns its name. A
    :class:`UserError` where the arms' engine is missing here. A measured arm's file is read and checked
    (:func:`systems.measured.read_spec`) before the systems, their physics and Pinocchio are imported, so
    that a bad one is refused at once."""
    if file_prefix(plugin) == MEASURED:
        read_spec(plugin[len(MEASURED):])
    if systems.WITHOUT_ARMS:
        raise UserError(f"{plugin}: {systems.WITHOUT_ARMS}")
    module, register = BY_FILE[file_prefix(plugin)]
    return getattr(importlib.import_module(module), register)(plugin)


def file_prefix(name: str) -> str | None:
    """The prefix of a system given by a file (``urdf:``, ``measured:``), or ``None``."""
    return next((p for p in BY_FILE if name.startswith(p)), None)
