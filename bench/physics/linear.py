"""Models linear in their coefficients.

* :class:`LinearParametricModel`: a system's :class:`~bench.physics.system.LinearForm`
  (an arm's rigid-body regressor, with further terms) at fitted values of its
  base parameters; its ``M`` and ``c`` come from the form's engine where the
  form has one (:attr:`~bench.physics.system.LinearForm.dynamics`);
* :class:`TermModel`: terms of the term library at their coefficients
  (the residual loop's effects), predicted from the terms summed where they act;
* :func:`torque_regressor` and :func:`lagrangian_regressor`: a form's
  regressors on a data set, with its further terms' columns.
"""

from __future__ import annotations

import functools
import weakref
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from bench.core.data import Dataset
from bench.core.kept import read_only
from bench.core.modelfile import ModelFileError, Packer, Unpacker, loader
from bench.physics.models import FittedModel, term_from_json, term_to_json
from bench.physics.terms import Term, TermLibrary


#: each linear form's torque regressor on each data set, ``{data: {form: (n, dof, p)}}``; an
#: entry goes with its data set
_REGRESSORS: "weakref.WeakKeyDictionary[Dataset, dict]" = weakref.WeakKeyDictionary()


def torque_regressor(form, data: Dataset) -> np.ndarray:
    """``form.torque_regressor`` at the states of ``data``, with the form's
    further :attr:`~bench.physics.system.LinearForm.terms`' columns, computed once
    per form and data set (read-only): the residual loop refits a linear model's
    coefficients many times on the same data, and an arm's regressor costs
    a pass of its rigid-body algorithm per sample."""
    kept = _REGRESSORS.setdefault(data, {})
    if form not in kept:
        Y = np.asarray(form.torque_regressor(data.q, data.qd, data.qdd), dtype=np.float64)
        if form.terms:
            extra = TermLibrary(form.terms).design(data, "indirect").reshape(len(data), data.dof, len(form.terms))
            Y = np.concatenate([Y, extra], axis=2)
        kept[form] = read_only(Y)
    return kept[form]


def lagrangian_regressor(form, data: Dataset) -> np.ndarray:
    """``form.lagrangian_regressor`` at the states of ``data``, with each of
    the form's further :attr:`~bench.physics.system.LinearForm.terms`' value in
    ``L`` (zero for friction): ``(n, p)``."""
    Y = form.lagrangian_regressor(data.q, data.qd)
    if not form.terms:
        return Y
    return np.column_stack([Y] + [t.value(data) for t in form.terms])


class LinearParametricModel(FittedModel):
    """A :class:`~bench.physics.system.LinearForm` at fitted values of some of its
    columns (its base parameters): ``tau = Y[:, :, columns] @ coef`` and
    ``L = Y_L[:, columns] @ coef + offset``.

    ``names`` say what each coefficient is (a base parameter is a parameter
    plus the combination of those that act only together with it).
    """

    def __init__(self, form, columns, coef, names: Sequence[str] | None = None, offset: float = 0.0,
                 feasible: "FeasibleSet | None" = None):
        self.form, self.columns = form, np.asarray(columns, dtype=int)
        self.coef, self.offset = np.asarray(coef, dtype=np.float64), float(offset)
        self.names = tuple(names) if names is not None else tuple(form.names[i] for i in self.columns)
        self.feasible = feasible

    def torque_columns(self, data: Dataset) -> np.ndarray:
        """The model's columns in torque space, flattened sample-major: ``(n * dof, k)``
        (the form's regressor on ``data`` is computed once, :func:`torque_regressor`)."""
        return torque_regressor(self.form, data)[:, :, self.columns].reshape(-1, len(self.columns))

    def predict_torque(self, data: Dataset) -> np.ndarray:
        return (self.torque_columns(data) @ self.coef).reshape(len(data), data.dof)

    def predict_lagrangian(self, data: Dataset) -> np.ndarray:
        return lagrangian_regressor(self.form, data)[:, self.columns] @ self.coef + self.offset

    def mass_and_bias(self, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """From the form's engine at the model's parameters (the regressors'
        columns: zero where not a base column) plus its further terms', where
        the form has one (:attr:`~bench.physics.system.LinearForm.dynamics`);
        else from the regressor at ``dof + 1`` accelerations a state."""
        dynamics = self.form.dynamics
        if dynamics is None:
            return super().mass_and_bias(q, qd)
        pi, further = self._parameters
        M, c = dynamics(pi, q, qd)
        if further is not None:
            M_t, c_t = further.mass_and_bias(q, qd)
            M, c = M + M_t, c + c_t
        return M, c

    @functools.cached_property
    def _parameters(self) -> tuple[np.ndarray, "TermModel | None"]:
        """The regressors' columns at the model's values (zero where not a base
        column), and the form's further terms at theirs (``None`` without any)."""
        rigid = len(self.form.names) - len(self.form.terms)
        pi = np.zeros(len(self.form.names))
        pi[self.columns] = self.coef
        return pi[:rigid], TermModel(list(self.form.terms), pi[rigid:]) if self.form.terms else None

    def with_coefficients(self, coef) -> "LinearParametricModel":
        return LinearParametricModel(self.form, self.columns, coef, self.names, self.offset, self.feasible)

    def parameters(self) -> dict[str, float]:
        """The fitted values, by name."""
        return dict(zip(self.names, self.coef.tolist()))

    def parametric(self) -> "LinearParametricModel":
        return self

    def structure(self) -> str:
        """``"feasible"`` for a model whose parameters are held physically
        feasible (:attr:`feasible`), ``"linear"`` otherwise."""
        return "linear" if self.feasible is None else "feasible"

    def saved(self, packer: Packer) -> dict:
        """Its coefficients, the form's further terms, and the form's regressor
        at :data:`PROBE_STATES` fixed states, by which loading checks that the
        system gives the same form."""
        extra = len(self.form.terms)
        return {"kind": "linear", "columns": packer.array(self.columns), "coef": packer.array(self.coef),
                "names": list(self.names), "offset": self.offset,
                "terms": [term_to_json(t) for t in self.form.terms],
                "term_names": list(self.form.names[len(self.form.names) - extra:]),
                "feasible": None if self.feasible is None else {
                    "bodies": self.feasible.bodies, "prior": packer.array(self.feasible.prior),
                    "regularisation": self.feasible.regularisation,
                    "nonnegative": [int(i) for i in self.feasible.nonnegative]},
                "probe": packer.array(_probe(self.form))}


#: the states at which a saved linear model's form is checked against the system's when it is loaded
PROBE_STATES = 3


def _probe(form) -> np.ndarray:
    """``form``'s torque regressor at :data:`PROBE_STATES` fixed states."""
    rng = np.random.default_rng(0)
    q, qd, qdd = (rng.uniform(-1.0, 1.0, (PROBE_STATES, form.dof)) for _ in range(3))
    return torque_regressor(form, Dataset(q, qd, qdd, np.zeros_like(q)))


@loader("linear")
def _load_linear(tree: dict, unpacker: Unpacker, context: dict) -> "LinearParametricModel":
    system = context.get("system")
    form = None if system is None else system.linear_form()
    if form is None:
        raise ModelFileError(f"{unpacker.source}: its model is an arm's linear form, and "
                             f"{getattr(system, 'name', 'no system')} gives none")
    terms = [term_from_json(t, unpacker.source) for t in tree["terms"]]
    form = form.with_terms(terms[len(form.terms):], tree["term_names"][len(form.terms):])
    probe = unpacker.array(tree["probe"])
    if probe.shape != _probe(form).shape or not np.allclose(_probe(form), probe, rtol=1e-9, atol=1e-12):
        raise ModelFileError(f"{unpacker.source}: {system.name}'s model is not the one this model was fitted on "
                             f"(its regressor differs at the probe states)")
    feasible = tree.get("feasible")
    return LinearParametricModel(
        form, unpacker.array(tree["columns"]), unpacker.array(tree["coef"]), tree["names"], float(tree["offset"]),
        None if feasible is None else FeasibleSet(int(feasible["bodies"]), tuple(unpacker.array(feasible["prior"])),
                                                  float(feasible["regularisation"]),
                                                  tuple(int(i) for i in feasible.get("nonnegative", ()))))


@dataclass(frozen=True)
class FeasibleSet:
    """How a linear model's parameters are held feasible (:func:`bench.physics.feasible.feasible_fit`):
    its first ``bodies`` blocks of 10 columns are rigid bodies', pulled toward
    ``prior`` with weight ``regularisation``, and the columns ``nonnegative``
    (a joint's friction) are held at 0 or above."""

    bodies: int
    prior: tuple[float, ...]
    regularisation: float
    nonnegative: tuple[int, ...] = ()


class TermModel(FittedModel):
    """Terms of the term library at their coefficients, ``tau = Phi c``.

    It predicts from the terms summed where they act (:meth:`~bench.physics.terms.TermLibrary.summed`):
    a driven rollout asks for the torque of a few states at each of its
    steps, and pays one Euler–Lagrange transform a step for all the terms of
    ``L``. Its ``M`` and ``c`` come from the terms whose torque does not depend
    on ``qdd`` once a state, and from the others at ``dof + 1`` accelerations."""

    def __init__(self, terms: list[Term], coef):
        self.terms, self.coef = list(terms), np.asarray(coef, dtype=np.float64)

    @functools.cached_property
    def _parts(self) -> list["_Summed"]:
        """The terms summed, those of the state alone first, then the others."""
        parts = []
        for moving in (False, True):
            chosen = [k for k, t in enumerate(self.terms) if t.takes_accelerations == moving]
            if chosen:
                parts.append(_Summed(TermLibrary([self.terms[k] for k in chosen]).summed(self.coef[chosen])))
        return parts

    def predict_torque(self, data: Dataset) -> np.ndarray:
        return sum((part.predict_torque(data) for part in self._parts), np.zeros((len(data), data.dof)))

    def predict_lagrangian(self, data: Dataset) -> np.ndarray:
        return sum((c * t.value(data) for c, t in zip(self.coef, self.terms)), np.zeros(len(data)))

    def takes_accelerations(self) -> bool:
        return any(t.takes_accelerations for t in self.terms)

    def mass_and_bias(self, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n, dof = q.shape
        M, c = np.zeros((n, dof, dof)), np.zeros((n, dof))
        for part in self._parts:
            M_p, c_p = part.mass_and_bias(q, qd)
            M, c = M + M_p, c + c_p
        return M, c


class _Summed(FittedModel):
    """Summed terms (coefficient 1 each): one part of a :class:`TermModel`."""

    def __init__(self, terms: list[Term]):
        self.terms = terms

    def predict_torque(self, data: Dataset) -> np.ndarray:
        return sum((t.torque(data, often=True) for t in self.terms), np.zeros((len(data), data.dof)))

    def predict_lagrangian(self, data: Dataset) -> np.ndarray:
        return sum((t.value(data) for t in self.terms), np.zeros(len(data)))

    def takes_accelerations(self) -> bool:
        return any(t.takes_accelerations for t in self.terms)
