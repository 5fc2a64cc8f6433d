"""A plugin method whose loss is not the stacked loop's: the MLP with a weight
penalty in ``extra_loss``. Under ``--stack-seeds`` it must train each seed alone
and say why (``--plugin tests/plugins/penalised.py``)."""

from __future__ import annotations

from methods import METHODS
from methods.mlp import MLP


@METHODS.add("penalised_mlp", "toy")
class PenalisedMLP(MLP):
    """The MLP plus ``1e-2`` times its squared weights in the loss."""

    def extra_loss(self):
        return 1e-2 * sum((p ** 2).sum() for p in self.model.parameters())
