r"""The residual loop's handling of the laws between the arm's torque and
the measured one (:mod:`bench.physics.sensor_laws`: a sensor's gain, a time
shift between torque and state, a drive's load-dependent friction, and any
law registered there), which act on the measured torque rather than on the
arm's Lagrangian.

The gains are relative. Multiplying every joint's torque by one factor is a
rescaling of ``L``, which no torque data can tell from the arm's own
parameters (a gauge), so one joint's gain is fixed at 1: the *reference*,
the joint whose measured torque has the largest root mean square on the
training data (:meth:`Sensor.exact`). Its torque is the best measured
against the noise, so the ratios the other gains are stand on the
best-conditioned footing; a user who knows which sensor is calibrated reads
the others as ratios to it.

Each law is bilinear in the model and the law (``g_j`` times the model's
torque), so each is judged like any term
(:func:`bench.residual.tracing.trace`) by its column linearised at the
model where it stands (:func:`column`). An accepted law is then applied
exactly (:func:`settle`): the model is refitted on the corrected training
data (:meth:`Sensor.correct`: each recording's states taken where the state
laws put them, each torque divided by the torque laws' factors), the
linearised columns fitted again beside the model's freedom, and the laws
updated, until their correction is below :data:`TOLERANCE` (a fixed point:
Gauss–Newton on the laws' parameters). The loop predicts a measured torque
through the laws (:class:`Sensed`) and compares rounds by their held-out
error in the measured torque's units. A law whose settled value leaves its
range is a finding (:func:`inadmissible`); one that a later round made
redundant goes (:func:`redundant`); on measured trajectories each must earn
its place on a held-out one (:func:`confine`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from bench.core.data import Dataset
from bench.core.modelfile import Packer, Unpacker, build, loader
from bench.physics.models import FittedModel, affine_parts, unit_accelerations
from bench.physics.regression import fit_statistics
from bench.physics.terms import Term
from bench.residual.beyond_data import held_out_verdict
from bench.residual.library import law_text, structural
from bench.residual.criteria import bic
from bench.physics.laws import LAWS
from bench.physics.sensor_laws import SensorLaw, has_time, law_of

#: the fixed point of :func:`settle` is reached when no gain changes by more than this share and
#: the shift by no more than this share of the median sample step
TOLERANCE = 1e-7
#: the most linearise-and-refit steps :func:`settle` takes
MAX_STEPS = 12


@dataclass(frozen=True)
class Sensor:
    """What the loop knows of the path from the arm's torque to the measured
    one: the laws found (:mod:`bench.physics.sensor_laws`, in the order of
    :attr:`bench.physics.laws.LAWS.sensor <bench.physics.laws.Laws.sensor>`, then by joint), each at its
    value, and the reference joint whose gain is fixed at 1."""

    reference: int
    laws: tuple[SensorLaw, ...] = ()

    @classmethod
    def exact(cls, train: Dataset) -> "Sensor":
        """A sensor that reads the torque as it is, its reference joint chosen on ``train``."""
        return cls(int(np.argmax(np.sqrt(np.mean(train.tau**2, axis=0)))))

    @property
    def found_any(self) -> bool:
        """Whether any law has been found."""
        return bool(self.laws)

    def found(self, dof: int) -> list[Term]:
        """The laws found, as terms."""
        return [law.as_term(dof) for law in self.laws]

    def law(self, term: Term) -> SensorLaw | None:
        """The law found that ``term`` stands for, or ``None``."""
        return next((law for law in self.laws if law.name == term.name and law.joint == term.joint), None)

    def at(self, term: Term) -> SensorLaw:
        """The law ``term`` stands for: as found, else at its neutral value."""
        return self.law(term) or law_of(term).start(term.joint)

    def value(self, term: Term) -> tuple[float, float]:
        """The law ``term``'s parameter and its standard error."""
        law = self.at(term)
        return law.value, law.stderr

    def with_laws(self, laws) -> "Sensor":
        """``self`` with ``laws`` (instances) put in their places."""
        order = list(LAWS.sensor)
        keyed = {(law.name, law.joint): law for law in self.laws} | {(law.name, law.joint): law for law in laws}
        ranked = sorted(keyed.values(), key=lambda law: (order.index(law.name), -1 if law.joint is None else law.joint))
        return dataclasses.replace(self, laws=tuple(ranked))

    def without(self, term: Term) -> "Sensor":
        """``self`` without the law ``term``."""
        return dataclasses.replace(self, laws=tuple(law for law in self.laws if (law.name, law.joint)
                                                    != (term.name, term.joint)))

    def states(self, data: Dataset) -> Dataset:
        """``data`` with the states at which the measured torques were the arm's."""
        for law in self.laws:
            data = law.states(data)
        return data

    def _factors(self, data: Dataset) -> list[np.ndarray]:
        return [f for f in (law.factor(data) for law in self.laws) if f is not None]

    def factor(self, corrected: Dataset) -> np.ndarray:
        """``(n, dof)``: what the arm's torques on ``corrected`` are multiplied
        by to read as measured ones (the torque laws' factors, in order)."""
        out = np.ones_like(corrected.tau)
        for f in self._factors(corrected):
            out = out * f
        return out

    def correct(self, measured: Dataset) -> Dataset:
        """The arm's torques at its states, from measured ones."""
        data = self.states(measured)
        factors = self._factors(data)
        if not factors:
            return data
        tau = data.tau
        for f in reversed(factors):
            tau = tau / f
        return data.replace(tau=tau)

    def measure(self, tau: np.ndarray, states: Dataset) -> np.ndarray:
        """The measured torques of the arm's torques ``tau`` at ``states``."""
        for law in self.laws:
            f = law.factor(states.with_torque(tau))
            if f is not None:
                tau = tau * f
        return tau

    def terms(self, train: Dataset) -> list[Term]:
        """The laws not yet found, wherever each is offered on ``train``
        (:meth:`~bench.physics.sensor_laws.SensorLaw.offered`: a gain on each
        joint but the reference, a load-dependent friction on each joint, a
        time shift where ``train`` has time stamps, and any law registered)."""
        return [t for law in LAWS.sensor.values() for joint in law.offered(train, self.reference)
                if self.law(t := law.term(joint, train.dof)) is None]

    def entries(self, dof: int) -> list[dict]:
        """The JSON entries of the laws found."""
        return [law.entry(dof, self.reference) for law in self.laws]


def column(term: Term, model: FittedModel, train: Dataset, sensor: Sensor | None = None) -> np.ndarray:
    """A law's column linearised at ``model`` on ``train``, the law as
    ``sensor`` has it (see :meth:`~bench.physics.sensor_laws.SensorLaw.column`),
    flattened sample-major."""
    tau = np.asarray(model.predict_torque(train), dtype=np.float64)
    law = law_of(term).start(term.joint) if sensor is None else sensor.at(term)
    return law.column(tau, train).ravel()


def settle(strategy, model, measured: Dataset, sensor: Sensor, new: list[Term]):
    """Apply the laws ``new`` (and those ``sensor`` has) exactly: refit the
    model on the corrected data, fit the laws' linearised columns beside it,
    update them, until the fixed point (:data:`TOLERANCE`). Returns the
    model, the sensor and the corrected training data."""
    sensor = sensor.with_laws([law_of(t).start(t.joint) for t in new if sensor.law(t) is None])
    if not sensor.laws:
        train = sensor.correct(measured)
        return strategy.refit(model, train, model.effects), sensor, train
    step = float(np.median(np.diff(np.unique(measured.time)))) if has_time(measured) and len(measured) > 1 else 1.0
    for _ in range(MAX_STEPS):
        train = sensor.correct(measured)
        model = strategy.refit(model, train, model.effects)
        target, F = strategy.problem(model, train)
        tau = np.asarray(model.predict_torque(train), dtype=np.float64)
        G = np.column_stack([law.column(tau, train).ravel() for law in sensor.laws])
        coef, stderr, _ = fit_statistics(np.hstack([F, G]), target.ravel())
        coef, stderr = coef[-len(sensor.laws):], stderr[-len(sensor.laws):]
        change = max(law.change(c, step) for law, c in zip(sensor.laws, coef))
        sensor = dataclasses.replace(sensor, laws=tuple(law.updated(c, e) for law, c, e in zip(sensor.laws, coef, stderr)))
        if change < TOLERANCE:
            break
    train = sensor.correct(measured)
    model = strategy.refit(model, train, model.effects)
    sensor = dataclasses.replace(sensor, laws=tuple(law.settled(strategy, model, train) for law in sensor.laws))
    return model, sensor, train


def measured_rss(model: FittedModel, sensor: Sensor, measured: Dataset, weights: np.ndarray | None = None) -> float:
    """The residual sum of squares of ``model`` read through ``sensor`` on the
    measured torques, each joint's times its ``weights`` where given: what fits
    read through different sensors are compared by."""
    r = Sensed(model, sensor).predict_torque(measured) - measured.tau
    return float(np.sum((r if weights is None else r * weights) ** 2))


def inadmissible(strategy, model, measured: Dataset, sensor: Sensor):
    """The laws whose settled parameter left its admissible range
    (:attr:`~bench.physics.sensor_laws.SensorLaw.bounds`: a gain outside
    :data:`~bench.physics.sensor_laws.GAIN_RANGE`, a load-dependent friction outside
    ``0 <= mu <= 0.5``), each dropped with the others settled again: the fixed
    point may take a law there that entered inside it. Returns the model, the
    sensor and, per law dropped, ``(term, structural finding)``."""
    out = []
    for law in sensor.laws:
        if law.admissible():
            continue
        term = law.as_term(measured.dof)
        out.append((term, structural(term, law.value - law.neutral, law.stderr)))
        model, sensor, _ = settle(strategy, model, measured, sensor.without(term), [])
    return model, sensor, out


def redundant(strategy, model, measured: Dataset, sensor: Sensor, min_drop: float):
    """Backward elimination of the sensor's laws after a round's refit: a law
    whose removal (the others settled again, :func:`settle`) raises the BIC of
    the fit to the measured torques by less than ``min_drop`` went redundant
    with what the round added (a gain that stood in for a missing term of
    ``L``), and goes. Returns the model, the sensor, the corrected training
    data and the labels of the laws dropped."""
    dropped = []
    while sensor.found_any:
        n, k = measured.tau.size, len(sensor.laws)
        now = bic(measured_rss(model, sensor, measured), n, k)
        options = []
        for term in sensor.found(measured.dof):
            m, s, t = settle(strategy, model, measured, sensor.without(term), [])
            options.append((bic(measured_rss(m, s, measured), n, k - 1) - now, term, m, s, t))
        gain, term, m, s, t = min(options, key=lambda o: o[0])
        if gain >= min_drop:
            break
        dropped.append(f"{term.name} on joint {term.joint + 1}" if term.joint is not None else term.name)
        model, sensor = m, s
    return model, sensor, sensor.correct(measured), dropped


def confine(strategy, model, measured: Dataset, sensor: Sensor, heldout):
    """On measured trajectories, each law the sensor has found must earn its
    place on held-out data (:func:`bench.residual.beyond_data.held_out_verdict`,
    the test an open-ended term passes): it rescales or delays whatever the
    model does, so along the trajectory it was fitted on it can absorb the
    model's own error there. The held-out errors are ``heldout(model, train,
    sensor)``, over the loop's folds: whole trajectories, or, where the data
    hold one, regions of its states, on which a law of one parameter must
    predict torques it was not fitted on. Returns the model, the sensor,
    the corrected training data and, per law dropped, ``(term, finding)``."""
    dropped, train = [], sensor.correct(measured)
    if not measured.trajectories():
        return model, sensor, train, dropped
    kept = None
    for term in sensor.found(measured.dof):
        law = sensor.law(term)
        m, s, t = settle(strategy, model, measured, sensor.without(term), [])
        verdict, errors = held_out_verdict(
            measured, lambda: (heldout(model, train, sensor) if kept is None else kept, heldout(m, t, s)),
            regions=True)
        if verdict is None:
            kept = errors[0]
            continue
        where = f"joint {term.joint + 1}" if term.joint is not None else "every joint"
        dropped.append((term, {
            "name": term.name, "kind": "beyond_data", "law": law_text(term, law.parameter),
            "joints": [j + 1 for j in term.joints], "parameters": {},
            "finding": (f"{term.name} on {where} fits the training data with {law.parameter} = {law.value:.4g} "
                        f"± {law.stderr:.2g}, but it is a law of the sensor or the drive, which rescales or delays "
                        f"whatever the model does, and {verdict}: reported, not added")}))
        model, sensor, train = m, s, t
        kept = None if errors is None else errors[1]
    return model, sensor, train, dropped


class Sensed(FittedModel):
    """A model of the arm read through a sensor: it predicts measured torques
    (for the built-in laws ``g_j (tau_hat_j + mu_j |tau_hat_j| s_j)`` at
    ``t - delta``); everything else is the arm's model's."""

    def __init__(self, model: FittedModel, sensor: Sensor):
        self.model, self.sensor = model, sensor

    def __getattr__(self, name):
        if name in ("model", "sensor"):  # not yet set (while unpickling)
            raise AttributeError(name)
        return getattr(self.model, name)

    def predict_torque(self, data: Dataset) -> np.ndarray:
        states = self.sensor.states(data)
        return self.sensor.measure(np.asarray(self.model.predict_torque(states), dtype=np.float64), states)

    def mass_and_bias(self, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The measured torque's ``M`` and ``c`` as :meth:`FittedModel.mass_and_bias` takes them, from the
        torque at ``dof + 1`` accelerations a state; the arm's torques there are its own ``M`` and ``c``,
        asked once a state (from its engine where it has one: a driven rollout asks at each of its steps),
        read through the sensor (a sensor without laws: the arm's). Where a law of the sensor moves the
        states (a time shift, on data with time stamps), from the arm's torque at the moved states."""
        if not self.sensor.laws:
            return self.model.mass_and_bias(q, qd)
        batch = unit_accelerations(q, qd)
        states = self.sensor.states(batch)
        if states is batch:
            M_arm, c_arm = self.model.mass_and_bias(q, qd)
            arm = np.concatenate([c_arm[:, None, :], c_arm[:, None, :] + np.transpose(M_arm, (0, 2, 1))], axis=1)
            arm = arm.reshape(len(batch), -1)
        else:
            arm = np.asarray(self.model.predict_torque(states), dtype=np.float64)
        return affine_parts(self.sensor.measure(arm, states), len(q))

    def predict_lagrangian(self, data: Dataset) -> np.ndarray:
        return self.model.predict_lagrangian(self.sensor.states(data))

    def expression(self):
        return self.model.expression()

    def saved(self, packer: Packer) -> dict:
        """The arm's model as saved, and the sensor: its reference joint and each law at its value."""
        return {"kind": "sensed", "model": self.model.saved(packer), "reference": self.sensor.reference,
                "laws": [{"name": law.name, "joint": law.joint, "value": law.value, "stderr": law.stderr}
                         for law in self.sensor.laws]}


@loader("sensed")
def _load(tree: dict, unpacker: Unpacker, context: dict) -> Sensed:
    laws = []
    for entry in tree["laws"]:
        if entry["name"] not in LAWS.sensor:
            raise ValueError(f"a law of the sensor or the drive named {entry['name']!r}, which is not registered here")
        joint = entry["joint"]
        laws.append(LAWS.sensor[entry["name"]](None if joint is None else int(joint), float(entry["value"]),
                                        float(entry["stderr"])))
    return Sensed(build(tree["model"], unpacker, context), Sensor(int(tree["reference"]), tuple(laws)))
