"""The residual loop's candidates: terms of the suite's term library
(:class:`~bench.core.terms.TermLibrary`) on one joint each.

* the named effects of :mod:`bench.core.effects` on every joint (viscous and
  Coulomb friction, armature, spring, offset) and the coupled ones on every
  pair of coordinates (a spring or damper on their difference);
* on a planar chain, the general Lagrangian terms of the whole system that a
  tip payload or a gravity direction that is off contributes, built from the
  system's geometry and declared Lagrangian;
* an open-ended library generated per joint ``j`` from the primitives
  ``q, qd, qdd, sign qd, |qd|, sin q, cos q`` of the joint and, per other
  joint ``k``, ``q_k, qd_k, qdd_k, sin(q_j - q_k), cos(q_j - q_k)``: every
  primitive that is not a named effect's own column, every product of two
  primitives (less the degenerate ones), and ``q^3``, ``qd^3`` and
  ``sign(qd) |q|``. These are generalized forces on joint ``j``, reported as
  ``symbolic`` with their expression (the term's name).
"""

from __future__ import annotations

import functools

import sympy

from bench.core.effects import EFFECTS
from bench.core.terms import Term, TermLibrary


def _primitives(dof: int, j: int) -> list[tuple[str, sympy.Expr]]:
    """The building blocks of the open-ended terms of joint ``j``, with their text."""
    n = j + 1
    q = sympy.symbols(f"q_1:{dof + 1}", real=True)
    qd = sympy.symbols(f"qd_1:{dof + 1}", real=True)
    qdd = sympy.symbols(f"qdd_1:{dof + 1}", real=True)
    out = [
        (f"q_{n}", q[j]),
        (f"qd_{n}", qd[j]),
        (f"qdd_{n}", qdd[j]),
        (f"sign(qd_{n})", sympy.sign(qd[j])),
        (f"Abs(qd_{n})", sympy.Abs(qd[j])),
        (f"sin(q_{n})", sympy.sin(q[j])),
        (f"cos(q_{n})", sympy.cos(q[j])),
    ]
    for k in range(dof):
        if k != j:
            m = k + 1
            out += [
                (f"q_{m}", q[k]),
                (f"qd_{m}", qd[k]),
                (f"qdd_{m}", qdd[k]),
                (f"sin(q_{n} - q_{m})", sympy.sin(q[j] - q[k])),
                (f"cos(q_{n} - q_{m})", sympy.cos(q[j] - q[k])),
            ]
    return out


#: products of the joint's own sign(qd) and |qd| are not new terms: sign^2 = 1,
#: sign(x) |x| = x, |x|^2 = x^2 (a square of a cosine, 1 - sin^2, and
#: qd sign(qd) = |qd| are skipped too)
_DEGENERATE = {("sign", "sign"), ("sign", "Abs"), ("Abs", "sign"), ("Abs", "Abs")}


@functools.lru_cache(maxsize=None)
def symbolic_terms(dof: int, j: int) -> TermLibrary:
    """The open-ended terms of joint ``j`` (see the module docstring), each a
    generalized force named by its expression's text."""
    n = j + 1
    prims = _primitives(dof, j)
    named = {f"q_{n}", f"qd_{n}", f"qdd_{n}", f"sign(qd_{n})"}  # spring, viscous, armature, Coulomb
    terms = [(text, e) for text, e in prims if text not in named]
    for a in range(len(prims)):
        for b in range(a, len(prims)):
            (ta, ea), (tb, eb) = prims[a], prims[b]
            heads = (ta.split("(")[0], tb.split("(")[0])
            if heads in _DEGENERATE or (ta == tb and heads[0] == "cos") or {ta, tb} == {f"qd_{n}", f"sign(qd_{n})"}:
                continue
            terms.append((f"{ta}**2" if ta == tb else f"{ta}*{tb}", ea * eb))
    q, qd = prims[0][1], prims[1][1]
    terms += [(f"q_{n}**3", q**3), (f"qd_{n}**3", qd**3), (f"sign(qd_{n})*Abs(q_{n})", sympy.sign(qd) * sympy.Abs(q))]
    return TermLibrary(Term.force(e, j, text) for text, e in terms)


#: the Stribeck velocities (rad/s, or m/s) the candidates start from; the loop refines an accepted one
STRIBECK_GRID = (0.03, 0.1, 0.3, 1.0, 3.0)


def candidates(dof: int, coupled: bool = True, system=None) -> TermLibrary:
    """Every candidate: the named effects on every joint (the coupled ones on
    every pair, where ``coupled``: the coordinates are absolute angles; the
    shaped ones at each velocity of :data:`STRIBECK_GRID`), the effects of
    the whole ``system`` that apply to it (a tip payload and a gravity tilt
    on a planar chain), then the open-ended terms."""
    named = [effect.term(*joints, shape=v) for effect in EFFECTS.values() if effect.arity == 1 or (coupled and effect.arity == 2)
             for joints in _placements(effect.arity, dof) for v in (STRIBECK_GRID if effect.shaped else (None,))]
    whole = [effect.term(system=system) for effect in EFFECTS.values() if effect.arity == 0 and effect.applies_to(system)]
    return TermLibrary(named + whole + [t for j in range(dof) for t in symbolic_terms(dof, j)])


def _placements(arity: int, dof: int) -> list[tuple[int, ...]]:
    if arity == 1:
        return [(j,) for j in range(dof)]
    return [(i, j) for i in range(dof) for j in range(i + 1, dof)]


def is_named(term: Term) -> bool:
    """A named effect (not an open-ended symbolic term)."""
    return term.name in EFFECTS


def admissible(term: Term, coefficient: float) -> bool:
    """Whether a named effect's coefficient is physical (:meth:`Effect.admissible`);
    an open-ended generalized force has no sign to keep."""
    return EFFECTS[term.name].admissible(coefficient) if is_named(term) else True


def structural(term: Term, coefficient: float, stderr: float) -> dict:
    """The JSON entry of a residual that only an inadmissible coefficient
    explains: the declared form lacks this freedom. It names the term and the
    coefficient that would be needed; the term is not added to the model."""
    effect = EFFECTS[term.name]
    law = _law(term, effect.parameter)
    return {"name": term.name, "kind": "structural", "law": law, "joints": [j + 1 for j in term.joints],
            "parameters": {},
            "finding": (f"the declared form lacks this freedom: the residual is explained by {law} only with "
                        f"{effect.parameter} = {coefficient:.4g} ± {stderr:.2g}, which is not physical "
                        f"({effect.parameter} >= 0); the term is not added")}


def label(term: Term) -> str:
    """``"<effect or expression> on joint <j>"`` or ``"... on joints <i>-<j>"``,
    joints from 1, with a shaped effect's parameter (``stribeck (v_s=0.3)``)."""
    joints = [j + 1 for j in term.joints]
    where = f"joint {joints[0]}" if len(joints) == 1 else f"joints {'-'.join(map(str, joints))}"
    shape = f" ({EFFECTS[term.name].shaped}={term.shape:.4g})" if term.shape is not None else ""
    return f"{term.name}{shape} on {where}"


def kind(term: Term) -> str:
    """``conservative`` (a term of ``L``), ``dissipative`` (of ``D``) or
    ``force`` (a generalized force: an offset or an open-ended term)."""
    if term.rayleigh:
        return "dissipative"
    return "force" if term.is_force else "conservative"


def _law(term: Term, parameter: str, expr: sympy.Expr | None = None) -> str:
    """The text of a term's law with its parameter: ``L += ...``, ``D = ...``
    or ``tau += ...``; ``expr`` in place of the term's own expression."""
    where = {"conservative": "L += ", "dissipative": "D = "}.get(kind(term), "tau += ")
    return f"{where}{sympy.Symbol(parameter) * (term.expr if expr is None else expr)}"


def describe_all(terms: list[Term], coef, stderr, shape_stderr: dict[Term, float]) -> list[dict]:
    """The JSON entries of the accepted effects: a Stribeck hump and the
    Coulomb and viscous friction on its joint make one ``stribeck_friction``
    entry with ``F_c, F_s, v_s, b`` (``F_s``'s error from those of ``F_c`` and
    ``F_s - F_c`` as if independent; ``v_s``'s from ``shape_stderr``); every
    other effect is one entry (:func:`describe`)."""
    fits = {t: (float(c), float(s)) for t, c, s in zip(terms, coef, stderr)}
    humps = {t.joint: t for t in terms if t.shape is not None and t.name == "stribeck"}
    grouped = {t for t in terms if t.joint in humps and t.name in ("coulomb_friction", "viscous_friction", "stribeck")
               and len(t.joints) == 1}
    out = []
    for t in terms:
        if t in grouped:
            continue
        entry = describe(t, *fits[t])
        if t.shape is not None:  # a shaped law on its own: its shape is a parameter too, named in its law
            effect = EFFECTS[t.name]
            n = t.joint + 1
            q, qd = (sympy.Symbol(f"q_{n}", real=True),), (sympy.Symbol(f"qd_{n}", real=True),)
            entry["law"] = _law(t, effect.parameter, effect.expr(q, qd, sympy.Symbol(effect.shaped, positive=True)))
            entry["parameters"][effect.shaped] = {"value": float(t.shape),
                                                  "stderr": float(shape_stderr.get(t, float("nan")))}
            for key in ("joint", "coefficient", "stderr"):
                entry.pop(key, None)
        out.append(entry)
    for j, hump in sorted(humps.items()):
        def part(name):
            found = [t for t in grouped if t.name == name and t.joint == j]
            return fits[found[0]] if found else (0.0, 0.0)
        (F_c, se_c), (dF, se_d), (b, se_b) = part("coulomb_friction"), part("stribeck"), part("viscous_friction")
        n = j + 1
        law = (f"D = F_c*Abs(qd_{n}) + (F_s - F_c)*v_s*sqrt(pi)/2*erf(Abs(qd_{n})/v_s) + b*qd_{n}**2/2")
        out.append({"name": "stribeck_friction", "kind": "dissipative", "law": law, "joints": [n],
                    "parameters": {"F_c": {"value": F_c, "stderr": se_c},
                                   "F_s": {"value": F_c + dF, "stderr": float((se_c**2 + se_d**2) ** 0.5)},
                                   "v_s": {"value": float(hump.shape), "stderr": float(shape_stderr.get(hump, float("nan")))},
                                   "b": {"value": b, "stderr": se_b}}})
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
    law = _law(term, parameter)
    if named and EFFECTS[term.name].coefficient_of is not None:  # a tilt's coefficient is sin(alpha): report alpha
        coefficient, stderr = EFFECTS[term.name].parameter_from(coefficient, stderr)
        law = law.replace(parameter, str(EFFECTS[term.name].coefficient_of(sympy.Symbol(parameter))), 1)
    entry = {"name": term.name if named else "symbolic", "kind": kind(term), "law": law,
             "joints": [j + 1 for j in term.joints],
             "parameters": {parameter: {"value": float(coefficient), "stderr": float(stderr)}}}
    if len(term.joints) == 1:
        entry.update(joint=term.joints[0] + 1, coefficient=float(coefficient), stderr=float(stderr))
    if not named:
        entry["expression"] = term.name
    return entry
