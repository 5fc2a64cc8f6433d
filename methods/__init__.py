"""Registry of learning methods.

Each module named in :data:`BUILT_IN` registers its method with
``@METHODS.add(name, *tags)``. Adding a method: write one module and add its
name to :data:`BUILT_IN`.

The contract: :mod:`methods.base` (the protocol a method's hooks plug into),
:mod:`methods.config` (hyperparameters, typed and ranged),
:mod:`methods.progress` (a fit's clock and best state) and
:mod:`methods.torch_method` (methods whose model is a torch module).

The package imports nothing until one of its names is asked for (PEP 562's
module ``__getattr__``), and the registry imports the modules of
:data:`BUILT_IN` the first time it is asked for a method
(:attr:`bench.core.registry.Registry.built_in`), so that a module that
only names the package (a run's spec, a command's options) costs nothing
until a method is looked up.
"""

from __future__ import annotations

import importlib

#: the modules that register the suite's methods, imported the first time the registry is asked for one; the
#: hybrids (``PRIOR+RESIDUAL`` names) last, since they compose the others
BUILT_IN = ("delan", "gp", "mggp", "mlp", "operon", "pysr_adapter", "sparse", "sparse_torque", "syrenets", "sysid",
            "hybrid")
#: the names this package gives, by the module that defines each
_EXPORTS = {
    "METHODS": "methods.base", "ExpressionMethod": "methods.base", "ExpressionModel": "methods.base",
    "Method": "methods.base", "FRACTION": "methods.config", "POSITIVE": "methods.config",
    "MethodConfig": "methods.config", "Range": "methods.config", "Progress": "methods.progress",
    "TorchConfig": "methods.torch_method", "TorchLagrangianMethod": "methods.torch_method",
}

__all__ = sorted(_EXPORTS)


def register_built_in() -> None:
    """Import :data:`BUILT_IN`: the registry's :attr:`~bench.core.registry.Registry.built_in`
    (:mod:`methods.base`)."""
    for name in BUILT_IN:
        importlib.import_module(f"methods.{name}")


def __getattr__(name: str):
    if name in _EXPORTS:
        value = getattr(importlib.import_module(_EXPORTS[name]), name)
        if name == "METHODS":  # handed out whole: a plugin that registers a method is checked against the suite's
            value.load_built_in()
        return value
    raise AttributeError(f"module 'methods' has no attribute {name!r}")
