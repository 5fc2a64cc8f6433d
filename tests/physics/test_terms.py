"""The term library: Lagrangian terms through the Euler-Lagrange transform,
generalized forces on one joint, and design matrices in either experiment."""

from __future__ import annotations

import numpy as np
import pytest
import sympy

from bench.core import symbolic
from bench.core.data import Dataset, generate
from bench.physics.terms import Term, TermLibrary
from bench.evaluation.recovery import euler_lagrange_symbolic
from systems import get_system


@pytest.fixture(scope="module")
def data():
    return generate(get_system("double_pendulum"), 300, 7)


def test_a_lagrangian_terms_torque_is_its_symbolic_euler_lagrange_image(data):
    (q1, q2), (v1, v2) = symbolic.coordinate_symbols(2)
    term = Term.lagrangian(v1 * v2 * sympy.cos(q1 - q2))
    qdd = symbolic.acceleration_symbols(2)
    images = euler_lagrange_symbolic(term.expr, 2)
    for j, image in enumerate(images):
        f = sympy.lambdify([q1, q2, v1, v2, *qdd], image, "numpy")
        np.testing.assert_allclose(term.torque(data)[:, j], f(*data.q.T, *data.qd.T, *data.qdd.T), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(term.value(data), data.qd[:, 0] * data.qd[:, 1] * np.cos(data.q[:, 0] - data.q[:, 1]))


def test_a_generalized_force_acts_on_its_joint_only(data):
    _, (v1, v2) = symbolic.coordinate_symbols(2)
    term = Term.force(sympy.sign(v2) * sympy.Abs(v1), 1, "stiction")
    tau = term.torque(data)
    np.testing.assert_array_equal(tau[:, 1], np.sign(data.qd[:, 1]) * np.abs(data.qd[:, 0]))
    assert not tau[:, 0].any() and term.label == "stiction" and term.joint == 1
    assert not term.value(data).any()
    with pytest.raises(ValueError, match="no value in L"):
        term.column(data, "direct")
    with pytest.raises(ValueError, match="q_i, qd_i and qdd_i only"):
        Term.force(sympy.Symbol("x"), 0).torque(data)


def test_design_matrices_in_either_experiment(data):
    (q1, _), (v1, v2) = symbolic.coordinate_symbols(2)
    library = TermLibrary.of_lagrangian([v1**2, sympy.cos(q1)]) + [Term.force(v2, 1)]
    assert len(library) == 3 and library.expressions[2] == v2 and isinstance(library[:2], TermLibrary)
    F = library.design(data, "indirect")
    assert F.shape == (600, 3)
    np.testing.assert_allclose(F[:, 0].reshape(300, 2)[:, 0], 2 * data.qdd[:, 0], rtol=1e-12)
    np.testing.assert_array_equal(F[:, 2].reshape(300, 2), np.column_stack([np.zeros(300), data.qd[:, 1]]))
    direct = library[:2].design(data, "direct")
    np.testing.assert_allclose(direct, np.column_stack([data.qd[:, 0] ** 2, np.cos(data.q[:, 0])]))
    # the Lagrangian of fitted coefficients leaves out zeros and generalized forces
    assert library.lagrangian([2.0, 0.0, 5.0]) == sympy.Float(2.0) * v1**2
    with pytest.raises(ValueError, match="2 coefficients for 3 terms"):
        library.lagrangian([1.0, 2.0])


def test_remembered_columns_are_computed_once_read_only_and_dropped_with_the_outermost_block(data, monkeypatch):
    from bench.physics import terms

    term = Term.lagrangian(sympy.Symbol("qd_1", real=True) ** 2 / 2)
    calls = []
    torque = Term.torque
    monkeypatch.setattr(Term, "torque", lambda self, d: calls.append(1) or torque(self, d))
    with terms.remembered_columns(data):
        first = term.column(data, "indirect")
        with terms.remembered_columns(data):
            assert term.column(data, "indirect") is first
        assert term.column(data, "indirect") is first and len(calls) == 1
        with pytest.raises(ValueError, match="read-only"):
            first[0] = 1.0
    term.column(data, "indirect")
    assert len(calls) == 2 and data not in terms._REMEMBERED


def test_smoothed_coulomb_friction_stays_finite_far_beyond_its_velocity(data):
    from bench.physics.effects import EFFECTS

    tau = EFFECTS["smooth_coulomb"].term(0, shape=1e-3).torque(data)  # qd / v_s up to about 1500: cosh overflows
    np.testing.assert_allclose(tau[:, 0], np.tanh(data.qd[:, 0] / 1e-3), rtol=0, atol=1e-15)


def _terms_of_every_effect(system) -> list[Term]:
    from bench.physics.effects import EFFECTS
    out = []
    for effect in EFFECTS.values():
        if effect.sensor:
            continue
        shape = None if effect.shaped is None else (3 if effect.grid is not None else 0.2)
        joints = () if effect.on_system is not None else tuple(range(effect.arity))
        out.append(effect.term(*joints, shape=shape, system=system))
    return out


def test_a_term_takes_accelerations_exactly_where_its_torque_depends_on_them(data):
    """Checked on the torque itself: the same states at zero and at random
    accelerations give the same torque where the term says it takes none."""
    system = get_system("double_pendulum")
    still = Dataset(data.q, data.qd, np.zeros_like(data.qdd), data.tau)
    (q1, _), (v1, _) = symbolic.coordinate_symbols(2)
    terms = _terms_of_every_effect(system) + [Term.force(symbolic.acceleration_symbols(2)[1] * v1, 0, "inertial"),
                                              Term.force(sympy.sign(v1) * q1, 1, "state")]
    taking = {t.label for t in terms if t.takes_accelerations}
    assert {"armature", "tip_payload", "inertial"} <= taking
    assert not taking & {"spring", "offset", "viscous_friction", "coulomb_friction", "periodic_sin", "state"}
    for term in terms:
        moved = np.abs(term.torque(data) - term.torque(still)).max()
        assert (moved > 1e-6) == term.takes_accelerations, term.label


def test_a_loop_models_mass_matrix_and_bias_are_those_of_its_torque(data, monkeypatch):
    """Its effects of the state alone are asked once a state, the others at
    dof + 1 accelerations; the sum is what the torque's own decomposition
    (``dof + 1`` torques a state) gives, and it predicts the torque."""
    from bench.evaluation.rollout import TrueModel
    from bench.physics.models import FittedModel
    from bench.residual.model import LoopModel
    system = get_system("double_pendulum")
    terms = _terms_of_every_effect(system)
    coef = np.linspace(0.1, 0.5, len(terms))
    model = LoopModel(TrueModel(system), terms, coef, np.zeros(len(terms)))
    asked, torque = [], Term.torque
    monkeypatch.setattr(Term, "torque", lambda self, d, often=False: asked.append((self.place, len(d))) or torque(self, d, often))
    M, c = model.mass_and_bias(data.q, data.qd)
    monkeypatch.undo()
    n = len(data)  # one transform of L for the effects of the state alone, one at dof + 1 accelerations for the rest
    assert sorted(asked) == [("D", n), ("L", n), ("L", 3 * n), ("force", n)]
    M_all, c_all = FittedModel.mass_and_bias(model, data.q, data.qd)
    np.testing.assert_allclose(M, M_all, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(c, c_all, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", M, data.qdd) + c, model.predict_torque(data), rtol=1e-10, atol=1e-10)
    assert not np.allclose(M, FittedModel.mass_and_bias(TrueModel(system), data.q, data.qd)[0])  # the armature's


def test_a_term_asked_often_takes_its_derivatives_from_sympy_and_gives_autograds_torques():
    """A model's summed terms of ``L`` (``often``: a driven rollout asks at each step) give, with the derivatives
    sympy derived once, the torques of the transform's two reverse passes, for every term of a three-joint
    library summed at random coefficients and one term alone (a constant, a term of ``q`` only)."""
    from bench.physics.terms import lagrangian_library

    library = lagrangian_library(3, ("angle", "angle", "linear"))
    rng = np.random.default_rng(3)
    data = Dataset(*(rng.normal(size=(64, 3)) for _ in range(3)), np.zeros((64, 3)))
    (summed,) = [t for t in TermLibrary(library.terms).summed(rng.normal(size=len(library.terms))) if t.place == "L"]
    q, _ = symbolic.coordinate_symbols(3)
    for term in (summed, Term.lagrangian(sympy.Integer(2)), Term.lagrangian(sympy.cos(q[0]) * q[2])):
        often, once = term.torque(data, often=True), term.torque(data)
        np.testing.assert_allclose(often, once, rtol=1e-12, atol=1e-12 * max(1.0, np.abs(once).max()))
    assert np.abs(summed.torque(data)).max() > 1.0  # not a vacuous match
