r"""Physical laws on one joint, each made of the effects of
:mod:`bench.physics.effects` (its *parts*), with its parameters, its
admissibility and the simpler laws it contains as limits.

Every law is in the suite's one registry, :data:`LAWS` (:class:`Laws`): these,
the arm's, and the sensor's and the drive's (:mod:`bench.physics.sensor_laws`).
The data generator adds laws (``bench data --effects``); the residual loop
reports what it found as laws, one per physical family and joint, and
replaces a law by a simpler one it contains where the data do not identify
the difference (:func:`bench.residual.pruning.simplest_laws`).

======================================  ========  ====================  =====================================
law                                     family    parameters            contains as limits
======================================  ========  ====================  =====================================
``viscous_friction``                    friction  ``b``
``coulomb_friction``                    friction  ``F_c``
``coulomb_viscous_friction``            friction  ``F_c, b``            Coulomb (``b = 0``), viscous
                                                                        (``F_c = 0``)
``stribeck_friction``                   friction  ``F_c, F_s, v_s, b``  Coulomb plus viscous (``F_s = F_c``,
                                                                        or ``v_s -> 0``); as ``v_s -> inf``
                                                                        the hump is Coulomb friction of
                                                                        level ``F_s - F_c``
``smooth_coulomb``                      friction  ``F_c, v_s, b``       Coulomb plus viscous (``v_s -> 0``),
                                                                        viscous with ``b + F_c / v_s``
                                                                        (``v_s -> inf``)
``armature``                            inertia   ``I``
``spring``                              spring    ``k``
``offset``                              offset    ``tau_0``
``offset_spring``                       spring    ``k, q0``             a spring (``q0 = 0``); it is a spring
                                                                        plus a torque offset ``-k q0``, which
                                                                        torques cannot tell apart
``periodic_torque``                     periodic  ``A, N, phi``         its sine part alone (``phi = 0``)
======================================  ========  ====================  =====================================

``periodic_torque`` is ``tau = A sin(N q + phi)`` on its joint: a motor's
cogging torque, or a gear's or a drive's position ripple, ``N`` times a
revolution (the cogging torque of a permanent-magnet motor has the period of
the least common multiple of its slots and poles: Jahns & Soong, "Pulsating
torque minimization techniques for permanent magnet AC motor drives", IEEE
Trans. Ind. Electron. 43(2), 1996). Its parts are ``a sin(N q)`` and
``b cos(N q)`` (:mod:`bench.physics.effects`), ``A = sqrt(a^2 + b^2)`` and
``phi = atan2(b, a)``, ``phi`` in ``(-pi, pi]``. A spring and an offset are
what it looks like on a joint that moves over a small part of one period,
so the loop offers it only for the ``N`` whose period the joint's recorded
range covers (:func:`bench.residual.library.resolved_periods`).

A law's :attr:`~Law.limits` say, for each of its shaped parts (a Stribeck
hump, a smoothed Coulomb term), which parts replace it in each limit, the
shape going to zero first and to infinity second; a part already on the
joint is not added twice. The one-parameter laws are the
named effects themselves, and what the loop's JSON reports for them is unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Callable, Mapping

from bench.core.names import is_name
from bench.physics.effects import EFFECTS, Effect, register_effect

#: which parts belong to which physical family: a joint carries at most one law of each (filled as laws register:
#: a part's family is that of the first law it is a member of)
FAMILIES: dict[str, str] = {}


@dataclass(frozen=True)
class Part:
    """An effect of a law on its joint: the effect's name, its coefficient,
    its shape (where the effect has one), and their standard errors."""

    name: str
    coefficient: float
    shape: float | None = None
    stderr: float = 0.0
    shape_stderr: float = 0.0


@dataclass(frozen=True)
class Law:
    """A named physical law on one joint; see the module docstring.

    ``required`` parts must all be on the joint, ``optional`` ones may be;
    ``parts(*parameters)`` gives the law's parts at its parameters (for the
    data generator), ``parameters_of(parts)`` the parameters and their
    standard errors from the fitted parts (``{name: Part}``, missing optional
    parts counting as zero). ``law`` is the text of its ``D``, ``L`` or
    torque, ``{n}`` standing for the joint's number.
    """

    name: str
    family: str
    parameters: tuple[str, ...]
    law: str
    kind: str
    required: tuple[str, ...]
    optional: tuple[str, ...] = ()
    admissible: Callable[..., bool] = lambda *p: True
    #: the admissibility condition in words
    condition: str = ""
    parts: Callable[..., list[Part]] | None = None
    parameters_of: Callable[[dict], dict] | None = None
    limits: dict[str, tuple[tuple[str, ...], ...]] = field(default_factory=dict)
    simpler: tuple[str, ...] = ()
    #: optional parts without which the law is not itself: a Stribeck law without its Coulomb
    #: level is a hump on its own, whose parameter F_c = 0 the data did not identify
    essential: tuple[str, ...] = ()

    @property
    def members(self) -> tuple[str, ...]:
        return self.required + self.optional

    @property
    def composite(self) -> bool:
        """Whether the law has more than one part, or a shaped one: its JSON
        entry is then the law's, with its parts listed (a one-parameter law's
        entry is its effect's)."""
        return len(self.members) > 1 or bool(self.limits)

    def text(self, joint: int) -> str:
        """The law's text on ``joint`` (0-based)."""
        return self.law.format(n=joint + 1)

    def check(self, values: tuple[float, ...]) -> bool:
        return len(values) == len(self.parameters) and all(map(math.isfinite, values)) and self.admissible(*values)


def _value(part: Part | None) -> tuple[float, float]:
    return (0.0, 0.0) if part is None else (part.coefficient, part.stderr)


def _stribeck(parts: dict) -> dict:
    (F_c, se_c), (dF, se_d), (b, se_b) = (_value(parts.get(n)) for n in
                                          ("coulomb_friction", "stribeck_hump", "viscous_friction"))
    hump = parts["stribeck_hump"]
    return {"F_c": (F_c, se_c), "F_s": (F_c + dF, math.hypot(se_c, se_d)), "v_s": (hump.shape, hump.shape_stderr),
            "b": (b, se_b)}


def _smooth(parts: dict) -> dict:
    s = parts["smooth_coulomb"]
    return {"F_c": (s.coefficient, s.stderr), "v_s": (s.shape, s.shape_stderr), "b": _value(parts.get("viscous_friction"))}


def _offset_spring(parts: dict) -> dict:
    (k, se_k), (t, se_t) = _value(parts["spring"]), _value(parts["offset"])
    q0 = -t / k if k else math.nan
    # the delta method, the two coefficients taken as independent
    se = math.hypot(se_t / k, t * se_k / k**2) if k else math.inf
    return {"k": (k, se_k), "q0": (q0, se)}


def _periodic(parts: dict) -> dict:
    (a, se_a), (b, se_b) = _value(parts.get("periodic_sin")), _value(parts.get("periodic_cos"))
    N = next(p.shape for p in parts.values() if p is not None)
    A = math.hypot(a, b)
    # the delta method, the two coefficients taken as independent
    se_A = math.hypot(a * se_a, b * se_b) / A if A else math.inf
    se_phi = math.hypot(b * se_a, a * se_b) / A**2 if A else math.inf
    return {"A": (A, se_A), "N": (float(N), 0.0), "phi": (math.atan2(b, a), se_phi)}


def _single(name: str, family: str) -> Law:
    effect = EFFECTS[name]
    return Law(name, family, (effect.parameter,), "", effect.kind, (name,),
               admissible=lambda c: effect.admissible(c), condition=effect.condition,
               parts=lambda c: [Part(name, c)],
               parameters_of=lambda parts: {effect.parameter: _value(parts[name])})


class Laws:
    """The suite's one registry of laws, by name: the arm's laws on one joint
    (:class:`Law`, :attr:`arm`) and the laws between the arm's torque and the
    measured one (:class:`~bench.physics.sensor_laws.SensorLaw` classes,
    :attr:`sensor`, registered by :mod:`bench.physics.sensor_laws` and by
    plugins). A name names one law of either place; the order is the order
    of registration, in which the loop offers them."""

    def __init__(self):
        self._arm: dict[str, Law] = {}
        self._sensor: dict[str, type] = {}

    def register(self, law):
        """Add ``law`` (a :class:`Law`, or a sensor law's class); a name another
        law has taken is refused, but the same class registered again (a plugin
        file imported twice) takes its place. Returns ``law``, so that it serves
        as a class decorator."""
        place = self._arm if isinstance(law, Law) else self._sensor
        known = self._arm.get(law.name) or self._sensor.get(law.name)
        again = isinstance(law, type) and isinstance(known, type) and \
            (known.__module__, known.__qualname__) == (law.__module__, law.__qualname__)
        if not law.name or (known is not None and not again):
            raise ValueError(f"a law needs a name of its own, got {law.name!r}")
        place[law.name] = law
        if isinstance(law, Law):
            for part in law.members:
                FAMILIES.setdefault(part, law.family)
        return law

    def declare(self, effect: Effect, family: str) -> Law:
        """A law of the joint made of one effect, declared at once: ``effect`` (a term per unit coefficient on
        one joint, :class:`~bench.physics.effects.Effect`) goes into :data:`~bench.physics.effects.EFFECTS`,
        where the data generator (``bench data --effects``) and the residual loop's library finds it, and
        its law into :attr:`arm` under ``family`` (a joint carries at most one law of each family). The
        built-in one-effect laws are declared so, and a plugin's law of the joint the same way
        (docs/extending.md); a declared name is refused again unless it is the same effect."""
        if effect.arity != 1 or effect.sensor or effect.on_system is not None:
            raise ValueError(f"{effect.name}: a law of the joint is one effect on one joint of the arm")
        if not is_name(family):
            raise ValueError(f"{effect.name}: a law's family is a name (letters, digits, _), got {family!r}")
        known = self._arm.get(effect.name)
        if known is not None and EFFECTS.get(effect.name) is effect and known.family == family:
            return known
        if effect.name in self._arm or effect.name in self._sensor:
            raise ValueError(f"a law needs a name of its own, got {effect.name!r}")
        register_effect(effect)
        return self.register(_single(effect.name, family))

    def remove(self, name: str) -> None:
        """Take the law ``name`` out, with the effect and the family a declared law brought (a test's plugin,
        once the test is done)."""
        law = self._arm.pop(name, None)
        if self._sensor.pop(name, None) is not None and name in EFFECTS and EFFECTS[name].sensor:
            EFFECTS.pop(name)  # the effect a sensor law's class brought
        if law is not None and law.members == (name,) and not any(name in other.members for other in self._arm.values()):
            FAMILIES.pop(name, None)
            if name in EFFECTS and not EFFECTS[name].sensor:
                EFFECTS.pop(name)

    @property
    def arm(self) -> Mapping[str, Law]:
        """The arm's laws on one joint, by name."""
        return MappingProxyType(self._arm)

    @property
    def sensor(self) -> Mapping[str, type]:
        """The laws of the sensor and the drive, by name, in the order the loop offers them."""
        return MappingProxyType(self._sensor)


#: every law of the suite, by name (see :class:`Laws`)
LAWS = Laws()
FAMILIES["offset"] = "offset"  # a torque offset is a family of its own, also where it is part of a spring's law
# in the order the loop offers them: friction, then inertia, springs and offsets, then periodic torques
for _name, _family in (("viscous_friction", "friction"), ("coulomb_friction", "friction")):
    LAWS.declare(EFFECTS[_name], _family)
for _law in (
        Law("coulomb_viscous_friction", "friction", ("F_c", "b"), "D = F_c*Abs(qd_{n}) + b*qd_{n}**2/2", "dissipative",
            ("coulomb_friction", "viscous_friction"), admissible=lambda F_c, b: F_c >= 0 and b >= 0, condition="F_c >= 0, b >= 0",
            parts=lambda F_c, b: [Part("coulomb_friction", F_c), Part("viscous_friction", b)],
            parameters_of=lambda p: {"F_c": _value(p["coulomb_friction"]), "b": _value(p["viscous_friction"])},
            simpler=("coulomb_friction", "viscous_friction")),
        Law("stribeck_friction", "friction", ("F_c", "F_s", "v_s", "b"),
            "D = F_c*Abs(qd_{n}) + (F_s - F_c)*v_s*sqrt(pi)/2*erf(Abs(qd_{n})/v_s) + b*qd_{n}**2/2", "dissipative",
            ("stribeck_hump",), ("coulomb_friction", "viscous_friction"),
            admissible=lambda F_c, F_s, v_s, b: F_s >= F_c >= 0 and v_s > 0 and b >= 0,
            condition="F_s >= F_c >= 0, v_s > 0, b >= 0",
            parts=lambda F_c, F_s, v_s, b: [Part("coulomb_friction", F_c), Part("stribeck_hump", F_s - F_c, v_s),
                                            Part("viscous_friction", b)],
            parameters_of=_stribeck, limits={"stribeck_hump": ((), ("coulomb_friction",))},
            simpler=("coulomb_viscous_friction",), essential=("coulomb_friction",)),
        Law("smooth_coulomb", "friction", ("F_c", "v_s", "b"), "D = F_c*v_s*log(cosh(qd_{n}/v_s)) + b*qd_{n}**2/2",
            "dissipative", ("smooth_coulomb",), ("viscous_friction",),
            admissible=lambda F_c, v_s, b: F_c >= 0 and v_s > 0 and b >= 0, condition="F_c >= 0, v_s > 0, b >= 0",
            parts=lambda F_c, v_s, b: [Part("smooth_coulomb", F_c, v_s), Part("viscous_friction", b)],
            parameters_of=_smooth, limits={"smooth_coulomb": (("coulomb_friction",), ("viscous_friction",))},
            simpler=("coulomb_viscous_friction", "viscous_friction")),
):
    LAWS.register(_law)
for _name, _family in (("armature", "inertia"), ("spring", "spring"), ("offset", "offset")):
    LAWS.declare(EFFECTS[_name], _family)
for _law in (
        Law("offset_spring", "spring", ("k", "q0"), "L += -k*(q_{n} - q0)**2/2", "conservative", ("spring", "offset"),
            admissible=lambda k, q0: k >= 0, condition="k >= 0", parts=lambda k, q0: [Part("spring", k), Part("offset", -k * q0)],
            parameters_of=_offset_spring, simpler=("spring",)),
        Law("periodic_torque", "periodic", ("A", "N", "phi"), "tau += A*sin(N*q_{n} + phi)", "conservative",
            ("periodic_sin",), ("periodic_cos",), admissible=lambda A, N, phi: A >= 0 and N >= 1 and N == int(N),
            condition="A >= 0, N a whole number >= 1",
            parts=lambda A, N, phi: [Part("periodic_sin", A * math.cos(phi), N), Part("periodic_cos", A * math.sin(phi), N)],
            parameters_of=_periodic),
):
    LAWS.register(_law)


def led_by(part: str) -> Law | None:
    """The law whose one required part is the shaped ``part`` (a Stribeck hump
    leads the Stribeck law, a sine part the periodic torque), or ``None``."""
    for law in LAWS.arm.values():
        if law.required == (part,) and EFFECTS[part].shaped is not None:
            return law
    return None


def part_of(part: str) -> Law:
    """The law ``part`` stands for where it is the only part of its law left:
    the law it leads, its own one-parameter law, or else the law it is a part of
    (a periodic torque's cosine part alone)."""
    return led_by(part) or LAWS.arm.get(part) or next(law for law in LAWS.arm.values() if part in law.members)


def group(parts: dict[str, Part]) -> list[tuple[Law, dict[str, Part]]]:
    """One joint's parts as laws: repeatedly the law that takes the most of the
    parts left, all of its required ones among them; a part no law takes is
    its own one-parameter law (or, for a shaped part, the law it leads)."""
    left, out = dict(parts), []
    while left:
        fits = [(len(set(law.members) & set(left)), law) for law in LAWS.arm.values() if set(law.required) <= set(left)]
        if not fits:
            name = next(iter(left))
            law = part_of(name)
            out.append((law, {name: left.pop(name)}))
            continue
        _, law = max(fits, key=lambda f: f[0])
        out.append((law, {n: left.pop(n) for n in law.members if n in left}))
    return out


def one_law_per_family(names: set[str]) -> bool:
    """Whether the parts ``names`` on one joint make at most one law of each family."""
    families = [law.family for law, _ in group({n: Part(n, 1.0) for n in names})]
    return len(families) == len(set(families))
