"""The one fitted-model interface, and the models the suite builds from it.

A fitted model predicts a Lagrangian and its torques at the states of a
:class:`~bench.core.data.Dataset`. Every method's fit
(:class:`methods.base.Method`), every variant a method derives, the residual
loop's models and the rollout's true model are :class:`FittedModel` s, and
the rest of the suite uses nothing else of them:

* :meth:`~FittedModel.predict_lagrangian` and
  :meth:`~FittedModel.predict_torque` (abstract);
* :meth:`~FittedModel.expression`: the Lagrangian as a sympy expression, or
  ``None`` for a model without one (a neural network);
* :meth:`~FittedModel.parametric`: the model as a parametric form with
  identified values (:class:`ParametricModel`), or ``None``;
* :meth:`~FittedModel.structure`: what kind of model it is (parametric,
  linear in its parameters, an expression, or opaque), for code that treats
  kinds differently;
* :meth:`~FittedModel.not_a_lagrangian`: why the model is not a Lagrangian
  of ``(q, qd)`` alone, or ``None``;
* :meth:`~FittedModel.mass_and_bias`: ``M`` and ``c`` of ``tau = M qdd + c``
  (the forward dynamics' and the checks' one source), and
  :meth:`~FittedModel.takes_accelerations`, which lets a torque of the state
  alone give them from one torque a state.

Models given by a batched torch function ``L(q, qd)`` subclass
:class:`LagrangianFunction`, which owns their predictions (torques through
the suite's one Euler–Lagrange transform); :class:`ExpressionModel` (a sympy
Lagrangian) and :class:`ParametricModel` (a system's parametric form at
given parameter values) are two of them.
"""

from __future__ import annotations

import abc
import functools
import weakref
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import sympy
import torch

from bench.core import symbolic
from bench.core.data import Dataset
from bench.core.experiment import Experiment
from bench.physics.dynamics import euler_lagrange_chunked
from bench.core.expressions import expression_from_json, expression_to_json
from bench.core.modelfile import Packer, Unpacker, loader
from bench.physics.terms import Term, TermLibrary

#: rows per call when a model's Lagrangian is evaluated on a large data set
CHUNK = 8192


@dataclass(frozen=True)
class NoVariant:
    """Why a method gives no model for one of its variants
    (:meth:`methods.base.Method.variants`), with the outcome it is: ``"timeout"``
    where the variant's work ran out of the run's budget, ``"not_applicable"``
    where the variant does not apply to the configuration, ``"failed"`` else."""

    reason: str
    status: str = "failed"

    def __post_init__(self):
        if self.status not in ("failed", "timeout", "not_applicable"):
            raise ValueError(f"a variant's outcome is failed, timeout or not_applicable; got {self.status!r}")

    def __str__(self) -> str:
        return self.reason


class FittedModel(abc.ABC):
    """A fitted Lagrangian model; see the module docstring."""

    @abc.abstractmethod
    def predict_lagrangian(self, data: Dataset) -> np.ndarray:
        """``L`` at the states of ``data``, shape ``(n,)``."""

    @abc.abstractmethod
    def predict_torque(self, data: Dataset) -> np.ndarray:
        """``tau`` at the states of ``data``, shape ``(n, dof)``."""

    def expression(self) -> sympy.Expr | None:
        """The Lagrangian in ``q_i, qd_i``; ``None`` for a model without one."""
        return None

    def expression_terms_bound(self) -> int | None:
        """An upper bound on the number of terms of :meth:`expression`, known
        without building it, for a model whose expression is costly to build;
        ``None`` where building it is cheap (it is then built and counted)."""
        return None

    def readable_expression(self) -> sympy.Expr | None:
        """The expression a person should read (what records store); by default :meth:`expression`."""
        return self.expression()

    def parametric(self) -> "ParametricModel | None":
        """The model as a parametric form with identified values, if it is one."""
        return None

    def structure(self) -> str:
        """What kind of model this is, for code that treats kinds differently
        (the residual loop's refit strategies): ``"parametric"`` (a form with
        nonlinear parameters, :class:`ParametricModel`), ``"linear"`` (linear
        in its parameters, :class:`LinearParametricModel`), ``"expression"``
        (an expression whose terms' coefficients can be refitted) or
        ``"opaque"`` (a function only, a network). By default that of
        :meth:`parametric` where the model gives one, else ``"expression"``
        where it has an expression."""
        parametric = self.parametric()
        if parametric is not None and parametric is not self:
            return parametric.structure()
        if self.expression_terms_bound() is not None or self.expression() is not None:
            return "expression"
        return "opaque"

    def not_a_lagrangian(self) -> str | None:
        """Why the model is not a Lagrangian of ``(q, qd)`` alone, or ``None``
        where it is. A model that also takes ``qdd`` as an input (a
        documented deviation of some configurations) has torques that are
        not affine in ``qdd``: it has no forward dynamics to roll out, and
        its expression cannot be judged against a Lagrangian."""
        return None

    def takes_accelerations(self) -> bool:
        """Whether the torque depends on ``qdd``. ``False`` for a torque of
        the state alone (a friction law, a GP of ``(q, qd)``): its mass matrix
        is zero, and :meth:`mass_and_bias` asks one torque a state. By default
        ``True``."""
        return True

    def mass_and_bias(self, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``M`` of shape ``(n, dof, dof)`` and ``c`` of shape ``(n, dof)`` with
        ``tau = M qdd + c``. By default from one :meth:`predict_torque` call at
        ``dof + 1`` accelerations a state (every Lagrangian's torque is affine
        in ``qdd``), or at ``qdd = 0`` alone where the torque
        :meth:`takes_accelerations` not; a model made of others combines
        theirs (:class:`methods.hybrid.Hybrid`)."""
        n, dof = q.shape
        if not self.takes_accelerations():
            zeros = np.zeros((n, dof))
            c = np.asarray(self.predict_torque(Dataset(q, qd, zeros, zeros)), dtype=np.float64)
            return np.zeros((n, dof, dof)), c
        return affine_parts(self.predict_torque(unit_accelerations(q, qd)), n)

    def saved(self, packer: Packer) -> dict:
        """The model as a model file holds it (:mod:`bench.core.modelfile`): a
        JSON tree with its ``kind`` (which :data:`~bench.core.modelfile.LOADERS`
        loads) and references to the arrays put in ``packer``. By default its
        expression, where predictions come from one; a ``ValueError`` says why
        a model cannot be saved."""
        if self.structure() == "expression" and self.not_a_lagrangian() is None:
            expr = self.expression()
            if expr is not None:
                return {"kind": "expression", "expression": expression_to_json(expr)}
        raise ValueError(f"a {type(self).__name__} model cannot be saved to a model file yet")

    def predict(self, data: Dataset, experiment: str) -> np.ndarray:
        """The prediction in the experiment's own target: ``L`` (direct) or ``tau`` (indirect)."""
        return Experiment.of(experiment).predict(self, data)


class LagrangianFunction(FittedModel):
    """A model given by a batched torch function :meth:`lagrangian`
    ``(q, qd) -> L`` in the dtype :attr:`dtype`; predictions are returned in
    float64."""

    dtype: torch.dtype = torch.float64
    #: where :meth:`lagrangian`'s tensors live (a torch method's network while it trains on a GPU)
    device: torch.device = torch.device("cpu")

    @abc.abstractmethod
    def lagrangian(self, q: torch.Tensor, qd: torch.Tensor) -> torch.Tensor:
        """``L`` for a batch: ``(batch, dof) x 2 -> (batch,)``."""

    def predict_lagrangian(self, data: Dataset) -> np.ndarray:
        t = data.tensors(self.dtype, self.device)
        with torch.no_grad():
            out = torch.cat([self.lagrangian(q, qd) for q, qd in zip(t["q"].split(CHUNK), t["qd"].split(CHUNK))])
        return out.double().cpu().numpy()

    def predict_torque(self, data: Dataset) -> np.ndarray:
        t = data.tensors(self.dtype, self.device)
        tau, _ = euler_lagrange_chunked(self.lagrangian, t["q"], t["qd"], t["qdd"])
        return tau.double().cpu().numpy()


class ExpressionModel(LagrangianFunction):
    """A fitted model given by a sympy Lagrangian in ``q_i, qd_i``."""

    def __init__(self, expr: sympy.Expr, dof: int):
        self.expr, self.dof = expr, dof
        self._fn = symbolic.to_torch(expr, dof)

    def lagrangian(self, q: torch.Tensor, qd: torch.Tensor) -> torch.Tensor:
        return self._fn(q, qd)

    def expression(self) -> sympy.Expr:
        return self.expr


@loader("expression")
def _load_expression(tree: dict, unpacker: Unpacker, context: dict) -> ExpressionModel:
    return ExpressionModel(expression_from_json(tree["expression"], unpacker.source), int(context["dof"]))


class ParametricModel(LagrangianFunction):
    """A system's parametric form (:class:`~bench.physics.system.ParametricForm`)
    at the parameter values ``theta``."""

    def __init__(self, form, theta: Sequence[float]):
        self.form, self.theta = form, np.asarray(theta, dtype=np.float64)
        self._theta = torch.tensor(self.theta, dtype=torch.float64)

    def lagrangian(self, q: torch.Tensor, qd: torch.Tensor) -> torch.Tensor:
        return self.form.torch_fn(q, qd, self._theta)

    def with_parameters(self, theta: Sequence[float]) -> "ParametricModel":
        return ParametricModel(self.form, theta)

    def parameters(self) -> dict[str, float]:
        """The parameter values, by name."""
        return {s.name: float(v) for s, v in zip(self.form.unknowns, self.theta)}

    def predict_torque(self, data: Dataset) -> np.ndarray:
        """``tau``: through the separated form (:func:`separate`) where there is one."""
        sep = separate(self.form)
        if sep is None:
            return super().predict_torque(data)
        return (sep.torque_columns(data) @ sep.coefficients(self.theta)).reshape(len(data), data.dof)

    def predict_lagrangian(self, data: Dataset) -> np.ndarray:
        sep = separate(self.form)
        if sep is None:
            return super().predict_lagrangian(data)
        return sep.value_columns(data) @ sep.coefficients(self.theta)

    def jacobian(self, data: Dataset) -> np.ndarray:
        """``d tau / d theta``, flattened sample-major: exact through the
        separated form (:func:`separate`), else by central differences."""
        sep = separate(self.form)
        if sep is not None:
            return sep.torque_columns(data) @ sep.jacobian(self.theta)
        cols = []
        for i, value in enumerate(self.theta):
            h = 1e-6 * max(1.0, abs(value))
            up, down = self.theta.copy(), self.theta.copy()
            up[i] += h
            down[i] -= h
            diff = self.with_parameters(up).predict_torque(data) - self.with_parameters(down).predict_torque(data)
            cols.append(diff.ravel() / (2 * h))
        return np.stack(cols, axis=1)

    def expression(self) -> sympy.Expr:
        return sympy.expand(self.form.substitute(self.theta.tolist()))

    def parametric(self) -> "ParametricModel":
        return self

    def structure(self) -> str:
        return "parametric"


class Separation:
    """A parametric form's Lagrangian written as ``sum_k c_k(theta) phi_k(q, qd)``.

    Every rigid-body Lagrangian of the suite is linear in functions of its
    unknowns (products of masses, lengths and inertias) times functions of
    the coordinates. Since the Euler–Lagrange transform ``g`` is linear,
    ``tau(theta) = sum_k c_k(theta) g(phi_k)``: the basis's torques are
    computed once per data set (kept while the data set lives), and the
    torque at any ``theta``, and its exact Jacobian ``sum_k dc_k/dtheta
    g(phi_k)``, are matrix products. A nonlinear least-squares fit of the
    parameters, which asks for both at every iteration, then needs no pass
    of automatic differentiation.
    """

    def __init__(self, unknowns, coefficients: list[sympy.Expr], basis: list[sympy.Expr]):
        self.basis = TermLibrary.of_lagrangian(basis)
        self._c = sympy.lambdify([unknowns], coefficients, "numpy")
        self._dc = sympy.lambdify([unknowns], [[sympy.diff(c, u) for u in unknowns] for c in coefficients], "numpy")
        self._torque: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
        self._value: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()

    def coefficients(self, theta) -> np.ndarray:
        return np.array([float(c) for c in self._c(list(theta))])

    def jacobian(self, theta) -> np.ndarray:
        """``dc / dtheta``, shape ``(K, p)``."""
        return np.array([[float(v) for v in row] for row in self._dc(list(theta))])

    def torque_columns(self, data: Dataset) -> np.ndarray:
        """``g(phi_k)`` at the states of ``data``, flattened sample-major: ``(n * dof, K)``."""
        if data not in self._torque:
            self._torque[data] = self.basis.design(data, "indirect")
        return self._torque[data]

    def value_columns(self, data: Dataset) -> np.ndarray:
        """``phi_k`` at the states of ``data``: ``(n, K)``."""
        if data not in self._value:
            self._value[data] = self.basis.design(data, "direct")
        return self._value[data]


@functools.lru_cache(maxsize=64)
def separate(form) -> Separation | None:
    """The form as a :class:`Separation`, or ``None`` where an unknown sits
    inside a function of the coordinates (then the torch function serves)."""
    q, qd = symbolic.coordinate_symbols(form.dof)
    unknowns = set(form.unknowns)
    groups: dict[sympy.Expr, sympy.Expr] = {}
    for term in sympy.Add.make_args(sympy.expand(form.expr)):
        coefficient, phi = term.as_independent(*q, *qd, as_Add=False)
        if phi.free_symbols & unknowns or not coefficient.free_symbols <= unknowns:
            return None
        groups[phi] = groups.get(phi, sympy.Integer(0)) + coefficient
    return Separation(form.unknowns, list(groups.values()), list(groups))


def term_to_json(term) -> dict:
    """A :class:`~bench.physics.terms.Term` as JSON (its expression by :func:`~bench.core.expressions.expression_to_json`)."""
    return {"expr": expression_to_json(term.expr), "place": term.place, "name": term.name, "joint": term.joint,
            "shape": term.shape}


def term_from_json(obj: dict, source: str):
    """The :class:`~bench.physics.terms.Term` of :func:`term_to_json`."""
    joint, shape = obj.get("joint"), obj.get("shape")
    return Term(expression_from_json(obj["expr"], source), str(obj["place"]), str(obj.get("name", "")),
                None if joint is None else int(joint), None if shape is None else float(shape))


def unit_accelerations(q: np.ndarray, qd: np.ndarray) -> Dataset:
    """Each state ``(q, qd)`` at ``qdd = 0`` and at each unit acceleration ``e_j``: ``dof + 1`` rows a
    state, in that order, whose torques :func:`affine_parts` takes ``M`` and ``c`` from."""
    n, dof = q.shape
    qdd = np.concatenate([np.zeros((1, dof)), np.eye(dof)])  # (dof + 1, dof)
    return Dataset(np.repeat(q, dof + 1, axis=0), np.repeat(qd, dof + 1, axis=0), np.tile(qdd, (n, 1)),
                   np.zeros((n * (dof + 1), dof)))


def affine_parts(tau: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``M`` ``(n, dof, dof)`` and ``c`` ``(n, dof)`` from torques at :func:`unit_accelerations`' rows of ``n``
    states: ``c`` is a state's torque at ``qdd = 0``, and column ``j`` of ``M`` its torque at ``e_j`` less ``c``."""
    tau = np.asarray(tau, dtype=np.float64)
    tau = tau.reshape(n, -1, tau.shape[-1])
    c = tau[:, 0]
    return np.transpose(tau[:, 1:] - c[:, None, :], (0, 2, 1)), c


def mass_and_bias(model: FittedModel, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``model``'s :meth:`~FittedModel.mass_and_bias` at the states ``(q, qd)``."""
    return model.mass_and_bias(q, qd)
