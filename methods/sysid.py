"""Parametric system identification (SysId), as in the paper.

The model is the system's own symbolic Lagrangian with its physical
parameters unknown (for the double pendulum m1, l1, m2, l2; g is known).
Following Valle & Haddadin (2021), Section IV, the unknowns are the outputs
of a small network whose input is a constant vector of ones: one hidden layer
of 64 softplus units without bias and a linear output layer with one unit per
unknown. It is trained with Adam at a constant learning rate of 1e-3, in
mini-batches of 32, keeping the best state.

Choices the paper leaves open
-----------------------------
* The constant input has one element.
* The output layer keeps its bias.
* The parametric form comes from the system (:meth:`bench.physics.system.System.parametric_form`),
  so any registered system that declares one can be identified.

Systems linear in their parameters (robot arms)
-----------------------------------------------
A system given by an engine (an arm from its URDF) has no symbolic form but
a :class:`~bench.physics.system.LinearForm`: ``tau = Y pi``, linear in each
link's 10 inertial parameters. There SysId does what the field does instead
of the paper's network (whose optimum this is, reached in one step): it
stacks the regressor over up to ``linear_samples`` training samples, finds
the base parameters, the identifiable combinations, by QR with column
pivoting (:func:`bench.physics.regression.base_columns`), and fits them by
least squares. The record gives the base parameters' relative error against
the true ones (from the URDF's parameters) and whether the identified mass
matrix is positive definite at the training states (up to :data:`MASS_STATES` of them, evenly spread; and at how many it is not).

By default (``feasible=True``) the arm's parameters are then identified
under the constraint that each link's pseudo-inertia is positive
semidefinite (Wensing, Kim & Slotine 2017; :func:`bench.physics.feasible.feasible_fit`),
which is least squares' optimum wherever that is a rigid body's. On the
generated Panda this cost about 0.9 s more per fit and was never worse on
held-out data (results/arms/README.md); with 5 % torque noise least
squares' parameters were no rigid body's. The record's ``feasibility``
gives, for both fits, the masses and each link's smallest pseudo-inertia
eigenvalue, and for the feasible one its distance to the least-squares
optimum.

The standard model (``--config sysid=standard``)
------------------------------------------------
The field's standard identified model of an arm, which every measured-arm
table reads its learners against: the rigid-body base parameters plus, on
each joint ``j``, Coulomb and viscous friction, the rotor's inertia
(armature) and a torque offset::

    tau_j = Y_j(q, qd, qdd) pi + F_c_j sign(qd_j) + b_j qd_j + I_a_j qdd_j + tau_0_j

by ordinary least squares (``friction=True, drive=True, feasible=False``;
the Coulomb column uses the data's filtered velocity sign where they carry
it, :meth:`~bench.core.data.Dataset.velocity_sign`). This is the model of
Khalil & Dombre, *Modeling, Identification and Control of Robots* (2002),
in its chapters on the dynamic model (friction and the rotors' inertia) and
on identifying its parameters (the offset), whose base parameters Gautier
(1990), "Numerical calculation of the base inertial parameters of robots",
finds by QR as here; see also Swevers, Verdonck & De Schutter, "Dynamic model
identification for industrial robots", IEEE Control Systems 27(5), 2007.
The base-parameter reduction (:func:`~bench.physics.regression.base_columns`)
drops the joint columns the data do not identify apart from the others
(the first joint's rotor inertia acts as the first link's ``ZZ`` does);
the record names them (``dropped_joint_columns``), and names the joint
columns whose standard error exceeds their value
(``joint_columns_not_significant``), each a finding rather than a parameter.
On an arm whose torque is measured at the joint, behind the gear, the rotor's
inertia is not in the torque: what its column takes there is something else
the model lacks. ``friction=True`` alone gives friction without the drive's
columns.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Annotated

import numpy as np
import sympy
import torch

from bench.core.experiment import Experiment
from bench.core.data import Dataset
from bench.core.errors import DataError
from bench.physics.effects import EFFECTS
from bench.physics.linear import FeasibleSet, LinearParametricModel, lagrangian_regressor, torque_regressor
from bench.physics.models import ParametricModel, mass_and_bias
from bench.physics.feasible import Feasibility, feasible_fit, nearest_completion
from bench.physics.regression import Compressed, base_columns, fit_statistics, least_squares
from bench.physics.system import LinearForm
from methods.base import METHODS
from methods.config import Named, Range
from methods.torch_method import TorchConfig, TorchLagrangianMethod


@dataclass(frozen=True)
class SysIdConfig(TorchConfig):
    """Attributes: ``hidden`` softplus units of the parameter network;
    ``linear_samples`` training samples a linear form is fitted on;
    ``feasible``: a rigid-body form's parameters identified with each body's
    pseudo-inertia positive semidefinite, the directions the data do not
    identify pulled toward the form's prior (the URDF) with weight
    ``regularisation`` (:mod:`bench.physics.feasible`); ``False`` gives the
    base parameters by least squares. ``friction``: a linear form fitted
    with Coulomb and viscous friction on each joint; ``drive``: with each
    joint's rotor inertia and a torque offset (:func:`with_joint_terms`)."""

    hidden: Annotated[int, Range(1)] = 64
    linear_samples: Annotated[int, Range(1)] = 8192
    feasible: bool = True
    regularisation: Annotated[float, Range(0)] = 1e-6
    friction: bool = False
    drive: bool = False


#: the further columns of each joint, in the suite's effects' terms: with friction, then with the drive
FRICTION_COLUMNS = (("viscous_friction", "b"), ("coulomb_friction", "F_c"))
DRIVE_COLUMNS = (("armature", "I_a"), ("offset", "tau_0"))


def joint_columns(friction: bool = True, drive: bool = False) -> tuple[tuple[str, str], ...]:
    """The further columns of each joint, ``(effect, symbol)``: :data:`FRICTION_COLUMNS` with ``friction``, then
    :data:`DRIVE_COLUMNS` with ``drive``."""
    return (FRICTION_COLUMNS if friction else ()) + (DRIVE_COLUMNS if drive else ())


def with_joint_terms(form: LinearForm, friction: bool = True, drive: bool = False) -> LinearForm:
    """``form`` with further columns on each joint (:func:`joint_columns`): viscous and Coulomb friction
    (``b_j``, ``F_c_j``) with ``friction``, the rotor's inertia and a torque offset (``I_a_j``, ``tau_0_j``) with
    ``drive``."""
    kinds = joint_columns(friction, drive)
    terms, names = [], []
    for j in range(form.dof):
        for effect, symbol in kinds:
            terms.append(EFFECTS[effect].term(j))
            names.append(f"{symbol}_{j + 1}")
    return form.with_terms(terms, names) if terms else form


def _joint_column_facts(form: LinearForm, W: np.ndarray, y: np.ndarray, independent: np.ndarray,
                        dependent: np.ndarray, coef: np.ndarray) -> dict:
    """The record's facts on ``form``'s further columns in a least-squares fit: those the base-parameter reduction
    dropped (``dropped_joint_columns``), and those kept whose standard error exceeds their value
    (``joint_columns_not_significant``), each by name."""
    first = len(form.names) - len(form.terms)
    if not form.terms:
        return {}
    dropped = [form.names[j] for j in sorted(dependent) if first <= j < len(form.names)]
    _, stderr, _ = fit_statistics(W[:, independent], y)
    weak = [form.names[j] for i, j in enumerate(independent)
            if first <= j < len(form.names) and not stderr[i] < abs(coef[i])]
    return {"dropped_joint_columns": dropped, "joint_columns_not_significant": weak}


def fit_linear_form(form: LinearForm, data: Dataset, experiment: str, feasible: bool = False,
                    regularisation: float = 1e-6) -> tuple[LinearParametricModel, dict]:
    """The base parameters of ``form`` fitted on ``data`` by least squares,
    and facts for the record: how many there are and, where the true
    parameters are known, their relative error.

    With ``feasible`` (a form of rigid bodies with a prior), every
    parameter instead, each body's pseudo-inertia held positive
    semidefinite (:func:`bench.physics.feasible.feasible_fit`), and the
    coefficient of each further term whose effect is nonnegative (a joint's
    friction, :attr:`~bench.physics.effects.Effect.nonnegative`) at 0 or
    above. Either way the
    facts say whether the identified set is a rigid body's (``feasibility``):
    the least-squares base parameters are judged by the full set nearest
    the prior with their torques (:func:`~bench.physics.feasible.nearest_completion`)."""
    experiment = Experiment.of(experiment)
    if not experiment.learns_torque:
        W = np.column_stack([lagrangian_regressor(form, data), np.ones(len(data))])  # L up to a constant
        y = data.target(experiment)
    else:
        W = torque_regressor(form, data).reshape(len(data) * data.dof, -1)
        y = data.tau.ravel()
    start = time.perf_counter()
    independent, dependent, beta = base_columns(W)
    coef = least_squares(W[:, independent], y)
    ls_seconds = time.perf_counter() - start
    constant = len(form.names)  # the direct experiment's constant column, not a parameter
    keep = independent != constant
    offset = float(coef[~keep][0]) if (~keep).any() else 0.0
    names = [form.names[j] + ("+" if np.any(beta[i] != 0) else "") for i, j in enumerate(independent) if j != constant]
    model = LinearParametricModel(form, independent[keep], coef[keep], names, offset)
    facts = {"base_parameters": int(keep.sum()), "regressor_columns": len(form.names)}
    if experiment.learns_torque:
        facts.update(_joint_column_facts(form, W, y, independent, dependent, coef))
    if form.true_values is not None:
        true = np.asarray(form.true_values + (0.0,))  # the constant's true value is unknown: 0 is not used below
        base_true = (true[independent] + beta @ true[dependent])[keep]
        facts["parameter_error"] = float(np.linalg.norm(model.coef - base_true) / np.linalg.norm(base_true))
    if form.bodies and form.prior is not None and experiment.learns_torque:
        prior = form.full_prior()
        start = time.perf_counter()
        problem = Compressed(W, y)  # one QR of the regressor: the completion and the feasible fit use its factor
        ls_full = nearest_completion(problem.R[:, : problem.columns], independent, coef, prior)
        report = {"least_squares": {**Feasibility.of(ls_full, form.bodies).as_dict(), "seconds": round(ls_seconds, 3)}}
        if feasible:
            first = len(form.names) - len(form.terms)  # the further terms' first column
            nonnegative = tuple(first + i for i, t in enumerate(form.terms)
                                if t.name in EFFECTS and EFFECTS[t.name].nonnegative)
            full, solve = feasible_fit(problem, form.bodies, np.asarray(form.prior), regularisation, nonnegative)
            base = full[independent] + beta @ full[dependent]
            model = LinearParametricModel(form, np.arange(len(form.names)), full, form.names,
                                          feasible=FeasibleSet(form.bodies, form.prior, regularisation, nonnegative))
            report["feasible"] = {
                **Feasibility.of(full, form.bodies).as_dict(), **solve,
                "seconds": round(time.perf_counter() - start, 3),
                "distance_to_least_squares": float(np.linalg.norm(base - coef) / np.linalg.norm(coef)),
                "training_error_ratio": problem.residual_norm2(full) / max(problem.residual_norm2(ls_full), 1e-300),
            }
            if form.true_values is not None:
                facts["parameter_error"] = float(np.linalg.norm(base[keep] - base_true) / np.linalg.norm(base_true))
        facts["feasibility"] = report
    return model, facts


class ParameterNetwork(torch.nn.Module):
    """ones -> Linear(no bias) -> softplus -> Linear -> theta; then L(q, qd; theta)."""

    def __init__(self, form, hidden: int):
        super().__init__()
        self.form = form
        self.register_buffer("ones", torch.ones(1))
        self.hidden = torch.nn.Linear(1, hidden, bias=False)
        self.out = torch.nn.Linear(hidden, len(form.unknowns))

    def theta(self) -> torch.Tensor:
        return self.out(torch.nn.functional.softplus(self.hidden(self.ones)))

    def forward(self, q: torch.Tensor, qd: torch.Tensor) -> torch.Tensor:
        return self.form.torch_fn(q, qd, self.theta())


#: training states whose mass matrices are computed at once (:meth:`SysId._post_fit`)
MASS_CHUNK = 512
#: at most this many training states, evenly spread, are checked for a positive definite mass matrix (all of the
#: KUKA's 4,926; 8,192 of a long log's 70,000, where checking every one took 14 of a fit's 18 s)
MASS_STATES = 8192


def _smallest_eigenvalues(model, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """The smallest eigenvalue of ``model``'s mass matrix at each state."""
    M, _ = mass_and_bias(model, q, qd)
    return np.linalg.eigvalsh(0.5 * (M + np.transpose(M, (0, 2, 1))))[:, 0]


@METHODS.add("sysid", "symbolic", "parametric", "baseline", "paper")
class SysId(TorchLagrangianMethod):
    title = "SysId"
    #: what the method is, for docs/methods_and_systems.md (generated from the registry)
    summary = ("the system's symbolic Lagrangian with unknown physical parameters, produced by a small network "
               "from a constant input (paper §IV); on an arm, the field's standard: the base parameters of the "
               "regressor linear in each link's 10 inertial parameters, found by QR with column pivoting and "
               "fitted by least squares, with their error against the URDF's; `feasible=true` identifies every "
               "inertial parameter with each link's pseudo-inertia held positive semidefinite (Wensing, Kim & "
               "Slotine 2017), by a semidefinite program in cvxpy, the directions the data do not identify held "
               "at the URDF's values")
    Config = SysIdConfig
    search_space = {"feasible": (True, False), "friction": (False, True)}
    work = 1  # one solve
    smoke = {"max_steps": 20, "eval_samples": 256}
    stackable = False  # an arm's linear form is solved, not trained; one seed's solve is the work
    configurations = {
        "standard": Named("the field's standard identified model of an arm: rigid-body base parameters plus Coulomb "
                          "and viscous friction, rotor inertia and a torque offset on each joint, by least squares "
                          "(Khalil & Dombre 2002)", {"feasible": False, "friction": True, "drive": True}),
        "feasible": Named("a physically feasible model of an arm: rigid bodies whose pseudo-inertias are positive "
                          "semidefinite, Coulomb and viscous friction and rotor inertia on each joint held at 0 or "
                          "above, and a torque offset on each joint", {"feasible": True, "friction": True, "drive": True}),
    }
    linear: LinearParametricModel | None = None

    def _fit(self, train, experiment, progress):
        form = self.system.linear_form() if self.system is not None else None
        joints = self.config.friction or self.config.drive
        what = " and ".join(w for w, on in (("friction", self.config.friction), ("drive", self.config.drive)) if on)
        if form is not None and joints:
            if not experiment.learns_torque:
                raise DataError(f"sysid's {what} columns act on torques: the direct experiment (samples of L) has none")
            form = with_joint_terms(form, self.config.friction, self.config.drive)
        if form is None and joints:
            raise DataError(f"sysid's {what} columns extend an arm's linear form; {train.system} has a symbolic "
                            f"form instead (leave {what} off, or let the residual loop find them)")
        if form is None:
            self.linear = None
            return super()._fit(train, experiment, progress)
        rng = np.random.default_rng(self.seed)
        sub = train.subset(np.sort(rng.choice(len(train), min(len(train), self.config.linear_samples), replace=False)))
        self.linear, self._facts = fit_linear_form(form, sub, experiment, self.config.feasible,
                                                   self.config.regularisation)
        while progress.step():
            progress.stop("solved")

    def trained_on(self) -> str:
        """The CPU where the fit solved an arm's linear form; its device where it trained the network."""
        return "cpu" if self.linear is not None else super().trained_on()

    def _get_state(self):
        return self.linear if self.linear is not None else super()._get_state()

    def _set_state(self, state):
        if isinstance(state, LinearParametricModel):
            self.linear = state
        else:
            super()._set_state(state)

    def _post_fit(self, train, experiment, seconds_left):
        super()._post_fit(train, experiment, seconds_left)  # a network's fit: on the CPU, in float64
        if self.linear is not None:  # the states whose mass matrices the record's facts check (record_details)
            rows = train.evenly(MASS_STATES)
            self._mass_states = (train.q[rows], train.qd[rows])

    def _mass_matrix_facts(self) -> dict:
        """The consistency the data can decide: whether the mass matrix is positive definite at the training
        states kept by the fit. Computed when the record asks for it, once: a fold fit of a tuned run or a
        hybrid's prior never reports it."""
        states = getattr(self, "_mass_states", None)
        if states is None or "mass_matrix_states" in getattr(self, "_facts", {}):
            return {}
        q, qd = states
        smallest = np.concatenate([_smallest_eigenvalues(self.linear, q[k:k + MASS_CHUNK], qd[k:k + MASS_CHUNK])
                                   for k in range(0, len(q), MASS_CHUNK)])
        return {"mass_matrix_positive_definite": bool(np.all(smallest > 0)),
                "mass_matrix_smallest_eigenvalue": float(smallest.min()),
                "mass_matrix_states": len(smallest),  # the training states checked
                "mass_matrix_indefinite_states": int(np.sum(~(smallest > 0)))}

    def saved(self, packer):
        """The linear model (:meth:`~bench.physics.linear.LinearParametricModel.saved`), or the parameter network."""
        return self.linear.saved(packer) if self.linear is not None else super().saved(packer)

    def predict_lagrangian(self, data):
        return self.linear.predict_lagrangian(data) if self.linear is not None else super().predict_lagrangian(data)

    def predict_torque(self, data):
        return self.linear.predict_torque(data) if self.linear is not None else super().predict_torque(data)

    def mass_and_bias(self, q, qd):
        return self.linear.mass_and_bias(q, qd) if self.linear is not None else super().mass_and_bias(q, qd)

    def record_details(self):
        if self.linear is None:
            return {}
        self._facts = {**getattr(self, "_facts", {}), **self._mass_matrix_facts()}
        return dict(self._facts)

    def build_model(self, train):
        if self.system is None:
            raise DataError(f"{train.source}: sysid needs to know the data's system (got none) for its parametric form")
        self.form = self.system.parametric_form()
        return ParameterNetwork(self.form, self.config.hidden)

    def parametric(self) -> ParametricModel | LinearParametricModel:
        """The form at the identified parameter values."""
        if self.linear is not None:
            return self.linear
        with torch.no_grad():
            return ParametricModel(self.form, self.model.theta().double().tolist())

    def identified_parameters(self) -> dict[str, float]:
        """The identified parameter values, by name."""
        return self.parametric().parameters()

    def expression(self) -> sympy.Expr | None:
        return None if self.linear is not None else self.parametric().expression()
