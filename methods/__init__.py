"""Registry of learning methods.

Each module below registers its method with ``@METHODS.add(name, *tags)``.
Adding a method: write one module and add it to the import line.
"""

from methods.base import (
    FRACTION,
    METHODS,
    POSITIVE,
    ExpressionMethod,
    ExpressionModel,
    Method,
    MethodConfig,
    Progress,
    Range,
    TorchConfig,
    TorchLagrangianMethod,
)

from methods import mggp, mlp, operon, pysr_adapter, sparse, syrenets, sysid  # noqa: E402,F401  (registers)

__all__ = [
    "FRACTION", "METHODS", "POSITIVE", "ExpressionMethod", "ExpressionModel", "Method", "MethodConfig", "Progress",
    "Range", "TorchConfig", "TorchLagrangianMethod",
]
