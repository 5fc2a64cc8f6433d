"""How the undeclared-effects benchmark (:mod:`bench.studies.residual_acceptance`)
scores a residual loop's report against the effects that were put in.

* :func:`expected`: the laws put in, ``{(name, joints from 1): {parameter: value}}``,
  as the loop's JSON names them (the parts on one joint as their laws; a
  sensor's gains relative to the loop's reference joint);
* :func:`reported`: the laws a loop's JSON reports (findings are not laws);
* :func:`score`: per run, the laws put in that were found right (the right law
  on the right joints, each parameter within :data:`WITHIN`), the laws
  reported and how many of them were put in (:func:`put_in`: a simpler law
  the one put in contains counts as put in, an incomplete finding rather than
  a false one), and what each law put in was reported as (for the confusion
  table).

A gain is judged within :data:`GAIN_WITHIN` of itself: 10 % of ``g`` would
take any gain from 0.86 to 1.06 for 0.96, which says nothing about a
calibration. A periodic torque's ``N`` must be exact; its phase, like every
other parameter, within 10 % (a parameter put in as 0 is not judged).

Where the data do not pin a parameter to 10 %, no method can be right by
that rule, so a run also counts the laws found on their joints whose every
parameter is within 10 % *or* within :data:`CONSISTENT` of its reported
standard errors (``consistent``; ``N`` still exact): an estimate the data's
own precision cannot tell from the truth.
"""

from __future__ import annotations

from bench.physics.effects import EFFECTS
from bench.physics.laws import FAMILIES, LAWS, Part, group
from bench.physics.undeclared import GENERATOR_LAWS

#: a parameter is right within this share of its true value
WITHIN = 0.10
#: a torque sensor's gain is right within this share of its true value
GAIN_WITHIN = 0.01
#: a parameter off by more than :data:`WITHIN` is still consistent with its true value within this
#: many of its standard errors
CONSISTENT = 2.0
#: the kinds of a loop's JSON entries that are findings, not laws
FINDINGS = ("structural", "beyond_data", "not_identified")


def expected(effects: dict, dof: int, reference: int = 0) -> dict[tuple, dict[str, float]]:
    """``{(name, joints from 1): {parameter: value}}`` of the effects added (see
    the module docstring); ``reference`` is the loop's reference joint (0-based)
    for a sensor's gains."""
    out, on_joint = {}, {}
    for name, placed in effects.items():
        if name == "torque_gain":
            base = placed.get((reference,), 1.0)
            for (j,), g in placed.items():
                if j != reference and g / base != 1.0:
                    out[("torque_gain", (j + 1,))] = {"g": g / base}
            continue
        for joints, c in placed.items():
            if name in GENERATOR_LAWS:
                for part in GENERATOR_LAWS[name].parts(*c):
                    if part.coefficient:
                        on_joint.setdefault(joints[0], {})[part.name] = part
            elif len(joints) == 1 and name in FAMILIES:
                if c:
                    on_joint.setdefault(joints[0], {})[name] = Part(name, c)
            elif c:
                where = tuple(j + 1 for j in joints) or tuple(range(1, dof + 1))
                out[(name, where)] = {EFFECTS[name].parameter: c}
    for j, parts in on_joint.items():
        for law, members in group(parts):
            out[(law.name, (j + 1,))] = {k: v for k, (v, _) in law.parameters_of(members).items()}
    return out


def reported(effects: list[dict], what: str = "value") -> dict[tuple, dict[str, float]]:
    """The laws of a loop's JSON ``effects``, keyed as :func:`expected` keys
    them: their parameters' values, or (``what="stderr"``) standard errors."""
    return {(e["name"], tuple(e["joints"])): {k: p[what] for k, p in e["parameters"].items()}
            for e in effects if e["kind"] not in FINDINGS}


def error(name: str, parameter: str, got: float, want: float) -> float | None:
    """The relative error of one parameter (see the module docstring); ``None``
    where it is not judged (put in as 0)."""
    if name == "torque_gain":  # scaled so that GAIN_WITHIN counts as WITHIN
        return abs(got - want) / abs(want) * WITHIN / GAIN_WITHIN
    if parameter == "N":
        return 0.0 if got == want else float("inf")
    return abs(got - want) / abs(want) if want else None


def within(name: str, parameter: str, got: float, want: float, stderr: float) -> bool:
    """Whether one parameter is right (:func:`error`) or, ``N`` aside, within
    :data:`CONSISTENT` of its standard error ``stderr`` of its true value."""
    e = error(name, parameter, got, want)
    return e is None or e <= WITHIN or (parameter != "N" and abs(got - want) <= CONSISTENT * stderr)


def score(want: dict, found: dict, stderr: dict | None = None) -> dict:
    """One run's figures: ``right`` (laws put in and found right), ``put_in``,
    ``reported``, ``true_reported`` (reported laws that were put in, on their
    joints, whatever their parameters), ``worst_error`` (over the laws found on
    their joints), ``as`` (per law put in, what it was reported as) and
    ``consistent`` (laws right, or off only within their standard errors
    ``stderr``, keyed as ``found``; see the module docstring)."""
    errors, right, consistent, seen_as = [], 0, 0, {}
    for key, params in want.items():
        if key not in found:
            others = sorted(f"{n} j{'-'.join(map(str, j))}" for n, j in found if set(j) & set(key[1]))
            seen_as[key] = ", ".join(others) or "nothing"
            continue
        mine = [error(key[0], p, found[key].get(p, float("nan")), v) for p, v in params.items()]
        mine = [e for e in mine if e is not None]
        errors += mine
        ok = all(e <= WITHIN for e in mine)
        right += ok
        se = (stderr or {}).get(key, {})
        consistent += all(within(key[0], p, found[key].get(p, float("nan")), v, se.get(p, 0.0)) for p, v in params.items())
        tolerance = GAIN_WITHIN if key[0] == "torque_gain" else WITHIN
        seen_as[key] = key[0] if ok else f"{key[0]} (off by more than {tolerance:.0%})"
    true_reported = sum(put_in(key, want) for key in found)
    return {"right": right, "consistent": consistent, "put_in": len(want), "reported": len(found), "true_reported": true_reported,
            "worst_error": max(errors) if errors else None,
            "as": {f"{n} j{'-'.join(map(str, j))}": v for (n, j), v in seen_as.items()},
            "spurious": sorted(f"{n} j{'-'.join(map(str, j))}" for n, j in found if not put_in((n, j), want))}


def put_in(key: tuple, want: dict) -> bool:
    """Whether the reported law ``key`` was put in: the law itself on its joints,
    or a law it contains on the same joints (Coulomb friction where Coulomb plus
    viscous friction was put in: an incomplete finding, which recall counts,
    not a false one)."""
    name, joints = key
    return key in want or any(j == joints and name in contained(n) for n, j in want if n in LAWS.arm)


def contained(law: str) -> set[str]:
    """The laws ``law`` contains: its parts, its simpler laws, the parts its
    limits leave, and theirs in turn."""
    out, todo = set(), [law]
    while todo:
        entry = LAWS.arm[todo.pop()]
        found = set(entry.members) | set(entry.simpler) | {p for limits in entry.limits.values() for parts in limits
                                                           for p in parts}
        todo += [n for n in found - out if n in LAWS.arm]
        out |= found
    return out
