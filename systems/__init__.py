"""Registry of physical systems.

Each module named in :data:`BUILT_IN` registers its systems with
``@SYSTEMS.add(name, *tags)``. Adding a system: write one module and add its
name to :data:`BUILT_IN`.

The package imports nothing until one of its names is asked for (PEP 562's
module ``__getattr__``), and the registry imports the modules of
:data:`BUILT_IN` the first time it is asked for a system
(:attr:`bench.core.registry.Registry.built_in`). So a command that reads a
file and refuses it (:mod:`systems.measured`'s declaration, say) imports
neither the physics nor Pinocchio first.
"""

from __future__ import annotations

import importlib

#: the modules that register the suite's systems, imported the first time the registry is asked for one
BUILT_IN = ("cart_pole", "delan_characters", "dfki_double_pendulum", "double_pendulum", "n_link_pendulum",
            "single_pendulum", "spring_pendulum")
#: the modules of the arms from URDF files (panda, ur5, kuka_lwr4, ``urdf:`` and ``measured:`` files), built with
#: Pinocchio: registered only where it can be imported (:data:`WITHOUT_ARMS` says why not otherwise)
ARMS = ("measured_arm", "urdf_arm")
#: the names this package gives, from :mod:`systems.base`
_FROM_BASE = ("SYSTEMS", "Domain", "ParametricForm", "System", "get_system")

__all__ = ["SYSTEMS", "Domain", "ParametricForm", "System", "get_system"]


def register_built_in() -> None:
    """Import :data:`BUILT_IN` and :data:`ARMS`; set :data:`WITHOUT_ARMS`. The registry's
    :attr:`~bench.core.registry.Registry.built_in` (:mod:`systems.base`)."""
    global WITHOUT_ARMS
    for name in BUILT_IN:
        importlib.import_module(f"systems.{name}")
    WITHOUT_ARMS = None
    try:
        for name in ARMS:
            importlib.import_module(f"systems.{name}")
    except ModuleNotFoundError as exc:
        if exc.name is None or exc.name.split(".")[0] not in ("pinocchio", "pin"):
            raise
        WITHOUT_ARMS = f"the arms from URDF files need Pinocchio, which is not installed here ({exc}; pip install pin)"


def __getattr__(name: str):
    if name in _FROM_BASE:
        value = getattr(importlib.import_module("systems.base"), name)
        if name == "SYSTEMS":  # handed out whole: a plugin that registers a system is checked against the suite's
            value.load_built_in()
        return value
    if name == "WITHOUT_ARMS":  # why the arms are not registered, where Pinocchio cannot be imported; else None
        __getattr__("SYSTEMS")
        return globals()["WITHOUT_ARMS"]
    raise AttributeError(f"module 'systems' has no attribute {name!r}")
