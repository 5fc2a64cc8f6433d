"""Registry of learning methods.

Each module below registers its method with ``@METHODS.add(name, *tags)``.
Adding a method: write one module and add it to the import line.

The contract: :mod:`methods.base` (the protocol a method's hooks plug into),
:mod:`methods.config` (hyperparameters, typed and ranged),
:mod:`methods.progress` (a fit's clock and best state) and
:mod:`methods.torch_method` (methods whose model is a torch module).
"""

from methods.base import METHODS, ExpressionMethod, ExpressionModel, Method
from methods.config import FRACTION, POSITIVE, MethodConfig, Range
from methods.progress import Progress
from methods.torch_method import TorchConfig, TorchLagrangianMethod

from methods import (delan, gp, mggp, mlp, operon, pysr_adapter, sparse, sparse_torque, syrenets,  # noqa: E402,F401
                     sysid)  # (each registers its method)
from methods import hybrid  # noqa: E402,F401  (composes PRIOR+RESIDUAL names)

__all__ = [
    "FRACTION", "METHODS", "POSITIVE", "ExpressionMethod", "ExpressionModel", "Method", "MethodConfig", "Progress",
    "Range", "TorchConfig", "TorchLagrangianMethod",
]
