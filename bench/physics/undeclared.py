"""What the data generator adds that a system does not declare: the
effects of :mod:`bench.physics.effects` and the laws of :mod:`bench.physics.laws`,
as ``bench data --effects`` names them.

* a one-joint effect: one coefficient per joint (``viscous_friction=0.8,0.5``);
* a coupled effect: ``i-j:c`` items, joints from 1 (``coupled_spring=1-2:3.0``);
* an effect of the whole system: one number (``tip_payload=0.3``);
* a law of the torque sensor or the drive (:attr:`bench.physics.laws.LAWS.sensor <bench.physics.laws.Laws.sensor>`,
  a plugin's too): one value per joint, applied with the law's own class to the
  torque the arm and every other effect make (``torque_gain=1,0.96``,
  ``load_friction=0,0.1``);
* a law of several parameters: ``j:p1,...,pk`` items, ``;``-separated, in the
  order of its parameters (``stribeck_friction=1:1.0,2.0,0.5,0.3``,
  ``smooth_coulomb=2:0.7,0.05``).
"""

from __future__ import annotations

import math

import numpy as np

from bench.core.data import Dataset
from bench.physics.effects import EFFECTS
from bench.core.errors import ConfigError
from bench.physics.laws import LAWS
from bench.physics.sensor_laws import JointTorqueLaw

#: the laws the generator takes as ``j:p1,...,pk`` items: those of several parameters, or a shaped one
GENERATOR_LAWS = {name: law for name, law in LAWS.arm.items() if law.composite}


def torque_laws() -> dict[str, type[JointTorqueLaw]]:
    """The registered laws of the sensor or the drive that multiply one joint's torque
    (:attr:`bench.physics.laws.LAWS.sensor <bench.physics.laws.Laws.sensor>`, a plugin's among them): the generator
    applies each with the class the residual loop fits."""
    return {name: law for name, law in LAWS.sensor.items() if issubclass(law, JointTorqueLaw)}


def parse_effects(items: list[str], dof: int, source: str = "--effects") -> dict[str, dict[tuple[int, ...], float]]:
    """``["viscous_friction=0.8,0.5", "coupled_spring=1-2:3.0"]`` ->
    ``{"viscous_friction": {(0,): 0.8, (1,): 0.5}, "coupled_spring": {(0, 1): 3.0}}``;
    a law's items give ``{(j,): (p1, ..., pk)}``. A clear :class:`ConfigError`
    naming ``source`` and the item otherwise."""
    out = {}
    for item in items:
        name, sep, values = item.partition("=")
        name = name.strip()
        if not sep:
            raise ConfigError(f"{source}: expected NAME=c1,...,c{dof} or NAME=i-j:c, got {item!r}")
        sensor = torque_laws()
        known = [n for n, e in EFFECTS.items() if e.shaped is None and not e.sensor] + list(GENERATOR_LAWS) + list(sensor)
        if name == "time_shift":
            raise ConfigError(f"{source}: time_shift needs recordings with time stamps; generated samples have none "
                              f"(bench robot-log --torque-delay SECONDS records one)")
        if name not in known:
            raise ConfigError(f"{source}: unknown effect {name!r}; known: {', '.join(known)}")
        if name in GENERATOR_LAWS:
            out[name] = _parse_law(name, values, dof, source)
            continue
        if name in sensor:
            law = sensor[name]
            coefs = _per_joint(name, values, dof, source)
            if not all(map(law.generable, coefs)):
                raise ConfigError(f"{source}: {name} needs {dof} coefficients with {law.generable_condition()}, one per "
                                  f"joint ({law.parameter} = {law.neutral:g}: none), got {values!r}")
            out[name] = {(j,): c for j, c in enumerate(coefs)}
            continue
        if EFFECTS[name].arity == 0:
            try:
                value = float(values)
            except ValueError:
                value = math.nan
            if not math.isfinite(value) or not EFFECTS[name].admissible(value):
                raise ConfigError(f"{source}: {name} needs one finite number{' >= 0' if EFFECTS[name].nonnegative else ''} "
                                  f"({EFFECTS[name].parameter}), got {values!r}")
            out[name] = {(): value}
            continue
        if EFFECTS[name].arity == 1:
            coefs = _per_joint(name, values, dof, source)
            out[name] = {(j,): c for j, c in enumerate(coefs)}
            _physical(name, out[name], source)
            continue
        pairs = {}
        for part in values.split(","):
            joints, colon, value = part.partition(":")
            i, dash, j = joints.partition("-")
            try:
                key, c = (int(i) - 1, int(j) - 1), float(value)
            except ValueError:
                key, c = None, math.nan
            if not (colon and dash and key and math.isfinite(c)) or not (0 <= min(key) and max(key) < dof and key[0] != key[1]):
                raise ConfigError(f"{source}: {name} needs i-j:c items with two distinct joints in 1..{dof} and a "
                                  f"finite coefficient, got {part!r}")
            pairs[key] = c
        _physical(name, pairs, source)
        out[name] = pairs
    return out


def _per_joint(name: str, values: str, dof: int, source: str) -> tuple[float, ...]:
    """``c1,...,cn`` -> one finite coefficient per joint; a :class:`ConfigError` naming ``source`` otherwise."""
    try:
        coefs = tuple(float(v) for v in values.split(","))
    except ValueError:
        raise ConfigError(f"{source}: {name} needs numbers, got {values!r}") from None
    if len(coefs) != dof or not all(np.isfinite(coefs)):
        raise ConfigError(f"{source}: {name} needs {dof} finite coefficient(s), one per joint, got {values!r}")
    return coefs


def _physical(name: str, coefficients: dict[tuple[int, ...], float], source: str) -> None:
    """A clear :class:`ConfigError` naming the effect and joint where an effect that
    only a coefficient >= 0 makes physical (friction, damping, an armature, a
    passive spring, :attr:`Effect.nonnegative`) is given a negative one: it would
    generate data with energy put in, or a negative inertia."""
    effect = EFFECTS[name]
    if effect.bounds is not None or not effect.nonnegative:
        return
    for joints, c in coefficients.items():
        if c < 0:
            where = f"joint {joints[0] + 1}" if len(joints) == 1 else f"joints {joints[0] + 1}-{joints[1] + 1}"
            raise ConfigError(f"{source}: {name} on {where} is {c:g}, which is not physical ({effect.condition}): "
                              f"negative friction or damping would put energy in, a negative armature is a negative "
                              f"inertia, and a passive spring's stiffness is not negative")


def _parse_law(name: str, values: str, dof: int, source: str) -> dict[tuple[int], tuple[float, ...]]:
    """``j:p1,...,pk;j:...`` -> ``{(j - 1,): (p1, ..., pk)}`` for a law."""
    law = GENERATOR_LAWS[name]
    out = {}
    for part in values.split(";"):
        joint, colon, rest = part.partition(":")
        try:
            j, ps = int(joint) - 1, tuple(float(v) for v in rest.split(","))
        except ValueError:
            j, ps = -1, ()
        if not colon or not 0 <= j < dof or len(ps) != len(law.parameters) or not all(map(math.isfinite, ps)):
            raise ConfigError(f"{source}: {name} needs j:{','.join(law.parameters)} items (a joint in 1..{dof} and "
                              f"{len(law.parameters)} finite numbers), ';'-separated, got {part!r}")
        if not law.check(ps):
            raise ConfigError(f"{source}: {name} on joint {j + 1} is not physical: it needs {law.condition}, "
                              f"got {part!r}")
        out[(j,)] = ps
    return out


def add_effects(data: Dataset, effects: dict, system=None) -> Dataset:
    """``data`` with the effects' torques added (and, for conservative effects,
    their terms added to ``L``); ``effects`` as :func:`parse_effects` gives
    them, or a one-joint effect's coefficients as a sequence, one per joint
    (``{"viscous_friction": (0.8, 0.5)}``). An effect of the whole system
    (a payload, a tilt) needs ``system``, the data's system."""
    tau = data.tau.copy()
    L = None if data.L is None else data.L.copy()
    effects = {name: coefs if isinstance(coefs, dict) else {(j,): c for j, c in enumerate(coefs)}
               for name, coefs in effects.items()}
    for name, coefs in effects.items():
        if name in LAWS.sensor:  # they act on the arm's torque: after the arm's effects
            continue
        for joints, c in coefs.items():
            if name in GENERATOR_LAWS:
                pairs = [(EFFECTS[p.name].term(joints[0], shape=p.shape), p.coefficient) for p in GENERATOR_LAWS[name].parts(*c)]
            elif EFFECTS[name].exact is not None:
                EFFECTS[name].require(system)
                pairs = [(EFFECTS[name].exact(system, c), 1.0)]
            else:
                pairs = [(EFFECTS[name].term(*joints, system=system), c)]
            for term, coef in pairs:
                if coef == 0:
                    continue
                tau += coef * term.torque(data)
                if L is not None and term.in_lagrangian:
                    L += coef * term.value(data)

    for name, law in torque_laws().items():  # each multiplies a joint's torque, so their order does not matter
        for (j,), c in effects.get(name, {}).items():
            tau[:, j] *= law(j, c).joint_factor(data.replace(tau=tau))

    def value(c):
        return ",".join(f"{x:g}" for x in c) if isinstance(c, tuple) else f"{c:g}"

    text = ", ".join(f"{k}=" + ",".join(f"{'-'.join(str(j + 1) for j in js)}:{value(c)}" if len(js) > 1 or k in GENERATOR_LAWS
                                        else value(c) for js, c in v.items()) for k, v in effects.items())
    return data.replace(tau=tau, L=L, source=f"{data.source} + undeclared {text}",
                        meta={**data.meta, "effects": {k: {"-".join(str(j + 1) for j in js) or "all": c for js, c in v.items()}
                                                       for k, v in effects.items()}})
