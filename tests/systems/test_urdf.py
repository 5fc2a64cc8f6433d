"""Arms from their URDF files, checked against Pinocchio built independently
from the shipped files, and the suite's own Euler–Lagrange transform checked
against Pinocchio's RNEA on a mechanism both can build."""

from __future__ import annotations

import dataclasses
import gzip

import numpy as np
import pytest
import torch

pin = pytest.importorskip("pinocchio")

from bench.cli import main  # noqa: E402
from bench.core.data import DataError, generate, mse  # noqa: E402
from bench.core.csv_format import read_csv
from bench.physics.dynamics import euler_lagrange  # noqa: E402
from bench.evaluation.rollout import rollout_error  # noqa: E402
from methods import METHODS  # noqa: E402
from systems import SYSTEMS, get_system  # noqa: E402
from systems.n_link_pendulum import n_link_pendulum  # noqa: E402
from systems.urdf_arm import DATA_DIR, physically_consistent, register_urdf  # noqa: E402
from bench.core.budget import Budget


def pinocchio_panda():
    model = pin.buildModelFromXML(gzip.open(DATA_DIR / "panda.urdf.gz", "rt").read())
    fingers = [model.getJointId(j) for j in ("panda_finger_joint1", "panda_finger_joint2")]
    return pin.buildReducedModel(model, fingers, pin.neutral(model))


def test_bench_data_on_the_panda_is_pinocchios_rnea_on_the_shipped_urdf(tmp_path):
    out = tmp_path / "panda.csv"
    assert main(["data", "--system", "panda", "--n", "300", "--seed", "3", "--out", str(out)]) == 0
    data = read_csv(out, dof=7)
    model = pinocchio_panda()
    d = model.createData()
    tau = np.stack([pin.rnea(model, d, q, v, a) for q, v, a in zip(data.q, data.qd, data.qdd)])
    L = np.array([pin.computeKineticEnergy(model, d, q, v) - pin.computePotentialEnergy(model, d, q)
                  for q, v in zip(data.q, data.qd)])
    assert np.abs(tau - data.tau).max() <= 1e-12 * np.abs(tau).max()
    assert np.abs(L - data.L).max() <= 1e-12 * np.abs(L).max()
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    assert np.all(data.q > lo) and np.all(data.q < hi)  # inside the joint limits
    assert np.all(np.abs(data.qd) <= model.velocityLimit / 2)


def pinocchio_pendulum(n: int, masses, lengths, g: float):
    """The suite's n-link rod pendulum, built in Pinocchio: revolute joints
    about y, each rod hanging along -z from its joint."""
    model = pin.Model()
    model.gravity.linear = np.array([0.0, 0.0, -g])
    parent, placement = 0, pin.SE3.Identity()
    for i in range(n):
        joint = model.addJoint(parent, pin.JointModelRY(), placement, f"joint{i + 1}")
        m, length = masses[i], lengths[i]
        inertia = pin.Inertia(m, np.array([0.0, 0.0, -length / 2]), np.diag([m * length**2 / 12, m * length**2 / 12, 0.0]))
        model.appendBodyToJoint(joint, inertia, pin.SE3.Identity())
        parent, placement = joint, pin.SE3(np.eye(3), np.array([0.0, 0.0, -length]))
    return model


@pytest.mark.parametrize("n", [1, 2, 3, 5])
def test_the_suites_euler_lagrange_transform_agrees_with_pinocchios_rnea(n):
    masses, lengths = np.linspace(0.7, 1.9, n), np.linspace(1.3, 0.6, n)
    params = {**{f"m{i + 1}": m for i, m in enumerate(masses)}, **{f"l{i + 1}": x for i, x in enumerate(lengths)}, "g": 9.81}
    cls = n_link_pendulum(n)
    system = cls(cls.Params(**params))
    rng = np.random.default_rng(n)
    q, qd, qdd = (rng.uniform(-1.5, 1.5, (200, n)) for _ in range(3))
    ours = euler_lagrange(system.lagrangian, *(torch.from_numpy(x) for x in (q, qd, qdd))).numpy()
    # the suite's angles are absolute, Pinocchio's relative: q = A phi with A lower-triangular ones
    A = np.tril(np.ones((n, n)))
    Ainv = np.linalg.inv(A)
    model = pinocchio_pendulum(n, masses, lengths, 9.81)
    d = model.createData()
    tau_phi = np.stack([pin.rnea(model, d, Ainv @ a, Ainv @ b, Ainv @ c) for a, b, c in zip(q, qd, qdd)])
    theirs = tau_phi @ Ainv  # tau_q = A^-T tau_phi, row by row
    assert np.abs(ours - theirs).max() <= 1e-10 * max(1.0, np.abs(theirs).max())


def test_sysid_identifies_the_pandas_base_parameters(monkeypatch):
    import methods.sysid as sysid

    checked = []
    counted = sysid._smallest_eigenvalues
    monkeypatch.setattr(sysid, "_smallest_eigenvalues", lambda *a: checked.append(1) or counted(*a))
    panda = get_system("panda")
    train, test = generate(panda, 4000, 0), generate(panda, 1000, 1000)
    m = METHODS["sysid"](feasible=False).fit(train, "indirect", 0, budget=Budget(steps=1))  # a linear form is solved in one step
    assert checked == []  # the mass matrices are checked when the record asks, not by every fit (a fold's, a prior's)
    facts = m.record_details()
    assert facts["base_parameters"] == 43  # as Gaz et al. (2019) found for the Panda
    assert facts["parameter_error"] < 1e-9 and facts["mass_matrix_positive_definite"]
    assert facts["mass_matrix_states"] == 4000 and len(checked) == 8  # every training state, 512 at a time
    assert m.record_details() == facts and len(checked) == 8  # once
    assert mse(m.predict_torque(test), test.tau) < 1e-20
    rollout = rollout_error(m, panda, test)
    assert rollout["status"] == "ok" and rollout["q_rmse"] < 1e-8  # against Pinocchio's own forward dynamics


@pytest.mark.parametrize("system_name", ["panda", "kuka_lwr4"])
def test_a_linear_models_mass_matrix_and_bias_from_the_engine_are_its_regressors(system_name):
    """``M`` and ``c`` by CRBA and RNEA at the model's parameters equal the
    torque regressor's at ``dof + 1`` accelerations, for parameters that are
    no rigid body's (half the columns, random signs, zero masses) and for a
    form with a further term; the engine is asked, not the regressor."""
    from bench.physics.effects import EFFECTS
    from bench.physics.linear import LinearParametricModel
    from bench.physics.models import FittedModel
    system = get_system(system_name)
    rng = np.random.default_rng(4)
    form = system.linear_form()
    form = form.with_terms([EFFECTS["armature"].term(1), EFFECTS["coulomb_friction"].term(2)], ["I_2", "F_c_3"])
    p = len(form.names)
    half = np.sort(rng.choice(p, p // 2, replace=False))
    q, qd = rng.uniform(-1, 1, (40, system.dof)), rng.uniform(-2, 2, (40, system.dof))
    for model in (LinearParametricModel(form, half, rng.normal(size=len(half))),
                  LinearParametricModel(form, np.arange(p), np.array(form.full_prior()) + 0.1)):
        asked = []
        model.form = dataclasses.replace(form, torque_regressor=lambda *a: asked.append(a) or form.torque_regressor(*a))
        M, c = model.mass_and_bias(q, qd)
        assert asked == []
        M_regressor, c_regressor = FittedModel.mass_and_bias(model, q, qd)
        assert len(asked) == 1
        np.testing.assert_allclose(M, M_regressor, rtol=1e-10, atol=1e-10 * np.abs(M_regressor).max())
        np.testing.assert_allclose(c, c_regressor, rtol=1e-10, atol=1e-10 * np.abs(c_regressor).max())


def test_the_urdf_parameters_are_physically_consistent_and_a_broken_set_is_named():
    for name in ("panda", "ur5"):
        assert physically_consistent(get_system(name).inertial_parameters()) == []
    p = get_system("ur5").inertial_parameters().reshape(-1, 10).copy()
    p[1, 0] = -1.0  # a negative mass on link 2
    p[2, 4] *= 100.0  # an inertia about x larger than about y and z together on link 3
    problems = physically_consistent(p.ravel())
    assert len(problems) == 2 and problems[0].startswith("link 2: mass") and problems[1].startswith("link 3:")


def test_any_urdf_registers_in_one_line_and_a_bad_one_is_refused(tmp_path):
    path = tmp_path / "arm.urdf"
    path.write_bytes(gzip.open(DATA_DIR / "ur5_robot.urdf.gz").read())
    name = register_urdf(f"urdf:{path}")
    assert name == "urdf_arm" and SYSTEMS[name]().dof == 6 and register_urdf(f"urdf:{path}") == name
    other = tmp_path / "other" / "arm.urdf"  # another file whose name would be the same system's
    other.parent.mkdir()
    other.write_bytes(path.read_bytes())
    with pytest.raises(DataError, match="another file is registered as 'urdf_arm' already") as caught:
        register_urdf(f"urdf:{other}")
    assert str(other) in str(caught.value) and "\n" not in str(caught.value)
    SYSTEMS.remove(name)
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='x'><link name='a'/><oops></robot>")
    with pytest.raises(DataError, match="not a URDF Pinocchio can read"):
        register_urdf(f"urdf:{bad}")
    with pytest.raises(DataError, match="no such URDF file"):
        register_urdf(f"urdf:{tmp_path / 'none.urdf'}")


@pytest.mark.parametrize("system_name", ["double_pendulum", "triple_pendulum"])
def test_a_tip_payload_and_a_gravity_tilt_agree_with_pinocchio(system_name):
    """``bench data --effects tip_payload=m`` and ``gravity_tilt=alpha`` against
    RNEA on the same chain with a point mass at its tip, and with gravity
    turned by alpha in the plane (equilibrium at q = alpha)."""
    from bench.physics.undeclared import add_effects, parse_effects

    system = SYSTEMS[system_name]()
    n = system.dof
    p = system.param_dict()
    masses, lengths = [p[f"m{i + 1}"] for i in range(n)], [p[f"l{i + 1}"] for i in range(n)]
    data = generate(system, 200, 7)
    m, alpha = 0.37, 0.08
    A = np.tril(np.ones((n, n)))
    Ainv = np.linalg.inv(A)

    def rnea(model):
        d = model.createData()
        tau_phi = np.stack([pin.rnea(model, d, Ainv @ a, Ainv @ b, Ainv @ c) for a, b, c in zip(data.q, data.qd, data.qdd)])
        return tau_phi @ Ainv

    loaded = pinocchio_pendulum(n, masses, lengths, p["g"])
    tip = loaded.getJointId(f"joint{n}")
    loaded.appendBodyToJoint(tip, pin.Inertia(m, np.array([0.0, 0.0, -lengths[-1]]), np.zeros((3, 3))), pin.SE3.Identity())
    ours = add_effects(data, parse_effects([f"tip_payload={m}"], n), system).tau
    assert np.abs(ours - rnea(loaded)).max() <= 1e-10 * np.abs(ours).max()

    tilted = pinocchio_pendulum(n, masses, lengths, p["g"])
    tilted.gravity.linear = p["g"] * np.array([-np.sin(alpha), 0.0, -np.cos(alpha)])
    ours = add_effects(data, parse_effects([f"gravity_tilt={alpha}"], n), system).tau
    assert np.abs(ours - rnea(tilted)).max() <= 1e-10 * np.abs(ours).max()
    assert np.abs(ours - data.tau).max() > 0.01 * np.abs(ours).max()  # the tilt is not lost in the comparison
