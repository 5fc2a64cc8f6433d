"""The effects a rigid-body model lacks, defined once as terms: what they add
to tau and L, and how a bad specification is refused."""

from __future__ import annotations

import numpy as np
import pytest
import sympy

from bench.core import symbolic
from bench.core.data import generate
from bench.core.dynamics import euler_lagrange_chunked
from bench.core.effects import EFFECTS, add_effects, parse_effects
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
    assert set(EFFECTS) == {"viscous_friction", "coulomb_friction", "armature", "spring", "offset"}


@pytest.mark.parametrize(
    "items, message",
    [
        (["viscous=1,2"], "unknown effect 'viscous'"),
        (["viscous_friction=1"], "needs 2 finite coefficient"),
        (["viscous_friction"], "expected NAME=c1,...,c2"),
        (["spring=a,b"], "needs numbers"),
    ],
)
def test_bad_effect_specs_are_refused(items, message):
    with pytest.raises(ConfigError, match=message):
        parse_effects(items, 2)


def test_each_effect_is_a_term_on_its_joint():
    data = generate(get_system("double_pendulum"), 200, 0)
    expected = {"viscous_friction": data.qd, "coulomb_friction": np.sign(data.qd), "armature": data.qdd,
                "spring": data.q, "offset": np.ones_like(data.q)}
    for name, columns in expected.items():
        for j in range(2):
            term = EFFECTS[name].term(j)
            assert term.name == name and term.joint == j and term.is_force == (not EFFECTS[name].conservative)
            tau = term.torque(data)
            np.testing.assert_array_equal(tau[:, j], columns[:, j])  # exact, through the transform too
            assert not tau[:, 1 - j].any()
