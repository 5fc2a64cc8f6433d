"""The effects a rigid-body model lacks, defined once as terms: what they add
to tau and L, and how a bad specification is refused."""

from __future__ import annotations

import numpy as np
import pytest
import sympy
from hypothesis import given, settings
from hypothesis import strategies as st

from bench.core import symbolic
from bench.core.data import generate
from bench.physics.dynamics import euler_lagrange_chunked
from bench.physics.effects import EFFECTS
from bench.physics.undeclared import add_effects, parse_effects
from bench.core.errors import ConfigError
from systems import get_system


def test_effects_add_to_tau_and_conservative_ones_to_L():
    s = get_system("double_pendulum")
    clean = generate(s, 50, 0)
    withfx = add_effects(clean, {"armature": (0.3, 0.0), "spring": (0.0, 2.0)})
    np.testing.assert_allclose(withfx.tau[:, 0] - clean.tau[:, 0], 0.3 * clean.qdd[:, 0])
    np.testing.assert_allclose(withfx.tau[:, 1] - clean.tau[:, 1], 2.0 * clean.q[:, 1])
    np.testing.assert_allclose(withfx.L - clean.L, 0.15 * clean.qd[:, 0] ** 2 - clean.q[:, 1] ** 2)
    # the Lagrangian terms are consistent with the torques through the suite's transform
    (q1, q2), (v1, v2) = symbolic.coordinate_symbols(2)
    extra = symbolic.to_torch(sympy.Rational(3, 20) * v1**2 - q2**2, 2)
    t = clean.tensors()
    tau_extra = euler_lagrange_chunked(extra, t["q"], t["qd"], t["qdd"])[0].numpy()
    np.testing.assert_allclose(withfx.tau - clean.tau, tau_extra, atol=1e-12)
    assert set(EFFECTS) == {"viscous_friction", "coulomb_friction", "armature", "spring", "offset",
                            "coupled_spring", "coupled_damper", "smooth_coulomb", "stribeck_hump", "periodic_sin",
                            "periodic_cos", "tip_payload", "gravity_tilt", "torque_gain", "time_shift",
                            "load_friction"}


@pytest.mark.parametrize(
    "items, message",
    [
        (["viscous=1,2"], "unknown effect 'viscous'"),
        (["viscous_friction=1"], "needs 2 finite coefficient"),
        (["viscous_friction"], "expected NAME=c1,...,c2"),
        (["spring=a,b"], "needs numbers"),
        (["coupled_spring=1-1:2"], "two distinct joints in 1..2"),
        (["coupled_spring=1-3:2"], "two distinct joints in 1..2"),
        (["coupled_damper=1:2"], "i-j:c items"),
        (["coupled_damper=1-2:x"], "i-j:c items"),
        (["coupled_damper=1-2:inf"], "finite coefficient"),
        (["stribeck_friction=1:1,2,0.5"], "needs j:F_c,F_s,v_s,b items"),
        (["stribeck_friction=3:1,2,0.5,0.1"], "a joint in 1..2"),
        (["stribeck_friction=1:2,1,0.5,0.1"], "not physical: it needs F_s >= F_c >= 0"),
        (["stribeck_friction=1:1,2,0,0.1"], "not physical"),
        (["stribeck_hump=1,2"], "unknown effect 'stribeck_hump'"),
        (["tip_payload=-0.1"], "tip_payload needs one finite number >= 0"),
        (["tip_payload=0.1,0.2"], "tip_payload needs one finite number"),
        (["gravity_tilt=nan"], "gravity_tilt needs one finite number"),
        (["gravity_tilt=1-2:0.1"], "gravity_tilt needs one finite number"),
        (["load_friction=-0.1,0"], "load_friction needs 2 coefficients with 0 <= mu <= 0.5"),
        (["viscous_friction=-0.8,0.3"], "viscous_friction on joint 1 is -0.8, which is not physical \\(b >= 0\\)"),
        (["armature=0,-0.5"], "armature on joint 2 is -0.5, which is not physical \\(I >= 0\\)"),
        (["coupled_damper=1-2:-0.6"], "coupled_damper on joints 1-2 is -0.6"),
        (["load_friction=0,0.6"], "0 <= mu <= 0.5"),
    ],
)
def test_bad_effect_specs_are_refused(items, message):
    with pytest.raises(ConfigError, match=message):
        parse_effects(items, 2)


@pytest.mark.parametrize("system_name", ["cart_pole", "spring_pendulum"])
def test_a_payload_or_tilt_on_a_system_that_is_no_planar_chain_is_refused(system_name):
    s = get_system(system_name)
    for item in ("tip_payload=0.2", "gravity_tilt=0.1"):
        with pytest.raises(ConfigError, match="needs a planar chain that gives its geometry"):
            add_effects(generate(s, 20, 0), parse_effects([item], s.dof), s)


def test_the_tilt_term_is_the_exact_tilt_with_sin_alpha_once_the_gravity_terms_are_rescaled():
    # L(q - alpha, qd) = kinetic + cos(alpha) * gravity + sin(alpha) * the tilt term, exactly
    s = get_system("triple_pendulum")
    data = generate(s, 100, 0)
    alpha = 0.3
    gravity = sympy.Add(*[t for t in sympy.Add.make_args(s.lagrangian_sympy) if not t.free_symbols & set(s.symbols[1])])
    tilt = EFFECTS["gravity_tilt"].term(system=s)
    exact = add_effects(data, {"gravity_tilt": {(): alpha}}, s).L
    from bench.physics.terms import Term
    rebuilt = data.L + (np.cos(alpha) - 1) * Term.lagrangian(gravity).value(data) + np.sin(alpha) * tilt.value(data)
    np.testing.assert_allclose(exact, rebuilt, atol=1e-12)
    assert EFFECTS["gravity_tilt"].parameter_from(np.sin(alpha), 1e-3) == pytest.approx((alpha, 1e-3 / np.cos(alpha)))


def test_each_effect_is_a_term_on_its_joint():
    data = generate(get_system("double_pendulum"), 200, 0)
    expected = {"viscous_friction": data.qd, "coulomb_friction": np.sign(data.qd), "armature": data.qdd,
                "spring": data.q, "offset": np.ones_like(data.q)}
    for name, columns in expected.items():
        assert EFFECTS[name].arity == 1
        for j in range(2):
            term = EFFECTS[name].term(j)
            assert term.name == name and term.joint == j and term.in_lagrangian == EFFECTS[name].conservative
            tau = term.torque(data)
            np.testing.assert_array_equal(tau[:, j], columns[:, j])  # exact, through the transform too
            assert not tau[:, 1 - j].any()


@pytest.mark.parametrize("name, column", [("coupled_spring", "q"), ("coupled_damper", "qd")])
def test_a_coupled_effect_acts_on_a_coordinate_difference_with_opposite_torques(name, column):
    data = generate(get_system("double_pendulum"), 200, 0)
    (fx,) = parse_effects([f"{name}=1-2:2.5"], 2).values()
    assert fx == {(0, 1): 2.5}
    diff = getattr(data, column)[:, 0] - getattr(data, column)[:, 1]
    tau = add_effects(data, {name: fx}).tau - data.tau
    np.testing.assert_allclose(tau, 2.5 * np.stack([diff, -diff], axis=1), rtol=1e-12, atol=1e-12)
    term = EFFECTS[name].term(0, 1)
    assert term.joints == (0, 1) and (term.place == "D") == (name == "coupled_damper")
    with pytest.raises(ValueError, match="2 distinct joint"):
        EFFECTS[name].term(1, 1)


def test_dissipative_effects_never_produce_energy():
    # D >= 0 with a coefficient >= 0, and the power qd . dD/dqd they take out is >= 0
    data = generate(get_system("double_pendulum"), 500, 1)
    for name, effect in EFFECTS.items():
        if effect.kind != "dissipative":
            continue
        term = effect.term(*range(effect.arity), shape=0.3 if effect.shaped else None)
        power = np.sum(data.qd * term.torque(data), axis=1)
        assert (power >= -1e-12).all(), name


def test_the_stribeck_law_adds_its_torque_on_its_joint():
    data = generate(get_system("double_pendulum"), 300, 0)
    fx = parse_effects(["stribeck_friction=2:1.0,2.0,0.5,0.3"], 2)
    tau = add_effects(data, fx).tau - data.tau
    v = data.qd[:, 1]
    np.testing.assert_allclose(tau[:, 1], (1.0 + np.exp(-(v / 0.5) ** 2)) * np.sign(v) + 0.3 * v, atol=1e-12)
    assert not tau[:, 0].any()


def test_a_shaped_effects_numeric_torque_is_its_terms():
    plain = generate(get_system("double_pendulum"), 300, 0)
    filtered = plain.replace(sign_qd=np.tanh(plain.qd / 0.2))  # a filtered recording's rounded signs
    for data in (plain, filtered):
        for name, effect in EFFECTS.items():
            if effect.shaped:
                for v in effect.grid[::5] if effect.grid else (0.05, 0.5, 3.0):
                    tau = effect.term(1, shape=v).torque(data)
                    numeric = effect.numeric(data.q[:, 1], data.qd[:, 1], v, data.velocity_sign()[:, 1])
                    np.testing.assert_allclose(numeric, tau[:, 1], rtol=1e-13, atol=1e-15)


def test_coulomb_friction_uses_the_datas_filtered_velocity_sign():
    data = generate(get_system("double_pendulum"), 200, 0)
    rounded = np.tanh(data.qd / 0.3)
    term = EFFECTS["coulomb_friction"].term(1)
    np.testing.assert_array_equal(term.torque(data)[:, 1], np.sign(data.qd[:, 1]))
    np.testing.assert_array_equal(term.torque(data.replace(sign_qd=rounded))[:, 1], rounded[:, 1])
    assert not term.torque(data.replace(sign_qd=rounded))[:, 0].any()


def test_a_sharp_smooth_coulomb_is_finite_at_any_speed():
    # log cosh's derivative is sinh/cosh, which overflows past |qd / v_s| ~ 710: the torque must be tanh
    data = generate(get_system("double_pendulum"), 100, 0)
    data = data.replace(qd=100 * data.qd)
    tau = EFFECTS["smooth_coulomb"].term(0, shape=0.0077).torque(data)
    assert np.isfinite(tau).all()
    np.testing.assert_allclose(tau[:, 0], np.tanh(data.qd[:, 0] / 0.0077), atol=1e-12)


_NAMES = st.sampled_from(["viscous_friction", "coupled_spring", "stribeck_friction", "tip_payload", "gravity_tilt", "x"])
_VALUES = st.text(alphabet="0123456789.,:;-+eEinfa ", max_size=24)


@settings(max_examples=300, deadline=None)
@given(name=_NAMES, sep=st.sampled_from(["=", "", "=="]), values=_VALUES, dof=st.integers(1, 4))
def test_any_effect_spec_is_parsed_or_refused_with_a_config_error(name, sep, values, dof):
    try:
        parsed = parse_effects([f"{name}{sep}{values}"], dof)
    except ConfigError as exc:
        assert str(exc).startswith("--effects: ") and "\n" not in str(exc)
        return
    for placed in parsed.values():
        for joints, c in placed.items():
            assert all(0 <= j < dof for j in joints)
            assert all(np.isfinite(np.atleast_1d(c)))
