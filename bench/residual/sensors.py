r"""Laws of the torque sensor, its recording and the drive, which act between
the arm's torque and the measured one rather than on the arm's Lagrangian:

* **load-dependent friction per joint**, ``tau_measured_j = tau_j + mu_j
  |tau_j| s_j`` with ``s_j`` the sign of ``qd_j`` (the data's,
  :meth:`~bench.core.data.Dataset.velocity_sign`): a Coulomb level that
  grows with the load torque the drive carries (:mod:`bench.core.effects`);
* **a gain per joint**, ``tau_measured_j = g_j tau_j`` (a calibration error);
* **a time shift** between the torque and the recorded state,
  ``tau_measured(t) = tau(t - delta)`` (a sensor's or a filter's delay), one
  for every joint and recording, so that it carries over to the test
  recordings.

The gains are relative. Multiplying every joint's torque by one factor is a
rescaling of ``L``, which no torque data can tell from the arm's own
parameters (a gauge), so one joint's gain is fixed at 1: the *reference*,
the joint whose measured torque has the largest root mean square on the
training data. Its torque is the best measured against the noise, so the
ratios the other gains are stand on the best-conditioned footing; a user who
knows which sensor is calibrated reads the others as ratios to it.

Each law is bilinear in the model and the law (``g_j`` times the model's
torque), so each is judged like any candidate (:func:`bench.residual.selection.trace`)
by its column linearised at the model where it stands:

* a gain's: the model's torque on its joint, ``tau_hat_j``, coefficient
  ``eps`` with ``g_j <- g_j (1 + eps)``;
* a load-dependent friction's: ``|tau_hat_j| s_j / (1 + mu_j sigma_j)``,
  coefficient the change of ``mu_j`` (``sigma_j = sign(tau_j) s_j``, +1
  where the drive moves the load and -1 where the load drives it back);
* a shift's: ``-d tau_hat / dt`` along each recording, coefficient the change
  of ``delta``.

An accepted law is then applied exactly (:func:`settle`): the model is
refitted on the corrected training data (each ``tau_j`` divided by ``g_j``;
each recording's states taken at ``t - delta``, linearly interpolated along
it; each ``tau_j`` divided by ``1 + mu_j sigma_j``, which needs only the
measured torque's sign, the arm's as long as ``mu_j < 1``), the linearised
columns fitted again beside the model's freedom, and the law updated, until
its correction is below :data:`TOLERANCE` (a fixed point: Gauss–Newton on
the law's parameters). The loop predicts a measured torque as
``g_j (tau_hat_j + mu_j |tau_hat_j| s_j)`` at ``t - delta`` (:class:`Sensed`),
and compares rounds by their held-out error in the measured torque's units.

A time shift needs time stamps and recordings (``bench convert`` data, a
robot log); on independent samples it is not offered. Where a recording's
torque barely changes over ``delta`` (a slow motion), the shift's column is
small and its standard error large: the loop's significance test refuses it.
A per-joint shift (one sensor lagging the others) is not among the laws; each
recording's own estimate of the common one is reported beside it, so that a
recording whose delay differs shows.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import sympy

from bench.core.data import Dataset
from bench.core.effects import EFFECTS
from bench.core.models import FittedModel
from bench.core.regression import fit_statistics
from bench.core.terms import Term
from bench.residual.candidates import law_text, structural
from bench.residual.selection import bic

#: the fixed point of :func:`settle` is reached when no gain changes by more than this share and
#: the shift by no more than this share of the median sample step
TOLERANCE = 1e-7
#: the most linearise-and-refit steps :func:`settle` takes
MAX_STEPS = 12
#: why the reference joint is the one it is, in the loop's JSON
WHY_REFERENCE = ("a gain common to every joint rescales L and no torque data identify it, so one joint's gain is "
                 "fixed at 1: the joint with the largest torque RMS on the training data, whose ratios to the others "
                 "are the best conditioned")


def gain_term(joint: int) -> Term:
    """Joint ``joint``'s (0-based) sensor gain as a candidate term."""
    return EFFECTS["torque_gain"].term(joint)


def load_term(joint: int) -> Term:
    """Joint ``joint``'s (0-based) load-dependent friction as a candidate term."""
    return EFFECTS["load_friction"].term(joint)


def shift_term(dof: int) -> Term:
    """The time shift between torque and state as a candidate term."""
    return Term(sympy.Add(*[sympy.Symbol(f"tau_{j + 1}", real=True) for j in range(dof)]), "sensor", "time_shift")


def has_time(data: Dataset) -> bool:
    """Whether ``data`` hold recordings with time stamps, where a time shift can be seen."""
    return data.time is not None and data.recording is not None


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
class Sensor:
    """What the loop knows of the path from the arm's torque to the measured
    one: each joint's gain (1 at the reference joint), the time shift in
    seconds, each joint's load-dependent friction ``mu``, and their standard
    errors."""

    gains: tuple[float, ...]
    reference: int
    shift: float = 0.0
    gain_stderr: tuple[float, ...] = ()
    shift_stderr: float = 0.0
    #: each training recording's own estimate of the shift, ``{recording: (value, stderr)}``
    per_recording: dict | None = None
    found_gain: frozenset = frozenset()
    found_shift: bool = False
    #: each joint's load-dependent friction (0 where none was found) and its standard error
    load: tuple[float, ...] = ()
    load_stderr: tuple[float, ...] = ()
    found_load: frozenset = frozenset()

    @classmethod
    def exact(cls, train: Dataset) -> "Sensor":
        """A sensor that reads the torque as it is, its reference joint chosen on ``train``."""
        reference = int(np.argmax(np.sqrt(np.mean(train.tau**2, axis=0))))
        zero = (0.0,) * train.dof
        return cls((1.0,) * train.dof, reference, gain_stderr=zero, load=zero, load_stderr=zero)

    @property
    def found_any(self) -> bool:
        """Whether any law has been found."""
        return bool(self.found_gain or self.found_shift or self.found_load)

    @property
    def scale(self) -> np.ndarray:
        return np.asarray(self.gains, dtype=np.float64)

    def states(self, data: Dataset) -> Dataset:
        """``data`` with the states at which the measured torques were the arm's."""
        return shifted(data, self.shift)

    def efficiency(self, data: Dataset) -> np.ndarray:
        """``(n, dof)``: ``1 + mu_j sigma_j`` on ``data`` (whose torques give
        ``sigma``'s sign: measured or corrected, they agree for ``mu < 1``)."""
        if not self.found_load:
            return np.ones_like(data.tau)
        return 1.0 + np.asarray(self.load) * np.sign(data.tau) * data.velocity_sign()

    def factor(self, corrected: Dataset) -> np.ndarray:
        """``(n, dof)``: what the arm's torques on ``corrected`` are multiplied
        by to read as measured ones (the load-dependent friction, then the gain)."""
        return self.efficiency(corrected) * self.scale

    def correct(self, measured: Dataset) -> Dataset:
        """The arm's torques at its states, from measured ones."""
        data = self.states(measured)
        if not self.found_gain and not self.found_load:
            return data
        return data.replace(tau=data.tau / self.scale / self.efficiency(data))

    def value(self, term: Term) -> tuple[float, float]:
        """The law ``term``'s parameter and its standard error."""
        if term.name == "torque_gain":
            return self.gains[term.joint], self.gain_stderr[term.joint]
        if term.name == "load_friction":
            return self.load[term.joint], self.load_stderr[term.joint]
        return self.shift, self.shift_stderr

    def candidates(self, train: Dataset) -> list[Term]:
        """The laws not yet found: a gain on each joint but the reference, a
        load-dependent friction on each joint, and a time shift where
        ``train`` has time stamps."""
        out = [gain_term(j) for j in range(train.dof) if j != self.reference and j not in self.found_gain]
        out += [load_term(j) for j in range(train.dof) if j not in self.found_load]
        if has_time(train) and not self.found_shift:
            out.append(shift_term(train.dof))
        return out

    def entries(self, dof: int) -> list[dict]:
        """The JSON entries of the laws found."""
        out = []
        for j in sorted(self.found_gain):
            out.append({"name": "torque_gain", "kind": "sensor", "law": law_text(gain_term(j), "g"),
                        "joints": [j + 1], "joint": j + 1,
                        "parameters": {"g": {"value": float(self.gains[j]), "stderr": float(self.gain_stderr[j])}},
                        "reference_joint": self.reference + 1, "reference": WHY_REFERENCE})
        for j in sorted(self.found_load):
            out.append({"name": "load_friction", "kind": "drive", "law": law_text(load_term(j), "mu"),
                        "joints": [j + 1], "joint": j + 1,
                        "parameters": {"mu": {"value": float(self.load[j]), "stderr": float(self.load_stderr[j])}}})
        if self.found_shift:
            out.append({"name": "time_shift", "kind": "sensor", "law": law_text(shift_term(dof), "delta"),
                        "joints": list(range(1, dof + 1)),
                        "parameters": {"delta": {"value": float(self.shift), "stderr": float(self.shift_stderr)}},
                        "per_recording": {k: {"value": v, "stderr": e} for k, (v, e) in (self.per_recording or {}).items()}})
        return out


def column(term: Term, model: FittedModel, train: Dataset, sensor: Sensor | None = None) -> np.ndarray:
    """A law's column linearised at ``model`` on ``train``, corrected by
    ``sensor`` (see the module docstring), flattened sample-major."""
    tau = np.asarray(model.predict_torque(train), dtype=np.float64)
    if term.name in ("torque_gain", "load_friction"):
        j, out = term.joint, np.zeros_like(tau)
        if term.name == "torque_gain":
            out[:, j] = tau[:, j]
        else:
            efficiency = np.ones(len(train)) if sensor is None else sensor.efficiency(train)[:, j]
            out[:, j] = np.abs(tau[:, j]) * train.velocity_sign()[:, j] / efficiency
        return out.ravel()
    return -time_derivative(train, tau).ravel()


def settle(strategy, model, measured: Dataset, sensor: Sensor, new: list[Term]):
    """Apply the laws ``new`` (and those ``sensor`` has) exactly: refit the
    model on the corrected data, fit the laws' linearised columns beside it,
    update them, until the fixed point (:data:`TOLERANCE`). Returns the
    model, the sensor and the corrected training data."""
    sensor = dataclasses.replace(sensor, found_gain=sensor.found_gain | {t.joint for t in new if t.name == "torque_gain"},
                                 found_load=sensor.found_load | {t.joint for t in new if t.name == "load_friction"},
                                 found_shift=sensor.found_shift or any(t.name == "time_shift" for t in new))
    terms = found(sensor, measured.dof)
    if not terms:
        train = sensor.correct(measured)
        return strategy.refit(model, train, model.effects), sensor, train
    step = float(np.median(np.diff(np.unique(measured.time)))) if has_time(measured) and len(measured) > 1 else 1.0
    for _ in range(MAX_STEPS):
        train = sensor.correct(measured)
        model = strategy.refit(model, train, model.effects)
        target, F = strategy.problem(model, train)
        G = np.column_stack([column(t, model, train, sensor) for t in terms])
        coef, stderr, _ = fit_statistics(np.hstack([F, G]), target.ravel())
        coef, stderr = coef[-len(terms):], stderr[-len(terms):]
        gains, gain_se, shift, shift_se = list(sensor.gains), list(sensor.gain_stderr), sensor.shift, sensor.shift_stderr
        load, load_se = list(sensor.load), list(sensor.load_stderr)
        change = 0.0
        for t, c, e in zip(terms, coef, stderr):
            if t.name == "torque_gain":
                gains[t.joint] *= 1.0 + c
                gain_se[t.joint] = gains[t.joint] * e
                change = max(change, abs(c))
            elif t.name == "load_friction":
                load[t.joint] += c
                load_se[t.joint] = e
                change = max(change, abs(c))
            else:
                shift += c
                shift_se = e
                change = max(change, abs(c) / step)
        sensor = dataclasses.replace(sensor, gains=tuple(gains), gain_stderr=tuple(gain_se), shift=shift, shift_stderr=shift_se,
                                     load=tuple(load), load_stderr=tuple(load_se))
        if change < TOLERANCE:
            break
    train = sensor.correct(measured)
    model = strategy.refit(model, train, model.effects)
    if sensor.found_shift:
        sensor = dataclasses.replace(sensor, per_recording={k: (sensor.shift + v, e) for k, (v, e)
                                                            in _each_recording(strategy, model, train).items()})
    return model, sensor, train


def without(sensor: Sensor, term: Term) -> Sensor:
    """``sensor`` without the law ``term`` (a gain back at 1, no load-dependent friction, no shift)."""
    if term.name == "torque_gain":
        gains = list(sensor.gains)
        gains[term.joint] = 1.0
        return dataclasses.replace(sensor, gains=tuple(gains), found_gain=sensor.found_gain - {term.joint})
    if term.name == "load_friction":
        load = list(sensor.load)
        load[term.joint] = 0.0
        return dataclasses.replace(sensor, load=tuple(load), found_load=sensor.found_load - {term.joint})
    return dataclasses.replace(sensor, shift=0.0, shift_stderr=0.0, per_recording=None, found_shift=False)


def found(sensor: Sensor, dof: int) -> list[Term]:
    """The laws ``sensor`` has found, as terms."""
    return ([gain_term(j) for j in sorted(sensor.found_gain)] + [load_term(j) for j in sorted(sensor.found_load)]
            + ([shift_term(dof)] if sensor.found_shift else []))


def measured_rss(model: FittedModel, sensor: Sensor, measured: Dataset) -> float:
    """The residual sum of squares of ``model`` read through ``sensor`` on the
    measured torques: what fits read through different sensors are compared by."""
    r = Sensed(model, sensor).predict_torque(measured) - measured.tau
    return float(np.sum(r**2))


def inadmissible(strategy, model, measured: Dataset, sensor: Sensor):
    """The laws whose settled parameter left its admissible range (a gain
    outside :data:`~bench.core.effects.GAIN_RANGE`, a load-dependent friction
    outside ``0 <= mu <= 0.5``), each dropped with the others settled again:
    the fixed point may take a law there that entered inside it. Returns the
    model, the sensor and, per law dropped, ``(term, structural finding)``."""
    out = []
    for term in found(sensor, measured.dof):
        value, stderr = sensor.value(term)
        coefficient = value - 1.0 if term.name == "torque_gain" else value  # a gain's coefficient is its change
        if term.name == "time_shift" or EFFECTS[term.name].admissible(coefficient):
            continue
        out.append((term, structural(term, coefficient, stderr)))
        model, sensor, _ = settle(strategy, model, measured, without(sensor, term), [])
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
        n, k = measured.tau.size, len(found(sensor, measured.dof))
        now = bic(measured_rss(model, sensor, measured), n, k)
        options = []
        for term in found(sensor, measured.dof):
            m, s, t = settle(strategy, model, measured, without(sensor, term), [])
            options.append((bic(measured_rss(m, s, measured), n, k - 1) - now, term, m, s, t))
        gain, term, m, s, t = min(options, key=lambda o: o[0])
        if gain >= min_drop:
            break
        dropped.append(f"{term.name} on joint {term.joint + 1}" if term.joint is not None else term.name)
        model, sensor = m, s
    return model, sensor, sensor.correct(measured), dropped


#: the held-out error a sensor's law must save on another trajectory, as a fraction of the error without it
MIN_GAIN = 0.01


def confine(strategy, model, measured: Dataset, sensor: Sensor, heldout):
    """On measured trajectories, each law the sensor has found must earn its
    place on a held-out trajectory, as an open-ended term must
    (:mod:`bench.residual.reach`): it rescales or delays whatever the model
    does, so along the one trajectory it was fitted on it can absorb the
    model's own error there. With the law, the held-out error
    (``heldout(model, train, sensor)``, over whole trajectories) must be at
    least :data:`MIN_GAIN` lower than without it; training data that hold one
    trajectory cannot confirm it, and there it never stays. Independent
    samples (generated data) have no trajectory to overfit. Returns the model,
    the sensor, the corrected training data and, per law dropped,
    ``(term, finding)``."""
    dropped, train = [], sensor.correct(measured)
    names = measured.trajectories()
    if not names:
        return model, sensor, train, dropped
    kept = heldout(model, train, sensor) if len(names) >= 2 else None
    for term in found(sensor, measured.dof):
        value, stderr = sensor.value(term)
        m, s, t = settle(strategy, model, measured, without(sensor, term), [])
        if kept is None:
            verdict = "the training data hold one trajectory, so no held-out trajectory can confirm it"
        else:
            less = heldout(m, t, s)
            if less >= (1 + MIN_GAIN) * kept:
                continue
            verdict = f"on held-out trajectories it does not pay: held-out MSE {kept:.4g} with it, {less:.4g} without"
        parameter = EFFECTS[term.name].parameter
        where = f"joint {term.joint + 1}" if term.joint is not None else "every joint"
        dropped.append((term, {
            "name": term.name, "kind": "beyond_data", "law": law_text(term, parameter), "joints": [j + 1 for j in term.joints],
            "parameters": {},
            "finding": (f"{term.name} on {where} fits the training data with {parameter} = {value:.4g} ± {stderr:.2g}, "
                        f"but it is a law of the sensor or the drive, which rescales or delays whatever the model does, and "
                        f"{verdict}: reported, not added")}))
        model, sensor, train = m, s, t
        kept = None if kept is None else less
    return model, sensor, train, dropped


def _each_recording(strategy, model, train: Dataset) -> dict:
    """Each recording's own estimate of what is left of the shift, added to it:
    the shift's column on that recording's rows only, fitted beside the model."""
    target, F = strategy.problem(model, train)
    full = column(shift_term(train.dof), model, train)
    rows = np.repeat(train.recording, train.dof)
    out = {}
    for name in train.recordings():
        G = np.where(rows == name, full, 0.0)[:, None]
        coef, stderr, _ = fit_statistics(np.hstack([F, G]), target.ravel())
        out[str(name)] = (float(coef[-1]), float(stderr[-1]))
    return out


class Sensed(FittedModel):
    """A model of the arm read through a sensor: it predicts measured torques,
    ``g_j (tau_hat_j + mu_j |tau_hat_j| s_j)`` at ``t - delta``; everything
    else is the arm's model's."""

    def __init__(self, model: FittedModel, sensor: Sensor):
        self.model, self.sensor = model, sensor

    def __getattr__(self, name):
        if name in ("model", "sensor"):  # not yet set (while unpickling)
            raise AttributeError(name)
        return getattr(self.model, name)

    def predict_torque(self, data: Dataset) -> np.ndarray:
        states = self.sensor.states(data)
        tau = np.asarray(self.model.predict_torque(states), dtype=np.float64)
        if self.sensor.found_load:
            tau = tau + np.asarray(self.sensor.load) * np.abs(tau) * states.velocity_sign()
        return tau * self.sensor.scale

    def predict_lagrangian(self, data: Dataset) -> np.ndarray:
        return self.model.predict_lagrangian(self.sensor.states(data))

    def expression(self):
        return self.model.expression()
