"""The residual loop's library: the terms it tries, from the suite's term library
(:class:`~bench.physics.terms.TermLibrary`), each one physical cause.

* the named effects of :mod:`bench.physics.effects` on every joint (viscous and
  Coulomb friction, armature, spring, offset) and the coupled ones on every
  pair of coordinates (a spring or damper on their difference);
* on a planar chain, the general Lagrangian terms of the whole system that a
  tip payload or a gravity direction that is off contributes, built from the
  system's geometry and declared Lagrangian;
* an open-ended library in the space of ``L`` and ``D``, reported as
  ``symbolic`` with their expression:

  - terms of ``L``: sparse regression's library
    (:func:`~bench.physics.terms.lagrangian_library`) with velocity degree 0
    (potentials ``p(q)``) and 2 (kinetic terms ``qd_i qd_j p(q)``), less the
    constant and what a named effect already is; degree 1 is left out, its
    terms being gyroscopic or, like ``qd_i cos q_i``, total derivatives with
    no torque. Only while the library has at most :data:`MAX_OPEN_LAGRANGIAN`
    terms (up to 4 angles): an arm's would be thousands, each needing its
    Euler–Lagrange transform. The mass matrix of the model with such terms
    is checked by the loop;
  - terms of ``D`` on each joint, ``|qd_j|^3 / 3`` (torque ``qd_j |qd_j|``,
    quadratic drag) and ``qd_j^4 / 4`` (torque ``qd_j^3``); being
    non-negative, they are physical only with a coefficient >= 0.

  Generalized forces that are neither (a product of ``sin q`` and ``qdd``,
  say) are not in it: on measured data they mended the fitted model's
  own errors on its training recordings and made it worse on others.
"""

from __future__ import annotations

import functools
import math

import sympy

from bench.physics.effects import EFFECTS
from bench.physics.laws import FAMILIES, Part, group
from bench.core.symbolic import coordinate_symbols
from bench.physics.terms import Term, TermLibrary, lagrangian_library, lagrangian_library_size
from bench.physics.sensor_laws import law_of


#: the most Lagrangian terms the open-ended library may have (see the module docstring)
MAX_OPEN_LAGRANGIAN = 300


@functools.lru_cache(maxsize=None)
def open_ended(dof: int, kinds: tuple[str, ...]) -> TermLibrary:
    """The open-ended terms of ``L`` and ``D`` (see the module docstring), each
    named by its expression's text."""
    q, qd = coordinate_symbols(dof)
    named = {sympy.Integer(1)} | {v**2 for v in qd} | {x**2 for x, k in zip(q, kinds) if k == "linear"}
    terms = []
    if lagrangian_library_size(dof, kinds) <= MAX_OPEN_LAGRANGIAN:
        terms += [Term.lagrangian(t.expr, str(t.expr)) for t in lagrangian_library(dof, kinds, (0, 2)) if t.expr not in named]
    for j, v in enumerate(qd):
        terms += [Term.dissipation(sympy.Abs(v) ** 3 / 3, f"Abs({v})**3/3", j), Term.dissipation(v**4 / 4, f"{v}**4/4", j)]
    return TermLibrary(terms)


#: the velocities (rad/s, or m/s) of a shaped effect (a Stribeck hump, smoothed Coulomb friction)
#: the library's terms start from; the loop refines an accepted one
SHAPE_GRID = (0.03, 0.1, 0.3, 1.0, 3.0)


def loop_library(dof: int, coupled: bool = True, system=None) -> TermLibrary:
    """Every term the loop tries: the named effects on every joint (the coupled ones on
    every pair, where ``coupled``: the coordinates are absolute angles; the
    shaped ones at each velocity of :data:`SHAPE_GRID`), the effects of
    the whole ``system`` that apply to it (a tip payload and a gravity tilt
    on a planar chain), then the open-ended terms of ``L`` and ``D``."""
    arm = [effect for effect in EFFECTS.values() if not effect.sensor]  # the sensor's laws: bench.residual.sensors
    named = [effect.term(*joints, shape=v) for effect in arm if effect.arity == 1 or (coupled and effect.arity == 2)
             for joints in _placements(effect.arity, dof) for v in _shapes(effect)]
    whole = [effect.term(system=system) for effect in arm if effect.arity == 0 and effect.applies_to(system)]
    kinds = system.kinds if system is not None else ("angle",) * dof
    return TermLibrary(named + whole + list(open_ended(dof, tuple(kinds))))


def _shapes(effect) -> tuple:
    """The shapes an effect's terms take: none, its own grid, or :data:`SHAPE_GRID`."""
    if not effect.shaped:
        return (None,)
    return effect.grid if effect.grid is not None else SHAPE_GRID


def resolved_periods(term: Term, data) -> bool:
    """Whether a periodic part's period fits in its joint's recorded range
    (``N * (max q - min q) >= 2 pi``): over a smaller part of one period its
    torque is a spring's and an offset's, which the simpler laws explain."""
    if term.shape is None or EFFECTS[term.name].grid is None:
        return True
    q = data.q[:, term.joint]
    return term.shape * float(q.max() - q.min()) >= 2 * math.pi


def _placements(arity: int, dof: int) -> list[tuple[int, ...]]:
    if arity == 1:
        return [(j,) for j in range(dof)]
    return [(i, j) for i in range(dof) for j in range(i + 1, dof)]


def is_named(term: Term) -> bool:
    """A named effect (not an open-ended symbolic term)."""
    return term.name in EFFECTS


def admissible(term: Term, coefficient: float) -> bool:
    """Whether a coefficient is physical: a named effect's by
    :meth:`Effect.admissible`; an open-ended term of ``D`` (non-negative) needs
    one >= 0; an open-ended term of ``L`` has no sign to keep (the loop
    checks the mass matrix instead)."""
    if term.place == "sensor":
        kind = law_of(term)
        return kind.admissible_value(kind.value_of(coefficient))
    if is_named(term):
        return EFFECTS[term.name].admissible(coefficient)
    return coefficient >= 0 if term.place == "D" else True


def structural(term: Term, coefficient: float, stderr: float) -> dict:
    """The JSON entry of a residual that only an inadmissible coefficient
    explains: the declared form lacks this freedom. It names the term and the
    coefficient that would be needed; the term is not added to the model."""
    if term.place == "sensor":  # a law of the sensor or the drive: its coefficient is a change from its neutral value
        kind = law_of(term)
        parameter, condition, coefficient = kind.parameter, kind.condition(), kind.value_of(coefficient)
    else:
        parameter = EFFECTS[term.name].parameter if is_named(term) else "c"
        condition = EFFECTS[term.name].condition if is_named(term) else f"{parameter} >= 0"
    law = law_text(term, parameter)
    entry = {"name": term.name if is_named(term) or term.place == "sensor" else "symbolic", "kind": "structural", "law": law,
             "joints": [j + 1 for j in term.joints], "parameters": {},
             "finding": (f"the declared form lacks this freedom: the residual is explained by {law} only with "
                         f"{parameter} = {coefficient:.4g} ± {stderr:.2g}, which is not physical "
                         f"({condition}); the term is not added")}
    if not is_named(term) and term.place != "sensor":
        entry["expression"] = term.name
    return entry


def mismatch(named: list[Term], term: Term, margin: float, size: float, rms: float) -> dict:
    """The JSON entry of a step where the named law ``named`` was the nearest
    the vocabulary has but an open-ended ``term`` explained the residual far
    better (by ``margin`` of BIC): what was seen, its joints, and its torque's
    size (``size``, RMS) against the residual's (``rms``). The named law is
    not reported for it."""
    where = "joint" + ("s " if len(term.joints) > 1 else " ") + "-".join(str(j + 1) for j in term.joints)
    return {"name": "unnamed", "kind": "structural", "law": law_text(term, "c"), "joints": [j + 1 for j in term.joints],
            "parameters": {}, "expression": term.name,
            "finding": (f"no named law explains the residual on {where}: its shape is {term.name}, which explains it "
                        f"better than the nearest named law ({' + '.join(label(t) for t in named)}) by a BIC of "
                        f"{margin:.3g}; its torque's RMS is {size:.3g} against the residual's {rms:.3g}; the named "
                        f"law is not reported for it")}


def label(term: Term) -> str:
    """``"<effect or expression> on joint <j>"`` or ``"... on joints <i>-<j>"``,
    joints from 1, with a shaped effect's parameter (``stribeck_hump (v_s=0.3)``)."""
    joints = [j + 1 for j in term.joints]
    where = f"joint {joints[0]}" if len(joints) == 1 else f"joints {'-'.join(map(str, joints))}"
    shape = f" ({EFFECTS[term.name].shaped}={term.shape:.4g})" if term.shape is not None else ""
    return f"{term.name}{shape} on {where}"


def law_text(term: Term, parameter: str) -> str:
    """The text of a term's law with its parameter: ``L += ...``, ``D = ...``
    or ``tau += ...``."""
    if term.place == "sensor":
        return law_of(term).law_text(term, parameter)
    where = {"L": "L += ", "D": "D = "}.get(term.place, "tau += ")
    return f"{where}{sympy.Symbol(parameter) * term.expr}"


def describe_all(terms: list[Term], coef, stderr, shape_stderr: dict[Term, float]) -> list[dict]:
    """The JSON entries of the accepted effects, one per law
    (:func:`bench.physics.laws.group`): the named effects on one joint that
    make a law of several parts (Coulomb plus viscous friction; a Stribeck
    hump with the Coulomb and viscous friction on its joint) or a shaped
    one (smoothed Coulomb friction) are one entry with the law's parameters
    and its ``parts`` (each as :func:`describe` gives it; a shape's error
    from ``shape_stderr``); every other effect is one entry (:func:`describe`),
    in the order the effects were accepted."""
    fits = {t: (float(c), float(s)) for t, c, s in zip(terms, coef, stderr)}
    on_joint: dict[int, dict[str, Term]] = {}
    for t in terms:
        if len(t.joints) == 1 and t.name in FAMILIES:  # a named effect on one joint
            on_joint.setdefault(t.joint, {})[t.name] = t
    laws = {}  # the first part of each law of several parts -> its entry; its other parts -> None
    for j, named in on_joint.items():
        parts = {n: Part(n, fits[t][0], t.shape, fits[t][1], float(shape_stderr.get(t, math.nan)))
                 for n, t in named.items()}
        for law, members in group(parts):
            if not law.composite:
                continue
            mine = [named[n] for n in members]
            entry = {"name": law.name, "kind": law.kind, "law": law.text(j), "joints": [j + 1], "joint": j + 1,
                     "parameters": {k: {"value": float(v), "stderr": float(e)} for k, (v, e) in law.parameters_of(members).items()},
                     "parts": [describe(t, *fits[t]) | ({"shape": {"name": EFFECTS[t.name].shaped, "value": float(t.shape),
                                                                   "stderr": members[t.name].shape_stderr}}
                                                        if t.shape is not None else {}) for t in mine]}
            first = min(mine, key=terms.index)
            laws.update({t: None for t in mine})
            laws[first] = entry
    out = []
    for t in terms:
        if t not in laws:
            out.append(describe(t, *fits[t]))
        elif laws[t] is not None:
            out.append(laws[t])
    return out


def describe(term: Term, coefficient: float, stderr: float) -> dict:
    """The JSON entry of an accepted effect (the README's contract): ``name``,
    ``kind``, ``law`` (the sympy text of its term of ``L`` or ``D``, or of
    its generalized force, with its parameter), ``joints`` (from 1),
    ``parameters`` ``{name: {"value", "stderr"}}``; an effect on one joint
    also keeps ``joint``, ``coefficient`` and ``stderr``, and an open-ended
    term ``expression``."""
    named = is_named(term)
    parameter = EFFECTS[term.name].parameter if named else "c"
    law = law_text(term, parameter)
    if named and EFFECTS[term.name].coefficient_of is not None:  # a tilt's coefficient is sin(alpha): report alpha
        coefficient, stderr = EFFECTS[term.name].parameter_from(coefficient, stderr)
        law = law.replace(parameter, str(EFFECTS[term.name].coefficient_of(sympy.Symbol(parameter))), 1)
    entry = {"name": term.name if named else "symbolic", "kind": term.kind, "law": law,
             "joints": [j + 1 for j in term.joints],
             "parameters": {parameter: {"value": float(coefficient), "stderr": float(stderr)}}}
    if len(term.joints) == 1:
        entry.update(joint=term.joints[0] + 1, coefficient=float(coefficient), stderr=float(stderr))
    if not named:
        entry["expression"] = term.name
    return entry
