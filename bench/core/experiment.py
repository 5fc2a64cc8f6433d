"""What is learned and from which samples: the experiment, a value.

The suite has two experiments, :data:`DIRECT` and :data:`INDIRECT`. The
direct one learns ``L(q, qd)`` from samples of ``L``; the indirect one
learns it from joint torques, which the one Euler–Lagrange transform
(:mod:`bench.physics.dynamics`) makes of ``L`` and its second derivatives.
An :class:`Experiment` knows its target (the dataset's column, its name in
a record, its symbol in a table), its rows (one sample of ``L``, or ``dof``
torques, per state), the derivatives of ``L`` its prediction needs, and
how a model predicts it, so that code asks the experiment rather than
comparing its name.

An experiment is a ``str``, its name, so that specs, records, the command
line and JSON hold it as before; :meth:`Experiment.of` turns a name into
the experiment (and refuses another in one line).
"""

from __future__ import annotations

from typing import Any

from bench.core.errors import ConfigError


class Experiment(str):
    """One experiment (see the module docstring); make it with :meth:`of`.

    Attributes
    ----------
    target
        The targets' name: the dataset's attribute and a record's ``target``
        (``"L"`` or ``"tau"``).
    symbol
        Its symbol in a table (``L`` or ``τ``).
    order
        The derivatives of ``L`` a prediction needs: 0 (``L`` itself) or 2 (torques).
    learns_torque
        Whether the targets are joint torques (the indirect experiment).
    """

    target: str
    symbol: str
    order: int
    learns_torque: bool

    def __new__(cls, name: str, target: str, symbol: str, order: int):
        self = super().__new__(cls, name)
        self.target, self.symbol, self.order = target, symbol, order
        self.learns_torque = target == "tau"
        return self

    def __reduce__(self):  # pickled as its name: one instance of each experiment per process
        return (Experiment.of, (str(self),))

    @property
    def name(self) -> str:
        return str(self)

    @staticmethod
    def of(name: "str | Experiment") -> "Experiment":
        """The experiment named ``name``; :class:`ConfigError` in one line for another name."""
        if isinstance(name, Experiment):
            return name
        try:
            return _BY_NAME[name]
        except (KeyError, TypeError):
            raise ConfigError(f"unknown experiment {name!r}; choose one of {', '.join(EXPERIMENTS)}") from None

    def rows(self, dof: int) -> int:
        """Targets per state: one sample of ``L``, or ``dof`` torques."""
        return dof if self.learns_torque else 1

    def predict(self, model, data) -> Any:
        """``model``'s prediction of the targets of ``data``: its ``predict_lagrangian`` or ``predict_torque``."""
        return model.predict_torque(data) if self.learns_torque else model.predict_lagrangian(data)


#: learning L from samples of L
DIRECT = Experiment("direct", "L", "L", 0)
#: learning L from joint torques
INDIRECT = Experiment("indirect", "tau", "τ", 2)
#: both, in the order tables show them
EXPERIMENTS: tuple[Experiment, ...] = (DIRECT, INDIRECT)
_BY_NAME = {e.name: e for e in EXPERIMENTS}
