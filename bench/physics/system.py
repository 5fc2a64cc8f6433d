"""The :class:`System` abstraction: a physical system that carries its truth.

A system knows its degrees of freedom, coordinate names, physical parameters
(a dataclass), the true Lagrangian as a sympy expression (compiled to a
batched torch function), a sampling domain, a hook for non-conservative
generalized forces, and the parametric form that system identification fits.

Adding a system means writing one subclass in ``systems/`` and registering
it with ``@SYSTEMS.add(name, *tags)``; ``systems/single_pendulum.py`` is the
smallest example. The contract lives in the core, below ``methods/``,
because methods read a system's declared parametric form and coordinate
kinds.

Systems given by an engine
--------------------------
A system whose dynamics come from a rigid-body engine (a robot arm loaded
from its URDF through Pinocchio, ``systems/urdf_arm.py``) has no sympy
Lagrangian: it sets :attr:`System.symbolic` to ``False``, gives its torques
and ``L = T - V`` by overriding :meth:`System.torque` and
:meth:`System.lagrangian`, and offers SysId a :class:`LinearForm`, the
torque and energy regressors linear in its inertial parameters, instead of a
:class:`ParametricForm`.

Sign convention for non-conservative effects
--------------------------------------------
The data's torque is ``tau = g(L)(q, qd, qdd) + nonconservative_torque(q, qd, qdd)``:
the effect's torque is *added* to the rigid-body torque. Viscous friction
``b * qd`` therefore has a positive coefficient ``b``.
"""

from __future__ import annotations

import abc
import dataclasses
import itertools
import math
from dataclasses import dataclass
from functools import cached_property
from types import SimpleNamespace
from typing import Callable, ClassVar, Sequence

import numpy as np
import sympy
import torch

from bench.core.experiment import EXPERIMENTS
from bench.core import symbolic
from bench.physics.dynamics import euler_lagrange_chunked
from bench.core.errors import ConfigError, DataError
from bench.core.registry import Registry

#: the parts of a Lagrangian's torque, as :meth:`System.forces` gives them
FORCES = ("inertial", "coriolis", "gravity")

HALF_PI = math.pi / 2


@dataclass(frozen=True)
class Domain:
    """Independent uniform sampling ranges for q, qd and qdd.

    Each of ``q``, ``qd``, ``qdd`` is one ``(low, high)`` pair for every
    coordinate, or a tuple of pairs, one per coordinate (a spring's length
    must stay positive while an angle swings). The paper samples every
    component from U(-pi/2, pi/2); the authors' public code used (-pi, pi).
    """

    q: tuple = (-HALF_PI, HALF_PI)
    qd: tuple = (-HALF_PI, HALF_PI)
    qdd: tuple = (-HALF_PI, HALF_PI)

    @classmethod
    def symmetric(cls, half_width: float) -> "Domain":
        r = (-float(half_width), float(half_width))
        return cls(q=r, qd=r, qdd=r)

    def __post_init__(self):
        for name in ("q", "qd", "qdd"):
            for lo, hi in self._pairs(name):
                if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                    raise ValueError(f"domain.{name} must be finite (low, high) pairs with low < high, got {(lo, hi)}")

    def _pairs(self, name: str) -> list[tuple[float, float]]:
        value = getattr(self, name)
        if len(value) == 2 and all(isinstance(v, (int, float)) for v in value):
            return [tuple(map(float, value))]
        return [tuple(map(float, pair)) for pair in value]

    def bounds(self, name: str, dof: int) -> tuple[np.ndarray, np.ndarray]:
        """``(low, high)`` arrays of length ``dof`` for ``q``, ``qd`` or ``qdd``."""
        pairs = self._pairs(name)
        if len(pairs) == 1:
            pairs = pairs * dof
        if len(pairs) != dof:
            raise ValueError(f"domain.{name} has {len(pairs)} ranges for {dof} coordinates")
        lo, hi = zip(*pairs)
        return np.asarray(lo), np.asarray(hi)


@dataclass(frozen=True)
class ParametricForm:
    """A Lagrangian with unknown parameters, for system identification.

    Attributes
    ----------
    expr
        Sympy expression in ``q_i, qd_i`` and the ``unknowns``.
    unknowns
        The parameter symbols to identify, in output order.
    true_values
        The values the unknowns take in the simulated system (``None`` for
        measured systems, where the truth is not known).
    dof
        Degrees of freedom.
    """

    expr: sympy.Expr
    unknowns: tuple[sympy.Symbol, ...]
    dof: int
    true_values: tuple[float, ...] | None = None

    @cached_property
    def torch_fn(self):
        """``f(q, qd, theta) -> L`` with ``theta`` of shape ``(len(unknowns),)``."""
        return symbolic.to_torch(self.expr, self.dof, self.unknowns)

    def substitute(self, values: Sequence[float]) -> sympy.Expr:
        return self.expr.subs(dict(zip(self.unknowns, map(sympy.Float, values))))


@dataclass(frozen=True)
class LinearForm:
    """A model linear in its parameters ``pi``: ``tau = Y(q, qd, qdd) pi`` and
    ``L = Y_L(q, qd) pi`` (the kinetic minus the potential energy regressor).

    Attributes
    ----------
    names
        The parameters, in the order of the regressors' columns.
    torque_regressor
        ``(q, qd, qdd) -> (n, dof, p)`` for arrays of shape ``(n, dof)``.
    lagrangian_regressor
        ``(q, qd) -> (n, p)``.
    true_values
        The parameters of the simulated system (``None`` where unknown).
    bodies
        How many rigid bodies' 10 inertial parameters (Pinocchio's order,
        :mod:`bench.physics.feasible`) are the first columns; ``0`` for a form
        whose parameters are not a rigid body's.
    prior
        The parameters' nominal values (an arm's URDF), which a feasible fit
        falls back on where the data do not decide; ``None`` where none are known.
    terms
        Further columns after the regressors' (:meth:`with_terms`): terms of
        the suite's term library (:class:`~bench.physics.terms.Term`), such as
        joint friction, each with one coefficient; the regressors above do
        not give them, :func:`bench.physics.linear.torque_regressor` does.
    dynamics
        ``(pi, q, qd) -> (M, c)`` with ``Y(q, qd, qdd) pi = M qdd + c``, for
        the regressors' columns at parameters ``pi``, from an engine that
        computes them faster than the regressor at ``dof + 1`` accelerations
        (an arm's rigid-body algorithms); ``None`` where there is none.
    """

    names: tuple[str, ...]
    dof: int
    torque_regressor: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
    lagrangian_regressor: Callable[[np.ndarray, np.ndarray], np.ndarray]
    true_values: tuple[float, ...] | None = None
    bodies: int = 0
    prior: tuple[float, ...] | None = None
    terms: tuple = ()
    dynamics: Callable | None = None

    def with_terms(self, terms, names) -> "LinearForm":
        """The form with ``terms`` as further columns, named ``names``."""
        return dataclasses.replace(self, names=self.names + tuple(names), terms=self.terms + tuple(terms),
                                   true_values=None if self.true_values is None else self.true_values + (0.0,) * len(terms))

    def full_prior(self) -> np.ndarray | None:
        """:attr:`prior` with a zero for each of :attr:`terms` (``None`` without a prior)."""
        return None if self.prior is None else np.concatenate([self.prior, np.zeros(len(self.terms))])


#: how far past its position limits, as a share of the joint's range, a log's q may go (:meth:`System.check_positions`)
LIMIT_SLACK = 0.1


class System(abc.ABC):
    """Base class of every system in the suite.

    Subclasses set ``coordinates`` and ``Params`` and write
    :meth:`lagrangian_expr`. Everything else is derived: the sympy Lagrangian
    with the numeric parameters, its batched torch function, and the default
    parametric form (the true expression with ``sysid_unknowns`` left free).

    Parameters
    ----------
    params
        An instance of ``Params``; the defaults when omitted.
    domain
        The sampling domain; :attr:`default_domain` when omitted.
    split
        Which of :attr:`splits` a measured system's :meth:`load` gives; the
        first when omitted.
    """

    name: ClassVar[str] = "unnamed"
    tags: ClassVar[frozenset[str]] = frozenset()
    coordinates: ClassVar[tuple[str, ...]] = ()
    #: "angle" or "linear" per coordinate (libraries use trigonometric terms of
    #: angles and polynomials of linear coordinates); all angles if empty
    coordinate_kinds: ClassVar[tuple[str, ...]] = ()
    #: whether the coordinates are absolute angles of the links (from one fixed
    #: direction), so that a joint between links i and j turns by ``q_i - q_j``
    #: and a spring or damper there acts on that difference; joint angles that
    #: are already relative (a robot's, DFKI's ``q2_relative``) are not
    absolute_angles: ClassVar[bool] = False
    #: whether the system is a planar chain of links hanging from a fixed pivot,
    #: angles from the downward vertical, with gravity in its plane, so that a
    #: gravity direction that is off (:meth:`tilt_direction`) and, given
    #: :attr:`link_lengths`, a payload at its tip (:meth:`tip_position`) can be
    #: placed on it (:mod:`bench.physics.effects`)
    planar_chain: ClassVar[bool] = False
    #: the ``Params`` fields of a planar chain's link lengths, base first;
    #: empty where they are not known
    link_lengths: ClassVar[tuple[str, ...]] = ()
    Params: ClassVar[type] = type(None)
    sysid_unknowns: ClassVar[tuple[str, ...]] = ()
    default_domain: ClassVar[Domain] = Domain()
    #: ``False`` for measured systems, which cannot generate data; they
    #: provide :meth:`load` instead, and their Lagrangian is unknown
    simulated: ClassVar[bool] = True
    #: the names of the train and test splits a measured system offers, its
    #: default first; an instance is made for one (``split``, ``--split`` on
    #: the command line), which its :meth:`load` gives. A system with one
    #: split offers ``("default",)``
    splits: ClassVar[tuple[str, ...]] = ("default",)
    #: the experiments the system's data allow (measured trajectories have no L)
    experiments: ClassVar[tuple[str, ...]] = EXPERIMENTS
    #: why an experiment missing from ``experiments`` does not apply
    not_applicable: ClassVar[str] = ""
    #: a published figure to read the tables against (printed above them)
    reference: ClassVar[str] = ""
    #: what the system is in a few words, for the README's list of systems, and in a sentence or a few, for its
    #: row of docs/methods_and_systems.md: both generated from the registry (:mod:`bench.reporting.docs`)
    title: ClassVar[str] = ""
    summary: ClassVar[str] = ""
    #: ``False`` for a system given by an engine: no sympy Lagrangian exists
    #: (see the module docstring), so no expression can be judged exact
    symbolic: ClassVar[bool] = True
    #: each coordinate's position limits ``(lower, upper)``, where the system declares them (an arm's URDF)
    position_limits: ClassVar[tuple[tuple[float, float], ...] | None] = None
    #: a system without an arm's rigid bodies: the name of a system that declares the same robot as an arm
    #: (a ``measured:`` file with its description), which commands that need an arm name (``bench select``)
    as_arm: ClassVar[str | None] = None

    def __init__(self, params=None, domain: Domain | None = None, split: str | None = None):
        self.params = params if params is not None else self.Params()
        if not isinstance(self.params, self.Params):
            raise TypeError(f"{self.name}: params must be a {self.Params.__name__}")
        self.domain = domain if domain is not None else self.default_domain
        if split is not None and split not in self.splits:
            raise ConfigError(f"system {self.name} has no split {split!r}; it offers {', '.join(self.splits)}")
        self.split = split if split is not None else self.splits[0]

    # -- what a subclass writes -------------------------------------------------
    @abc.abstractmethod
    def lagrangian_expr(self, q: Sequence[sympy.Symbol], qd: Sequence[sympy.Symbol], p) -> sympy.Expr:
        """The Lagrangian in the symbols ``q``, ``qd`` with parameters ``p``.

        ``p`` has one attribute per field of ``Params``; each is a number for the
        true Lagrangian, or a sympy symbol for the parametric form.
        """

    def check_positions(self, data, margin: float = LIMIT_SLACK) -> None:
        """A :class:`DataError` naming the file, the joint, the range of q seen
        and the limits where ``data``'s positions leave the system's position
        limits by more than ``margin`` of the joint's range (a log in degrees
        leaves them by far); nothing for a system without limits."""
        if self.position_limits is None or data is None or not len(data):
            return
        for j, ((lo, hi), name) in enumerate(zip(self.position_limits, self.coordinates)):
            slack = margin * (hi - lo)
            seen = (float(np.min(data.q[:, j])), float(np.max(data.q[:, j])))
            if seen[0] < lo - slack or seen[1] > hi + slack:
                raise DataError(f"{data.source}: joint {j + 1} ({name}) has q from {seen[0]:.4g} to {seen[1]:.4g}, "
                                f"outside its limits [{lo:.4g}, {hi:.4g}] by more than {margin:.0%} of its range: is the "
                                f"log in degrees? (--ignore-limits fits it anyway)")

    @classmethod
    def listing(cls) -> str:
        """What ``bench list`` says of the system's data beyond its kind (a measured system's recordings)."""
        return ""

    @classmethod
    def source_files(cls) -> list[str]:
        """The files outside the code that define the system (its robot
        description, its measured-arm file); none for a system given by code."""
        return []

    def load(self, part: str):
        """The ``"train"`` or ``"test"`` part of a measured system's data (of
        the instance's :attr:`split` where it offers several)."""
        raise NotImplementedError(f"{self.name} is simulated: generate its data with bench.core.data.generate")

    def logged_torque(self, part: str):
        """The torque of :meth:`load`'s ``part`` as logged, before any filter,
        at the same samples; ``None`` where the data have no filter (a
        simulated system's)."""
        return None

    def nonconservative_torque(self, q: torch.Tensor, qd: torch.Tensor, qdd: torch.Tensor) -> torch.Tensor | None:
        """Torque added to ``g(L)`` by non-conservative effects (``None``: none)."""
        return None

    # -- derived -----------------------------------------------------------------
    def link_angles(self, q: Sequence) -> list:
        """A planar chain's link angles from the vertical, given its
        coordinates ``q``: the coordinates themselves where they are absolute
        angles, else their running sums (the same map takes velocities to the
        links' angular velocities)."""
        return list(q) if self.absolute_angles else list(itertools.accumulate(q))

    def link_length_values(self) -> list[sympy.Float]:
        """A planar chain's link lengths (:attr:`link_lengths`) at the system's parameters."""
        if not (self.planar_chain and self.link_lengths):
            raise ValueError(f"{self.name} does not give a planar chain's link lengths")
        return [sympy.Float(getattr(self.params, n)) for n in self.link_lengths]

    def tip_position(self, q: Sequence[sympy.Symbol]) -> tuple[sympy.Expr, sympy.Expr]:
        """The end of a planar chain's last link, ``(x, y)`` with ``y`` up and
        the pivot at the origin, at the system's link lengths."""
        lengths, angles = self.link_length_values(), self.link_angles(q)
        return (sum(l * sympy.sin(a) for l, a in zip(lengths, angles)),
                -sum(l * sympy.cos(a) for l, a in zip(lengths, angles)))

    def tilt_direction(self) -> tuple[int, ...]:
        """How the coordinates change when the whole planar chain turns about
        its pivot by a unit angle: every absolute angle, or only the base
        joint's where the others are relative."""
        if not self.planar_chain:
            raise ValueError(f"{self.name} is not a planar chain")
        return (1,) * self.dof if self.absolute_angles else (1,) + (0,) * (self.dof - 1)

    @property
    def dof(self) -> int:
        return len(self.coordinates)

    @property
    def symbols(self):
        return symbolic.coordinate_symbols(self.dof)

    @property
    def kinds(self) -> tuple[str, ...]:
        kinds = self.coordinate_kinds or ("angle",) * self.dof
        if len(kinds) != self.dof or set(kinds) - {"angle", "linear"}:
            raise ValueError(f"{self.name}: coordinate_kinds must give 'angle' or 'linear' for each coordinate")
        return tuple(kinds)

    def scaled_domain(self, half_width: float) -> Domain:
        """The domain with angles, velocities and accelerations in U(-w, w);
        linear coordinates keep their own ranges."""
        w = (-float(half_width), float(half_width))
        lo, hi = self.domain.bounds("q", self.dof)
        q = tuple(w if kind == "angle" else (a, b) for kind, a, b in zip(self.kinds, lo, hi))
        return Domain(q=q, qd=w, qdd=w)

    def param_dict(self) -> dict[str, float]:
        return {f.name: float(getattr(self.params, f.name)) for f in dataclasses.fields(self.params)}

    @cached_property
    def lagrangian_sympy(self) -> sympy.Expr:
        """The true Lagrangian with the numeric parameters substituted."""
        q, qd = self.symbols
        p = SimpleNamespace(**{k: sympy.Float(v) for k, v in self.param_dict().items()})
        return sympy.expand(self.lagrangian_expr(q, qd, p))

    @cached_property
    def _lagrangian_torch(self):
        return symbolic.to_torch(self.lagrangian_sympy, self.dof)

    def lagrangian(self, q: torch.Tensor, qd: torch.Tensor) -> torch.Tensor:
        """The true Lagrangian, batched: ``(batch, dof) x 2 -> (batch,)``."""
        return self._lagrangian_torch(q, qd)

    def torque(self, q: torch.Tensor, qd: torch.Tensor, qdd: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The system's torque ``g(L) + nonconservative_torque`` and ``L``, batched."""
        tau, L = euler_lagrange_chunked(self.lagrangian, q, qd, qdd)
        extra = self.nonconservative_torque(q, qd, qdd)
        return (tau if extra is None else tau + extra), L

    def forces(self, data) -> dict[str, np.ndarray] | None:
        """The parts of the true Lagrangian's torque at the states of ``data``
        (a :class:`~bench.core.data.Dataset`): ``inertial`` ``M(q) qdd``,
        ``coriolis`` ``c(q, qd)`` and ``gravity`` ``g(q)``, each ``(n, dof)``
        (:data:`FORCES`); ``None`` where they are not known (a measured
        system that does not ship them). Non-conservative forces are in
        none of them."""
        if not self.simulated:
            return None

        def conservative(qd, qdd):
            q, qd, qdd = (torch.from_numpy(np.ascontiguousarray(x, dtype=np.float64)) for x in (data.q, qd, qdd))
            tau, _ = self.torque(q, qd, qdd)
            extra = self.nonconservative_torque(q, qd, qdd)
            return (tau if extra is None else tau - extra).numpy()

        zero = np.zeros_like(data.q)
        gravity = conservative(zero, zero)
        return {"inertial": conservative(zero, data.qdd) - gravity, "coriolis": conservative(data.qd, zero) - gravity,
                "gravity": gravity}

    def forward_dynamics(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """Unforced accelerations ``(n, dof)`` from an engine-backed system's own
        forward dynamics; symbolic systems have none (the rollout derives the
        motion from the torques)."""
        raise NotImplementedError(f"{self.name} is symbolic: its motion follows from its torques")

    def linear_form(self) -> LinearForm | None:
        """The form SysId fits by least squares, for a system linear in its
        parameters (an engine-backed arm); ``None`` for the others, which give
        :meth:`parametric_form`."""
        return None

    def parametric_form(self) -> ParametricForm:
        """The form SysId fits: the true expression with ``sysid_unknowns`` free."""
        if not self.symbolic:
            raise NotImplementedError(f"system {self.name!r} has no symbolic form; SysId uses its linear_form()")
        if not self.sysid_unknowns:
            raise NotImplementedError(f"system {self.name!r} declares no parametric form for SysId")
        q, qd = self.symbols
        values = self.param_dict()
        unknown_syms = tuple(sympy.Symbol(n, real=True) for n in self.sysid_unknowns)
        fields = {k: sympy.Float(v) for k, v in values.items()}
        fields.update({s.name: s for s in unknown_syms})
        expr = sympy.expand(self.lagrangian_expr(q, qd, SimpleNamespace(**fields)))
        return ParametricForm(
            expr=expr,
            unknowns=unknown_syms,
            dof=self.dof,
            true_values=tuple(values[n] for n in self.sysid_unknowns) if self.simulated else None,
        )

    def describe(self) -> dict:
        return {
            "name": self.name,
            "dof": self.dof,
            "coordinates": list(self.coordinates),
            "params": self.param_dict(),
            "domain": dataclasses.asdict(self.domain),
        }

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.params!r}, {self.domain!r})"


SYSTEMS: Registry[type[System]] = Registry("system")


def get_system(name: str, **kwargs) -> System:
    """Instantiate the registered system ``name``."""
    return SYSTEMS[name](**kwargs)
