r"""The laws that act between the arm's torque and the measured one, one class
each, registered in the suite's one registry of laws (:data:`bench.physics.laws.LAWS`, its
:attr:`~bench.physics.laws.Laws.sensor` laws).

A law either moves the states at which a torque was measured (a *state
law*: the time shift) or multiplies the arm's torque on a joint by a factor
(a *torque law*: a sensor's gain, a drive's load-dependent friction),
``tau_measured_j = tau_j F_j(data)``. An instance is the law at its value on
one joint (or on every joint, where :attr:`SensorLaw.per_joint` is false);
:class:`bench.residual.sensors.Sensor` holds the instances found and
:mod:`bench.residual.sensors` runs the loop over them.

Each law gives the residual loop:

* its *column*, the measured torque's derivative in the law's coefficient,
  linearised at the model where it stands (:meth:`SensorLaw.column`); for a
  torque law ``tau_hat_j d ln F_j / d theta``;
* its *update* from a fitted coefficient (:meth:`SensorLaw.updated`) and how
  large that step is (:meth:`SensorLaw.change`);
* the values it may take (:attr:`SensorLaw.bounds`), its law in words
  (:meth:`SensorLaw.law_text`) and its JSON entry (:meth:`SensorLaw.entry`).

A new law is one subclass (of :class:`JointTorqueLaw` for a factor on one
joint's torque) and :func:`register`; the loop offers it wherever
:meth:`SensorLaw.offered` says, settles it, checks its range and asks it to
earn its place on held-out trajectories as it does the others.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
import sympy

from bench.core.data import Dataset
from bench.physics.effects import EFFECTS, Effect, register_effect
from bench.physics.laws import LAWS
from bench.physics.regression import fit_statistics
from bench.physics.terms import Term

#: why the reference joint is the one it is, in the loop's JSON
WHY_REFERENCE = ("a gain common to every joint rescales L and no torque data identify it, so one joint's gain is "
                 "fixed at 1: the joint with the largest torque RMS on the training data, whose ratios to the others "
                 "are the best conditioned")


def has_time(data: Dataset) -> bool:
    """Whether ``data`` hold recordings with time stamps, where a time shift can be seen."""
    return data.time is not None and data.recording is not None


@dataclass(frozen=True)
class SensorLaw:
    """One law of the sensor or the drive at its value on :attr:`joint`
    (``None``: every joint), with the value's standard error."""

    joint: int | None
    value: float
    stderr: float = 0.0

    #: the law's name, in the JSON and in :class:`~bench.physics.terms.Term`
    name: ClassVar[str] = ""
    #: ``"sensor"`` or ``"drive"``: the JSON's word for where it acts
    kind: ClassVar[str] = "sensor"
    #: the parameter's symbol
    parameter: ClassVar[str] = "c"
    #: the value at which the law does nothing
    neutral: ClassVar[float] = 0.0
    #: the values that are physical, ``(low, high)``; ``None``: any
    bounds: ClassVar[tuple[float, float] | None] = None
    #: one instance per joint, or one for every joint
    per_joint: ClassVar[bool] = True
    #: the law as an effect (place ``sensor``: its term per unit coefficient), where it has one: :func:`register`
    #: puts it into :data:`~bench.physics.effects.EFFECTS` beside the arm's, where the loop's library and the
    #: loop's reports look a law up by name; a law is declared once, here
    effect: ClassVar[Effect | None] = None

    @classmethod
    def start(cls, joint: int | None) -> "SensorLaw":
        """The law on ``joint`` at its neutral value."""
        return cls(joint, cls.neutral)

    @classmethod
    def offered(cls, train: Dataset, reference: int) -> list[int | None]:
        """Where the loop may look for the law on ``train``: the joints (or
        ``[None]`` for a law of every joint; ``[]`` where ``train`` cannot show it)."""
        return list(range(train.dof)) if cls.per_joint else [None]

    @classmethod
    def expression(cls, joint: int | None, dof: int) -> sympy.Expr:
        """The law's expression in the measured torque's symbols ``tau_i``."""
        joints = [joint] if joint is not None else range(dof)
        return sympy.Add(*[sympy.Symbol(f"tau_{j + 1}", real=True) for j in joints])

    @classmethod
    def term(cls, joint: int | None, dof: int) -> Term:
        """The law on ``joint`` as a term of the loop's library (place ``sensor``): its :attr:`effect`'s, else one of
        :meth:`expression`."""
        if cls.effect is not None and cls.effect.expr is not None:
            return cls.effect.term(joint)
        return Term(cls.expression(joint, dof), "sensor", cls.name, joint)

    @classmethod
    def law_text(cls, term: Term, parameter: str) -> str:
        """The law in words with ``parameter``."""
        j = term.joint + 1
        return f"tau_measured_{j} = (1 + {parameter}*f(q, qd, tau))*tau_{j}"

    @classmethod
    def value_of(cls, coefficient: float) -> float:
        """The value a first fitted coefficient (from the neutral value) gives."""
        return cls.neutral + coefficient

    @classmethod
    def admissible_value(cls, value: float) -> bool:
        """Whether ``value`` is physical (:attr:`bounds`)."""
        return cls.bounds is None or cls.bounds[0] <= value <= cls.bounds[1]

    @classmethod
    def generable(cls, value: float) -> bool:
        """Whether the data generator may apply the law at ``value``: by default
        a value the law admits (:meth:`admissible_value`)."""
        return cls.admissible_value(value)

    @classmethod
    def generable_condition(cls) -> str:
        """What :meth:`generable` asks, in words."""
        return cls.condition() or "any value"

    @classmethod
    def condition(cls) -> str:
        """What :meth:`admissible_value` asks, in words."""
        return "" if cls.bounds is None else f"{cls.bounds[0]:g} <= {cls.parameter} <= {cls.bounds[1]:g}"

    def admissible(self) -> bool:
        return self.admissible_value(self.value)

    def as_term(self, dof: int) -> Term:
        return self.term(self.joint, dof)

    # what the law does to data
    def states(self, data: Dataset) -> Dataset:
        """``data`` with the states at which the measured torques were the arm's (a state law's)."""
        return data

    def factor(self, data: Dataset) -> np.ndarray | None:
        """``(n, dof)``: what the arm's torques are multiplied by to read as
        measured ones, on ``data`` (whose torques give any sign the law
        needs); ``None`` for a state law."""
        return None

    def column(self, tau_hat: np.ndarray, data: Dataset) -> np.ndarray:
        """``(n, dof)``: the law's column linearised at the model's torques
        ``tau_hat`` on the corrected ``data``; its coefficient is the change
        :meth:`updated` takes."""
        raise NotImplementedError

    def updated(self, coefficient: float, stderr: float) -> "SensorLaw":
        """The law after a fitted change ``coefficient`` (standard error ``stderr``)."""
        return dataclasses.replace(self, value=self.value + coefficient, stderr=stderr)

    def change(self, coefficient: float, step: float) -> float:
        """How large a step ``coefficient`` is, against the loop's tolerance
        (``step``: the data's median sample step in seconds)."""
        return abs(coefficient)

    def settled(self, strategy, model, train: Dataset) -> "SensorLaw":
        """The law once the loop has settled it at ``model`` (a hook for what it reports beside its value)."""
        return self

    def entry(self, dof: int, reference: int) -> dict:
        """The JSON entry of the law found."""
        joints = [self.joint + 1] if self.joint is not None else list(range(1, dof + 1))
        out = {"name": self.name, "kind": self.kind, "law": self.law_text(self.as_term(dof), self.parameter),
               "joints": joints}
        if self.joint is not None:
            out["joint"] = self.joint + 1
        out["parameters"] = {self.parameter: {"value": float(self.value), "stderr": float(self.stderr)}}
        return out


class JointTorqueLaw(SensorLaw):
    """A torque law of one joint: ``tau_measured_j = F_j(data) tau_j``, the
    other joints' torques as they are. A subclass gives the factor on its
    joint (:meth:`joint_factor`) and its column there (:meth:`joint_column`,
    ``tau_hat_j d ln F_j / d theta``); this class spreads both over the joints."""

    def joint_factor(self, data: Dataset) -> np.ndarray | float:
        """``F_j`` on :attr:`joint`, per sample of ``data`` (or one for all)."""
        raise NotImplementedError

    def joint_column(self, tau_hat: np.ndarray, data: Dataset) -> np.ndarray:
        """The column on :attr:`joint` at the model's torques ``tau_hat`` there (``(n,)``)."""
        raise NotImplementedError

    def factor(self, data):
        out = np.ones_like(data.q)
        out[:, self.joint] = self.joint_factor(data)
        return out

    def column(self, tau_hat, data):
        out = np.zeros_like(tau_hat)
        out[:, self.joint] = self.joint_column(tau_hat[:, self.joint], data)
        return out


class TorqueGain(JointTorqueLaw):
    """``tau_measured_j = g_j tau_j``: a calibration error of joint ``j``'s
    torque sensor, relative to the reference joint (whose gain is fixed at 1:
    a gain common to every joint is a rescaling of ``L``). Its coefficient is
    the gain's relative change, ``g <- g (1 + c)``."""

    # the coefficient is the gain's change, g <- g (1 + c): a gain between 0.8 and 1.25 is a calibration error
    # (a torque sensor's is a few percent); a residual that asks for more is something else the model lacks,
    # and a finding
    effect = Effect("torque_gain", lambda q, qd: sympy.Symbol("tau" + str(q[0])[1:], real=True), "sensor", "g",
                    "tau_measured = g·tau", nonnegative=False, bounds=(-0.2, 0.25))
    name, kind, parameter, neutral = effect.name, "sensor", effect.parameter, 1.0
    bounds = tuple(1.0 + b for b in effect.bounds)

    @classmethod
    def offered(cls, train, reference):
        return [j for j in range(train.dof) if j != reference]

    @classmethod
    def generable(cls, value):
        """Any positive gain: data whose gain lies outside the range the loop admits test that it says so."""
        return value > 0

    @classmethod
    def generable_condition(cls):
        return f"{cls.parameter} > 0"

    @classmethod
    def law_text(cls, term, parameter):
        return f"tau_measured_{term.joint + 1} = {parameter}*tau_{term.joint + 1}"

    def joint_factor(self, data):
        return self.value

    def joint_column(self, tau_hat, data):
        return tau_hat

    def updated(self, coefficient, stderr):
        value = self.value * (1.0 + coefficient)
        return dataclasses.replace(self, value=value, stderr=value * stderr)

    def entry(self, dof, reference):
        return super().entry(dof, reference) | {"reference_joint": reference + 1, "reference": WHY_REFERENCE}


class LoadFriction(JointTorqueLaw):
    """``tau_measured_j = tau_j + mu_j |tau_j| s_j``, ``s_j`` the sign of
    ``qd_j`` (the data's, :meth:`~bench.core.data.Dataset.velocity_sign`): a
    Coulomb level that grows with the load torque the drive carries; its
    factor is ``1 + mu_j sigma_j``, ``sigma_j = sign(tau_j) s_j`` (+1 where
    the drive moves the load, -1 where the load drives it back), which needs
    only the torque's sign, the same measured or the arm's while ``mu < 1``."""

    effect = Effect("load_friction", lambda q, qd: sympy.Abs(sympy.Symbol("tau" + str(q[0])[1:], real=True))
                    * sympy.sign(qd[0]), "sensor", "mu", "tau_measured = tau + mu·|tau|·sign(qd)", bounds=(0.0, 0.5))
    name, kind, parameter, neutral, bounds = effect.name, "drive", effect.parameter, 0.0, effect.bounds

    @classmethod
    def law_text(cls, term, parameter):
        j = term.joint + 1
        return f"tau_measured_{j} = tau_{j} + {parameter}*|tau_{j}|*sign(qd_{j})"

    def joint_factor(self, data):
        j = self.joint
        return 1.0 + self.value * np.sign(data.tau[:, j]) * data.velocity_sign()[:, j]

    def joint_column(self, tau_hat, data):
        return np.abs(tau_hat) * data.velocity_sign()[:, self.joint] / self.joint_factor(data)


def shifted(data: Dataset, delta: float) -> Dataset:
    """``data`` with each recording's states (``q, qd, qdd`` and the filtered
    velocity sign, where the data carry one) taken at ``t - delta``, linearly
    interpolated along the recording (held at its ends); the torques stay."""
    if not delta or not has_time(data):
        return data
    q, qd, qdd = data.q.copy(), data.qd.copy(), data.qdd.copy()
    sign = None if data.sign_qd is None else data.sign_qd.astype(np.float64).copy()
    for index in data.in_time_order():
        t = data.time[index]
        for array in (q, qd, qdd) + ((sign,) if sign is not None else ()):
            source = array[index].copy()
            for j in range(data.dof):
                array[index, j] = np.interp(t - delta, t, source[:, j])
    return data.replace(q=q, qd=qd, qdd=qdd, sign_qd=sign)  # a filtered sign is a smooth signal too


def time_derivative(data: Dataset, values: np.ndarray) -> np.ndarray:
    """``d values / dt`` along each recording (``np.gradient`` over its time stamps)."""
    out = np.zeros_like(values)
    for index in data.in_time_order():
        if len(index) >= 2:
            out[index] = np.gradient(values[index], data.time[index], axis=0)
    return out


@dataclass(frozen=True)
class TimeShift(SensorLaw):
    """``tau_measured(t) = tau(t - delta)``: a sensor's or a filter's delay
    between the torque and the recorded state, one for every joint and
    recording, so that it carries over to the test recordings. It needs time
    stamps and recordings; each training recording's own estimate of it is
    reported beside it (:attr:`per_recording`), so that a recording whose
    delay differs shows."""

    #: each training recording's own estimate, ``{recording: (value, stderr)}``
    per_recording: dict | None = field(default=None, compare=False)

    effect = Effect("time_shift", None, "sensor", "delta", "tau_measured(t) = tau(t − delta)", arity=0,
                    nonnegative=False)
    name, kind, parameter, neutral, bounds, per_joint = effect.name, "sensor", effect.parameter, 0.0, None, False

    @classmethod
    def offered(cls, train, reference):
        return [None] if has_time(train) else []

    @classmethod
    def law_text(cls, term, parameter):
        return f"tau_measured(t) = tau(t - {parameter})"

    def states(self, data):
        return shifted(data, self.value)

    def column(self, tau_hat, data):
        return -time_derivative(data, tau_hat)

    def change(self, coefficient, step):
        return abs(coefficient) / step

    def settled(self, strategy, model, train):
        """Each recording's own estimate of what is left of the shift, added
        to it: the shift's column on that recording's rows only, fitted beside the model."""
        target, F = strategy.problem(model, train)
        full = self.column(np.asarray(model.predict_torque(train), dtype=np.float64), train).ravel()
        rows = np.repeat(train.recording, train.dof)
        out = {}
        for name in train.recordings():
            G = np.where(rows == name, full, 0.0)[:, None]
            coef, stderr, _ = fit_statistics(np.hstack([F, G]), target.ravel())
            out[str(name)] = (self.value + float(coef[-1]), float(stderr[-1]))
        return dataclasses.replace(self, per_recording=out)

    def entry(self, dof, reference):
        return super().entry(dof, reference) | {
            "per_recording": {k: {"value": v, "stderr": e} for k, (v, e) in (self.per_recording or {}).items()}}


def register(law: type[SensorLaw]) -> type[SensorLaw]:
    """Add ``law`` to the one registry of laws, :data:`bench.physics.laws.LAWS`
    (usable as a class decorator), and its :attr:`~SensorLaw.effect`, where it
    has one, to :data:`~bench.physics.effects.EFFECTS`: the built-in laws and
    a plugin's are declared the same way, as one class each. A name another
    law or an arm's effect has taken is refused (the same class imported
    again, as a plugin file may be, takes its place)."""
    if not isinstance(law, type) or not issubclass(law, SensorLaw) or \
            law.name in EFFECTS and EFFECTS[law.name].place != "sensor":
        raise ValueError(f"a law of the sensor or the drive needs a name of its own, got {getattr(law, 'name', law)!r}")
    effect = law.effect
    if effect is not None and (effect.name != law.name or effect.place != "sensor"):
        raise ValueError(f"{law.name}: a sensor law's effect has its name and the place 'sensor', got "
                         f"{effect.name!r} at {effect.place!r}")
    registered = LAWS.register(law)
    if effect is not None:
        EFFECTS.pop(law.name, None)  # the same class imported again brings an effect of its own
        register_effect(effect)
    return registered


for _law in (TorqueGain, LoadFriction, TimeShift):  # in the order the loop offers them
    register(_law)

#: the gains a torque sensor's calibration error may have, ``(low, high)``
GAIN_RANGE = TorqueGain.bounds


def law_of(term: Term) -> type[SensorLaw]:
    """The class of the law ``term`` (place ``sensor``) stands for."""
    return LAWS.sensor[term.name]
