r"""The suite's one term-library type.

A model that is linear in its coefficients is a list of terms, each one
column of a design matrix. A term is either

* a **Lagrangian term** ``f(q, qd)``, a piece of ``L``: its value is ``f``
  and its torque is ``g(f)``, through the suite's one Euler–Lagrange transform
  (``g`` is linear in ``L``, so ``L = sum_k c_k f_k`` has the torque
  ``sum_k c_k g(f_k)``); or
* a **Rayleigh term** ``D(q, qd)``, a piece of the dissipation function:
  its torque is ``dD/dqd`` on every joint (viscous friction ``b qd_j^2 / 2``,
  Coulomb friction ``F |qd_j|``, a damper between two coordinates
  ``b (qd_i - qd_j)^2 / 2``). It has no value in ``L``; or
* a **generalized force** on one joint ``j``: an expression in
  ``q, qd, qdd`` (with ``sign`` and ``Abs`` allowed) that acts on joint
  ``j``'s torque directly, such as an offset. It has no value in ``L``.

A :class:`TermLibrary` is an ordered collection of terms; its
:meth:`~TermLibrary.design` gives their columns in an experiment's target:
``L`` (direct; Lagrangian terms only) or ``tau`` flattened sample-major
(indirect). Sparse regression's library, the residual loop's
effects and open-ended terms, and the DFKI filter study's rigid-body and
friction columns are all term libraries.
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import time
import weakref
from dataclasses import dataclass
from typing import Iterable, Iterator, Sequence

import numpy as np
import sympy

from bench.core import symbolic
from bench.core.data import Dataset
from bench.core.experiment import Experiment
from bench.core.kept import read_only
from bench.physics.dynamics import euler_lagrange_chunked
from bench.core.timeouts import Timeout


#: where a term acts, and what the loop's JSON calls that kind of term
PLACES = {"L": "conservative", "D": "dissipative", "force": "force", "sensor": "sensor"}


@dataclass(frozen=True)
class Term:
    """One column of a linear model: an expression and its place.

    Attributes
    ----------
    expr
        The term in the suite's symbols ``q_i, qd_i`` (and ``qdd_i`` for a
        generalized force).
    place
        ``"L"``: a piece of the Lagrangian; ``"D"``: a piece of the Rayleigh
        dissipation function, its torque ``dD/dqd``; ``"force"``: a
        generalized force on :attr:`joint`; ``"sensor"``: a law of the torque
        sensor (a gain, a time shift), in the measured torque's symbols
        ``tau_i``, whose column the residual loop computes from the model it
        corrects (:mod:`bench.residual.sensors`).
    name
        What reports call the term (an effect's name, say); ``str(expr)``
        when empty.
    joint
        The joint (0-based) a generalized force acts on, or the joint a term
        of ``L`` or ``D`` belongs to, where it belongs to one (an armature of
        joint ``j``).
    shape
        A nonlinear parameter fixed in ``expr`` (a Stribeck velocity), where
        the term has one; its coefficient stays linear.
    """

    expr: sympy.Expr
    place: str = "L"
    name: str = ""
    joint: int | None = None
    shape: float | None = None

    def __post_init__(self):
        if self.place not in PLACES:
            raise ValueError(f"a term's place is one of {', '.join(PLACES)}, got {self.place!r}")
        if self.place == "force" and self.joint is None:
            raise ValueError("a generalized force needs the joint it acts on")

    @classmethod
    def lagrangian(cls, expr, name: str = "", joint: int | None = None, shape: float | None = None) -> "Term":
        return cls(sympy.sympify(expr), "L", name, joint, shape)

    @classmethod
    def force(cls, expr, joint: int, name: str = "") -> "Term":
        return cls(sympy.sympify(expr), "force", name, int(joint))

    @classmethod
    def dissipation(cls, expr, name: str = "", joint: int | None = None, shape: float | None = None) -> "Term":
        """A Rayleigh term ``D(q, qd)``: torque ``dD/dqd``."""
        return cls(sympy.sympify(expr), "D", name, joint, shape)

    @property
    def in_lagrangian(self) -> bool:
        """Whether the term is a piece of ``L`` (it has a value there); a term
        of ``D`` or a generalized force acts on the torque only."""
        return self.place == "L"

    @property
    def kind(self) -> str:
        """``conservative``, ``dissipative`` or ``force``, by :attr:`place` (:data:`PLACES`)."""
        return PLACES[self.place]

    @functools.cached_property
    def takes_accelerations(self) -> bool:
        """Whether the term's torque may depend on ``qdd``: a term of ``L``
        whose expression uses a velocity (``d/dt dL/dqd`` then carries
        ``qdd``), a force that uses an acceleration, or a law of the sensor
        (whose column depends on the model it corrects). A potential, a
        term of ``D`` and a force of the state do not."""
        if self.place == "sensor":
            return True
        if self.place == "D":
            return False
        prefix = "qd_" if self.place == "L" else "qdd_"
        return any(str(s).startswith(prefix) for s in self.expr.free_symbols)

    @property
    def joints(self) -> tuple[int, ...]:
        """The joints (0-based) the term acts on: its :attr:`joint`, or else
        every coordinate its expression uses."""
        if self.joint is not None:
            return (self.joint,)
        found = {int(str(s).rpartition("_")[2]) - 1 for s in self.expr.free_symbols}
        return tuple(sorted(found))

    @property
    def label(self) -> str:
        return self.name or str(self.expr)

    def value(self, data: Dataset) -> np.ndarray:
        """The term's value in ``L`` at the states of ``data``, shape ``(n,)``
        (zero for a term of ``D`` or a generalized force)."""
        if not self.in_lagrangian:
            return np.zeros(len(data))
        return np.broadcast_to(_value_function(self.expr, data.dof)(data.q, data.qd), (len(data),)).astype(np.float64)

    def torque(self, data: Dataset, often: bool = False) -> np.ndarray:
        """The term's torque per unit coefficient, shape ``(n, dof)``. ``often``: a term of ``L`` asked for its
        torque again and again (a model's summed terms, at each step of a driven rollout) has its derivatives
        derived by sympy once (:class:`~bench.core.symbolic.SymbolicTangent`), which takes five times longer
        to compile than the term alone and half as long to evaluate as autograd's reverse passes."""
        if self.place == "D":
            out = np.zeros_like(data.q)
            for j, dD in _dissipative_forces(self.expr, data.dof):
                out[:, j] = _force_function(dD)(data)
            return out
        if self.place == "force":
            out = np.zeros_like(data.q)
            out[:, self.joint] = _force_function(self.expr)(data)
            return out
        if self.place == "sensor":
            raise ValueError(f"{self.label} is a law of the torque sensor: its column depends on the model it "
                             f"corrects (bench.residual.sensors), not on the data alone")
        t = data.tensors()
        compiled = (_tangent_function if often else _lagrangian_function)(self.expr, data.dof)
        return euler_lagrange_chunked(compiled, t["q"], t["qd"], t["qdd"])[0].numpy()

    def column(self, data: Dataset, experiment: str) -> np.ndarray:
        """The term's column in ``experiment``'s target: ``L`` (``(n,)``) or
        ``tau`` flattened sample-major (``(n * dof,)``); computed once per
        term and data set inside :func:`remembered_columns` (read-only then)."""
        experiment = Experiment.of(experiment)
        if not experiment.learns_torque and not self.in_lagrangian:
            raise ValueError(f"{self.label} acts on the torque only: it has no value in L (direct experiment)")
        kept = _REMEMBERED.get(data)
        if kept is not None and (self, experiment) in kept[1]:
            return kept[1][(self, experiment)]
        column = self.torque(data).ravel() if experiment.learns_torque else self.value(data)
        if kept is not None:
            kept[1][(self, experiment)] = read_only(column)
        return column


#: the data sets whose term columns are kept: ``{data: [users, {(term, experiment): column}]}``
_REMEMBERED: "weakref.WeakKeyDictionary[Dataset, list]" = weakref.WeakKeyDictionary()


@contextlib.contextmanager
def remembered_columns(*datasets: Dataset | None):
    """Within the block, each term's column on each of ``datasets`` is
    computed once (:meth:`Term.column`): the residual loop asks for the same
    columns of its library's terms in every step of every round. Blocks may
    nest; the columns are dropped when the outermost block of a data set ends."""
    held = [d for d in datasets if d is not None]
    for d in held:
        _REMEMBERED.setdefault(d, [0, {}])[0] += 1
    try:
        yield
    finally:
        for d in held:
            entry = _REMEMBERED.get(d)
            if entry is not None:
                entry[0] -= 1
                if entry[0] <= 0:
                    del _REMEMBERED[d]


def share_columns(data: Dataset, like: Dataset) -> bool:
    """Let ``data`` use the columns remembered for ``like`` (inside its
    :func:`remembered_columns` block), where the two hold the same states
    (the same ``q``, ``qd``, ``qdd`` and velocity sign arrays; a term's column
    depends on those only). Returns whether they are shared."""
    kept = _REMEMBERED.get(like)
    same = all(getattr(data, k) is getattr(like, k) for k in ("q", "qd", "qdd", "sign_qd"))
    if kept is None or not same:
        return False
    _REMEMBERED[data] = kept
    return True


def _tanh(expr: sympy.Expr) -> sympy.Expr:
    """``sinh(a)/cosh(a)`` as ``tanh(a)``: log cosh's derivative comes as the
    quotient, which overflows at large ``a`` (each ``sinh(a)`` is written
    ``tanh(a) cosh(a)``, and the ``cosh(a)`` cancel)."""
    return expr.subs({s: sympy.tanh(s.args[0]) * sympy.cosh(s.args[0]) for s in expr.atoms(sympy.sinh)})


@functools.lru_cache(maxsize=4096)
def _dissipative_forces(expr: sympy.Expr, dof: int) -> tuple[tuple[int, sympy.Expr], ...]:
    """``(j, dD/dqd_j)`` for each joint ``j`` on which the Rayleigh term ``expr``
    acts, derived once per expression: a model's torques are asked for at
    every step of a driven rollout."""
    out = []
    for j in range(dof):
        dD = _tanh(sympy.diff(expr, sympy.Symbol(f"qd_{j + 1}", real=True)))
        if dD != 0:
            out.append((j, dD))
    return tuple(out)


@functools.lru_cache(maxsize=4096)
def _lagrangian_function(expr: sympy.Expr, dof: int):
    """A Lagrangian term compiled to torch once per expression (see :func:`_dissipative_forces`)."""
    return symbolic.to_torch(expr, dof)


@functools.lru_cache(maxsize=256)
def _tangent_function(expr: sympy.Expr, dof: int):
    """A Lagrangian term compiled to torch with its derivatives once per expression
    (:class:`~bench.core.symbolic.SymbolicTangent`)."""
    return symbolic.SymbolicTangent(expr, dof)


@functools.lru_cache(maxsize=4096)
def _value_function(expr: sympy.Expr, dof: int):
    """A Lagrangian term's value compiled to numpy once per expression (see :func:`_dissipative_forces`)."""
    return symbolic.to_numpy(expr, dof)


@functools.lru_cache(maxsize=4096)
def _force_function(expr: sympy.Expr):
    """``f(data) -> (n,)`` for a generalized force, compiled once per expression
    over the symbols it uses (``q_i``, ``qd_i``, ``qdd_i``). Each
    ``sign(qd_i)`` is the data's :meth:`~bench.core.data.Dataset.velocity_sign`:
    on filtered recordings, the sign as the torque's low-pass saw it."""
    signs = {a: sympy.Symbol(f"sign_{a.args[0]}") for a in expr.atoms(sympy.sign)
             if a.args[0].is_Symbol and str(a.args[0]).startswith("qd_")}
    expr = expr.xreplace(signs)
    symbols = sorted(expr.free_symbols, key=str)
    columns = []
    for s in symbols:
        kind, _, index = str(s).rpartition("_")
        if kind not in ("q", "qd", "qdd", "sign_qd") or not index.isdigit():
            raise ValueError(f"a generalized force may use q_i, qd_i and qdd_i only, got {s}")
        columns.append((kind, int(index) - 1))
    raw = sympy.lambdify(symbols, expr, modules="numpy")

    def f(data: Dataset) -> np.ndarray:
        out = raw(*[(data.velocity_sign() if kind == "sign_qd" else getattr(data, kind))[:, i] for kind, i in columns])
        return np.broadcast_to(np.asarray(out, dtype=np.float64), (len(data),))

    return f


class TermLibrary(Sequence[Term]):
    """An ordered, immutable collection of terms."""

    def __init__(self, terms: Iterable[Term | sympy.Expr]):
        self.terms = tuple(t if isinstance(t, Term) else Term.lagrangian(t) for t in terms)

    @classmethod
    def of_lagrangian(cls, exprs: Iterable) -> "TermLibrary":
        return cls(Term.lagrangian(e) for e in exprs)

    def __getitem__(self, index):
        if isinstance(index, slice):
            return TermLibrary(self.terms[index])
        return self.terms[index]

    def __len__(self) -> int:
        return len(self.terms)

    def __iter__(self) -> Iterator[Term]:
        return iter(self.terms)

    def __add__(self, other: Iterable[Term]) -> "TermLibrary":
        return TermLibrary(self.terms + tuple(other))

    def __repr__(self) -> str:
        return f"TermLibrary({len(self)} terms)"

    @property
    def expressions(self) -> list[sympy.Expr]:
        return [t.expr for t in self.terms]

    def design(self, data: Dataset, experiment: str, deadline: float | None = None) -> np.ndarray:
        """The terms' columns in ``experiment``'s target.

        Shape ``(n, K)`` for direct, ``(n * dof, K)`` for indirect (rows
        ordered sample-major, like ``tau.ravel()``). Raises
        :class:`~bench.core.timeouts.Timeout` once ``time.perf_counter()``
        passes ``deadline``.
        """
        experiment = Experiment.of(experiment)
        cols = []
        for term in self.terms:
            if deadline is not None and time.perf_counter() > deadline:
                raise Timeout(f"design matrix: {len(cols)} of {len(self)} columns done")
            cols.append(term.column(data, experiment))
        rows = len(data) * experiment.rows(data.dof)
        return np.stack(cols, axis=1) if cols else np.zeros((rows, 0))

    def lagrangian(self, coef: Sequence[float]) -> sympy.Expr:
        """``sum_k c_k f_k`` over the Lagrangian terms with a nonzero coefficient."""
        if len(coef) != len(self):
            raise ValueError(f"{len(coef)} coefficients for {len(self)} terms")
        return sympy.Add(*[sympy.Float(float(c)) * t.expr for c, t in zip(coef, self.terms) if c != 0.0 and t.in_lagrangian])

    def summed(self, coef: Sequence[float]) -> list[Term]:
        """The terms at ``coef`` as one term per place (of ``L``, as :meth:`lagrangian`
        gives its expression; of ``D``) and per joint a generalized force acts on:
        the torque is linear in each term, so the sum's torque is the terms' at
        their coefficients."""
        groups: dict[tuple, sympy.Expr] = {}
        for term, c in zip(self.terms, coef):
            key = (term.place, term.joint if term.place == "force" else None)
            groups[key] = groups.get(key, sympy.Integer(0)) + sympy.Float(float(c)) * term.expr
        return [Term(expr, place, "summed", joint) for (place, joint), expr in groups.items()]


def lagrangian_library_size(dof: int, kinds: tuple[str, ...]) -> int:
    """The number of terms of :func:`lagrangian_library`, without building it."""
    n_angle = sum(k == "angle" for k in kinds)
    n_linear = dof - n_angle
    positions = 1 + 2 * n_angle + n_angle * (n_angle - 1) + n_linear * (2 + 2 * n_angle)
    velocities = 1 + dof + dof * (dof + 1) // 2
    return positions * velocities


def _positions(dof: int, kinds: tuple[str, ...]) -> list[sympy.Expr]:
    q, _ = symbolic.coordinate_symbols(dof)
    angles = [q[i] for i in range(dof) if kinds[i] == "angle"]
    linear = [q[i] for i in range(dof) if kinds[i] == "linear"]
    positions = [sympy.Integer(1)]
    for a in angles:
        positions += [sympy.sin(a), sympy.cos(a)]
    for a, b in itertools.combinations(angles, 2):
        positions += [sympy.sin(a - b), sympy.cos(a - b)]
    for x in linear:
        positions += [x, x**2]
        for a in angles:
            positions += [x * sympy.sin(a), x * sympy.cos(a)]
    return positions


def lagrangian_library(dof: int, kinds: tuple[str, ...], velocity_degrees: tuple[int, ...] = (0, 1, 2)) -> TermLibrary:
    """Lagrangian terms generic in coordinates of the given kinds, simplest first:
    every product ``v * p`` of a position term ``p`` (1; ``sin q_i``,
    ``cos q_i`` of every angle; ``sin(q_i - q_j)``, ``cos(q_i - q_j)`` of
    every pair of angles; ``q_k``, ``q_k^2`` of every linear coordinate and
    ``q_k sin q_i``, ``q_k cos q_i`` with an angle) and a velocity term ``v``
    of a degree in ``velocity_degrees`` (1; ``qd_i``; ``qd_i qd_j``)."""
    _, qd = symbolic.coordinate_symbols(dof)
    by_degree = {0: [sympy.Integer(1)], 1: list(qd), 2: [qd[i] * qd[j] for i in range(dof) for j in range(i, dof)]}
    velocities = [v for d in velocity_degrees for v in by_degree[d]]
    return TermLibrary.of_lagrangian(v * p for v in velocities for p in _positions(dof, kinds))
