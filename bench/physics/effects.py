"""Effects a rigid-body model lacks, defined once for the data generator
(which adds them, undeclared) and the residual loop (which finds them).

Each effect has one coefficient and acts on one joint or, for the coupled
ones, on a pair of coordinates ``i, j`` through their difference. Its torque
is *added* to the rigid-body torque ``g(L)``, so friction coefficients are
positive. An effect is a :class:`~bench.physics.terms.Term` in one of three
places, which the loop's JSON names by the kind of effect:

* ``L``, **conservative**: a term of the Lagrangian, its torque through the
  Euler–Lagrange transform;
* ``D``, **dissipative**: a term of the Rayleigh dissipation function ``D``,
  its torque ``dD/dqd``; physically admissible only with a coefficient >= 0;
* ``force``: a generalized force that is neither (a constant offset: a
  sensor or cable bias).

Effects are the parts of physical laws (:mod:`bench.physics.laws`): a law is
one effect, or several on one joint (Coulomb plus viscous friction; the
Stribeck law).

=====================  =============  ========================================  ===================================
name                   kind           term per unit coefficient                 torque
=====================  =============  ========================================  ===================================
``viscous_friction``   dissipative    ``D = qd_j^2 / 2``                        ``b qd_j`` on joint j
``coulomb_friction``   dissipative    ``D = |qd_j|``                            ``F sign(qd_j)`` on joint j
``armature``           conservative   ``L += qd_j^2 / 2`` (rotor inertia)       ``I qdd_j`` on joint j
``spring``             conservative   ``L += -q_j^2 / 2`` (potential)           ``k q_j`` on joint j
``offset``             force          ``c`` on joint j                          ``c`` on joint j
``coupled_spring``     conservative   ``L += -(q_i - q_j)^2 / 2``               ``k (q_i - q_j)`` on i, minus on j
``coupled_damper``     dissipative    ``D = (qd_i - qd_j)^2 / 2``               ``b (qd_i - qd_j)`` on i, minus on j
``smooth_coulomb``     dissipative    ``D = v_s log cosh(qd_j / v_s)``          ``F_c tanh(qd_j / v_s)``
``stribeck_hump``      dissipative    ``D = v_s sqrt(pi)/2 erf(|qd_j| / v_s)``  ``dF exp(-(qd_j/v_s)^2) sign(qd_j)``
``periodic_sin``       conservative   ``L += cos(N q_j) / N``                   ``a sin(N q_j)``
``periodic_cos``       conservative   ``L += -sin(N q_j) / N``                  ``b cos(N q_j)``
=====================  =============  ========================================  ===================================

``smooth_coulomb`` is Coulomb friction that reaches its level over a
velocity ``v_s`` (a recording's low-pass filter, or a real drive's
compliance, rounds the sign function off); ``stribeck_hump`` is the hump
of Stribeck friction at low speed, its velocity ``v_s`` fixed in the term
(:attr:`~bench.physics.terms.Term.shape`) and its coefficient ``dF = F_s - F_c``.
With Coulomb and viscous friction on the same joint it makes the Stribeck
law (:attr:`bench.physics.laws.LAWS.arm <bench.physics.laws.Laws.arm>`)::

    tau = (F_c + (F_s - F_c) exp(-(qd / v_s)^2)) sign(qd) + b qd,

which is physical with ``F_s >= F_c >= 0``, ``v_s > 0`` and ``b >= 0``.

Three effects act between the arm's torque and the measured one, not on the
arm's Lagrangian (place ``sensor``; the residual loop's
:mod:`bench.residual.sensors` finds them, and the data generator adds them
after every other effect, the load-dependent friction before the gain):

=================  ======  ==================================================
name               kind    what is measured
=================  ======  ==================================================
``load_friction``  drive   ``tau_j + mu_j |tau_j| sign(qd_j)``: a Coulomb
                           level that grows with the load the joint's drive
                           carries, ``tau_j`` the arm's torque on it
``torque_gain``    sensor  ``g_j tau_j``: joint ``j``'s torque sensor reads
                           ``g_j`` times the torque (a calibration error)
``time_shift``     sensor  ``tau(t - delta)``: the torque lags the recorded
                           state by ``delta`` seconds (a sensor's or filter's
                           delay); it needs a recording's time stamps
=================  ======  ==================================================

Load-dependent friction is the friction of a gear whose contact forces, and
so its Coulomb level, grow with the torque it transmits (Bittencourt &
Gunnarsson, "Static friction in a robot joint: modeling and identification
of load and temperature effects", J. Dyn. Syst. Meas. Control 134(5), 2012).
It is the drive's efficiency read as a torque: the measured torque is
``(1 + mu)`` times the load where the drive moves it (``tau qd > 0``) and
``(1 - mu)`` times where the load drives the joint back. It is admissible
for ``0 <= mu <= 0.5``: a drive that loses at most half the torque it
carries; a residual that asks for more, or for a negative ``mu``, is
something else the model lacks, and a finding. Its simpler limit is no law
(``mu = 0``); a Coulomb level that does not grow with the load is the
``coulomb_friction`` beside it.

``periodic_sin`` and ``periodic_cos`` are the two parts of a torque that
repeats ``N`` times a revolution of its joint (a motor's cogging torque, a
drive's position ripple): ``A sin(N q + phi) = a sin(N q) + b cos(N q)``
with ``a = A cos(phi)``, ``b = A sin(phi)``. It depends on the position only,
so it is the force of a potential; ``N`` is a whole number, the
:attr:`Effect.grid` the loop searches, and is not refined.

On absolute angles, ``q_i - q_j`` is the relative angle of the joint
between links ``i`` and ``j``: an elbow spring or damper is one coupled
effect with one coefficient, not a spring on each joint and cross terms.

Two effects belong to a whole planar chain (:attr:`System.planar_chain
<bench.physics.system.System.planar_chain>`) and are built from the system's
own geometry and declared Lagrangian, at its parameters:

=================  ============  ===========================================================
name               kind          term per unit coefficient
=================  ============  ===========================================================
``tip_payload``    conservative  ``L += |v_tip|^2 / 2 - g y_tip``: a point mass ``m`` at the
                                 end of the last link (:meth:`System.tip_position`)
``gravity_tilt``   conservative  ``L += -sum_j s_j dL/dq_j``: gravity turned by ``alpha``
                                 in the plane, coefficient ``sin(alpha)`` (``s`` the base
                                 rotation, :meth:`System.tilt_direction`)
=================  ============  ===========================================================

A payload is physical with ``m >= 0`` (its mass matrix, ``m J^T J``, is
positive semi-definite). The tilt's term is what the residual loop fits:
turning gravity by ``alpha`` changes each gravity term ``c cos(a)`` into
``c cos(a - alpha) = c cos(alpha) cos(a) + c sin(alpha) sin(a)``, so the
term's coefficient is ``sin(alpha)`` and the loop reports ``alpha``; the
``cos(alpha)`` rescaling of the gravity terms is one a fitted model already
has (a mass or a length). The data generator adds the exact tilt,
``L(q - alpha s, qd) - L(q, qd)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
import sympy

from bench.core.data import Dataset
from bench.core.errors import ConfigError
from bench.core.names import is_name
from bench.physics.terms import PLACES, Term


@dataclass(frozen=True)
class Effect:
    """One kind of effect.

    Attributes
    ----------
    expr
        ``expr(q, qd) -> sympy``: the term per unit coefficient, given the
        symbols of the effect's coordinates (one, or a pair ``i, j``).
    place
        Where its term acts (:attr:`Term.place <bench.physics.terms.Term.place>`):
        ``L`` (conservative), ``D`` (dissipative) or ``force`` (a generalized
        force on the joint).
    parameter
        The coefficient's name in reports (``b``, ``k``, ...).
    nonnegative
        Whether only a coefficient >= 0 is physical: dissipation cannot
        produce energy, and a rotor inertia or a passive spring's stiffness
        is not negative. An offset may have either sign.
    shaped
        The name of a nonlinear parameter the term needs (``v_s``), given
        to :meth:`term` and to ``expr`` as a third argument; ``None`` if none.
    """

    name: str
    expr: Callable[[tuple, tuple], sympy.Expr]
    place: str
    parameter: str
    formula: str
    arity: int = 1
    nonnegative: bool = True
    shaped: str | None = None
    #: for a shaped effect, ``numeric(q_j, qd_j, shape, sign_j)``: its torque on its joint per unit
    #: coefficient, in numpy, with ``sign_j`` the data's sign of ``qd_j``
    #: (:meth:`~bench.core.data.Dataset.velocity_sign`; a search over the shape evaluates it often;
    #: tested equal to the term's)
    numeric: Callable | None = None
    #: for an effect of the whole system (``arity`` 0), ``on_system(system, q, qd)``: its term per
    #: unit coefficient in the system's symbols; ``expr`` is then unused
    on_system: Callable | None = None
    #: where the linear coefficient is a function of the reported parameter
    #: (a tilt's is ``sin(alpha)``): that function, of a sympy symbol
    coefficient_of: Callable | None = None
    #: whether an effect of the whole system needs the chain's link lengths (a payload does)
    needs_link_lengths: bool = False
    #: for the data generator, ``exact(system, value)``: the effect's exact term at ``value``
    #: (coefficient 1), where the term the loop fits is only its part linear in a coefficient
    exact: Callable | None = None
    #: where only a range of coefficients is physical (a sensor's gain correction): ``(low, high)``
    bounds: tuple[float, float] | None = None
    #: for a shaped effect whose shape takes only some values (a whole number of periods a
    #: revolution): those values, which the loop tries each and does not refine; ``None`` for a
    #: shape on a continuous scale
    grid: tuple | None = None

    def parameter_from(self, coefficient: float, stderr: float) -> tuple[float, float]:
        """The reported parameter and its standard error, from the fitted
        linear coefficient's (through :attr:`coefficient_of`, by the delta method)."""
        if self.coefficient_of is None:
            return coefficient, stderr
        x = sympy.Symbol("x")
        f = self.coefficient_of(x)
        try:
            value = float(sympy.nsolve(f - coefficient, x, 0.0))
        except (ValueError, ZeroDivisionError):  # no parameter gives this coefficient (a sine above 1)
            return math.nan, math.inf
        slope = float(sympy.diff(f, x).subs(x, value))
        return value, abs(stderr / slope) if slope else math.inf

    @property
    def sensor(self) -> bool:
        """Whether the effect is a law of the torque sensor or the drive
        (:mod:`bench.residual.sensors`), which acts on the measured torque
        rather than on the arm's Lagrangian."""
        return self.place == "sensor"

    def applies_to(self, system) -> bool:
        """Whether the effect can be placed on ``system`` (a payload needs the
        chain's link lengths); every per-joint effect can."""
        if self.on_system is None:
            return True
        return system is not None and system.planar_chain and (not self.needs_link_lengths or bool(system.link_lengths))

    def require(self, system) -> None:
        """A clear :class:`ConfigError` where the effect cannot be placed on ``system``."""
        if not self.applies_to(system):
            raise ConfigError(f"{self.name} needs a planar chain that gives its geometry; "
                              f"{getattr(system, 'name', system)} does not")

    def admissible(self, coefficient: float) -> bool:
        """Whether ``coefficient`` is physical for this effect."""
        if self.bounds is not None:
            return self.bounds[0] <= coefficient <= self.bounds[1]
        return coefficient >= 0 or not self.nonnegative

    @property
    def condition(self) -> str:
        """What :meth:`admissible` asks, in words (``""`` where any coefficient is)."""
        if self.bounds is not None:
            return f"{self.bounds[0]:g} <= {self.parameter} <= {self.bounds[1]:g}"
        return f"{self.parameter} >= 0" if self.nonnegative else ""

    @property
    def conservative(self) -> bool:
        return self.place == "L"

    @property
    def kind(self) -> str:
        """``conservative``, ``dissipative`` or ``force``: the JSON's word for its place."""
        return PLACES[self.place]

    def numeric_torque(self, data: Dataset, joint: int, shape: float) -> np.ndarray:
        """A shaped effect's torque on ``joint`` per unit coefficient at
        ``shape``, ``(n, dof)``, by :attr:`numeric` (what :meth:`term`'s
        torque is, without building and compiling a term for each value)."""
        out = np.zeros((len(data), data.dof))
        out[:, joint] = self.numeric(data.q[:, joint], data.qd[:, joint], shape, data.velocity_sign()[:, joint])
        return out

    def term(self, *joints: int, shape: float | None = None, system=None) -> Term:
        """The effect on ``joints`` (0-based; two for a coupled effect, none
        for an effect of the whole ``system``) as a term; ``shape`` is the
        value of its nonlinear parameter, if it has one."""
        if self.on_system is not None:
            self.require(system)
            return Term.lagrangian(sympy.expand(self.on_system(system, *system.symbols)), self.name)
        if len(joints) != self.arity or len(set(joints)) != len(joints):
            raise ValueError(f"{self.name} acts on {self.arity} distinct joint(s), got {joints}")
        if (shape is None) != (self.shaped is None) or (shape is not None and not shape > 0):
            raise ValueError(f"{self.name} needs {'a positive ' + self.shaped if self.shaped else 'no shape'}, got {shape}")
        q = tuple(sympy.Symbol(f"q_{j + 1}", real=True) for j in joints)
        qd = tuple(sympy.Symbol(f"qd_{j + 1}", real=True) for j in joints)
        if shape is not None and self.grid is not None and shape != int(shape):
            raise ValueError(f"{self.name} needs a whole number {self.shaped}, got {shape}")
        value = None if shape is None else sympy.Integer(int(shape)) if self.grid is not None else sympy.Float(shape)
        expr = sympy.sympify(self.expr(q, qd) if shape is None else self.expr(q, qd, value))
        joint = joints[0] if self.arity == 1 else None
        return Term(expr, self.place, self.name, joint, shape)


EFFECTS: dict[str, Effect] = {
    e.name: e
    for e in (
        Effect("viscous_friction", lambda q, qd: qd[0] ** 2 / 2, "D", "b", "b·qd (D = b·qd²/2)"),
        Effect("coulomb_friction", lambda q, qd: sympy.Abs(qd[0]), "D", "F_c", "F_c·sign(qd) (D = F_c·|qd|)"),
        Effect("armature", lambda q, qd: qd[0] ** 2 / 2, "L", "I", "I·qdd (L += I·qd²/2)"),
        Effect("spring", lambda q, qd: -(q[0] ** 2) / 2, "L", "k", "k·q (L −= k·q²/2)"),
        Effect("offset", lambda q, qd: sympy.Integer(1), "force", "tau_0", "tau_0", nonnegative=False),
        Effect("coupled_spring", lambda q, qd: -((q[0] - q[1]) ** 2) / 2, "L", "k",
               "k·(q_i − q_j) on i, −k·(q_i − q_j) on j (L −= k·(q_i − q_j)²/2)", 2),
        Effect("coupled_damper", lambda q, qd: (qd[0] - qd[1]) ** 2 / 2, "D", "b",
               "b·(qd_i − qd_j) on i, −b·(qd_i − qd_j) on j (D = b·(qd_i − qd_j)²/2)", 2),
        Effect("smooth_coulomb", lambda q, qd, v: v * sympy.log(sympy.cosh(qd[0] / v)), "D", "F_c",
               "F_c·tanh(qd/v_s) (D = F_c·v_s·log cosh(qd/v_s))", shaped="v_s",
               numeric=lambda q, qd, v, sign: np.tanh(qd / v)),
        Effect("stribeck_hump", lambda q, qd, v: v * sympy.sqrt(sympy.pi) / 2 * sympy.erf(sympy.Abs(qd[0]) / v), "D",
               "dF", "dF·exp(−(qd/v_s)²)·sign(qd) (D = dF·v_s·√π/2·erf(|qd|/v_s))", shaped="v_s",
               numeric=lambda q, qd, v, sign: np.exp(-((qd / v) ** 2)) * sign),
        Effect("periodic_sin", lambda q, qd, N: sympy.cos(N * q[0]) / N, "L", "a",
               "a·sin(N·q) (L += a·cos(N·q)/N)", nonnegative=False, shaped="N",
               numeric=lambda q, qd, N, sign: np.sin(N * q), grid=tuple(range(1, 13))),
        Effect("periodic_cos", lambda q, qd, N: -sympy.sin(N * q[0]) / N, "L", "b",
               "b·cos(N·q) (L −= b·sin(N·q)/N)", nonnegative=False, shaped="N",
               numeric=lambda q, qd, N, sign: np.cos(N * q), grid=tuple(range(1, 13))),
        Effect("tip_payload", None, "L", "m", "a point mass m at the tip (L += m·(|v_tip|²/2 − g·y_tip))",
               arity=0, on_system=lambda system, q, qd: _payload(system, q, qd), needs_link_lengths=True),
        Effect("gravity_tilt", None, "L", "alpha",
               "gravity turned by alpha in the plane (L += sin(alpha)·(−Σ s_j·∂L/∂q_j))",
               arity=0, nonnegative=False, on_system=lambda system, q, qd: _tilt(system, q, qd),
               coefficient_of=sympy.sin, exact=lambda system, alpha: tilted(system, alpha)),
    )
}

def register_effect(effect: Effect) -> Effect:
    """Add ``effect`` to :data:`EFFECTS`, where the data generator and the residual loop's library finds it; a
    name another effect has taken is refused (the same effect again is kept). A law of the joint is declared
    through :meth:`bench.physics.laws.Laws.declare`, which registers its effect here."""
    known = EFFECTS.get(effect.name)
    if not is_name(effect.name) or (known is not None and known != effect):
        raise ValueError(f"an effect needs a name of its own (letters, digits, _), got {effect.name!r}")
    EFFECTS[effect.name] = effect
    return effect


def _payload(system, q, qd) -> sympy.Expr:
    """``|v_tip|^2 / 2 - g y_tip``: the Lagrangian of a unit point mass at the
    chain's tip. With link angles ``a_j`` (the coordinates, or their running
    sums for relative joints) and lengths ``l_j``,
    ``|v_tip|^2 = sum_jk l_j l_k a_j' a_k' cos(a_j - a_k)``."""
    angles, rates, lengths = system.link_angles(q), system.link_angles(qd), system.link_length_values()
    n = len(angles)
    speed2 = sum(lengths[j] * lengths[k] * rates[j] * rates[k] * (1 if j == k else sympy.cos(angles[j] - angles[k]))
                 for j in range(n) for k in range(n))
    return speed2 / 2 - sympy.Float(system.params.g) * system.tip_position(q)[1]


def _tilt(system, q, qd) -> sympy.Expr:
    """``-sum_j s_j dL/dq_j``: the first-order change of the declared ``L``
    when gravity turns by a unit angle in the plane."""
    return -sum(s * sympy.diff(system.lagrangian_sympy, a) for s, a in zip(system.tilt_direction(), q))


def tilted(system, alpha: float) -> Term:
    """The exact change of the declared Lagrangian when gravity turns by
    ``alpha`` in the plane: ``L(q - alpha s, qd) - L(q, qd)`` (for the data generator)."""
    q, _ = system.symbols
    L = system.lagrangian_sympy
    shifted = L.subs({a: a - sympy.Float(alpha) * s for a, s in zip(q, system.tilt_direction())}, simultaneous=True)
    return Term.lagrangian(sympy.expand(shifted - L), "gravity_tilt")
