"""The DFKI real double pendulum: raw-file checks, the filter-and-differentiate
step, and the rigid-body form against the measured torques."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from bench.core.data import DataError
from bench.core.errors import ConfigError
from bench.studies.dfki_filter import lab_coefficients, lab_design
from systems import get_system
from bench.core.recordings import DEFAULT_FILTER, FilterSpec, preprocess
from systems.dfki_double_pendulum import LAYOUTS, RAW_COLUMNS, read_raw
from bench.core.scoring import opened


def synthetic_recording(rng, seconds=6.0, quantum=0.011):
    """Two joints swinging at 1.3 and 0.7 Hz, sampled at 2 ms with gaps to
    3.4 ms, velocities quantized like the robot's encoders."""
    steps = np.where(rng.random(int(seconds / 0.002)) < 0.05, 0.0034, 0.002)
    t = np.concatenate([[0.0], np.cumsum(steps)])
    t = t[t < seconds]
    w = 2 * np.pi * np.array([1.3, 0.7])
    amp = np.array([0.8, 1.5])
    q = amp * np.sin(w * t[:, None])
    qd = amp * w * np.cos(w * t[:, None])
    frame = pd.DataFrame({"time": t})
    for i in (0, 1):
        frame[f"pos_meas{i + 1}"] = q[:, i]
        frame[f"vel_meas{i + 1}"] = np.round(qd[:, i] / quantum) * quantum + rng.normal(0, 0.01, len(t))
        frame[f"tau_meas{i + 1}"] = np.sin(w[i] * t)
    return frame, amp, w


def test_preprocess_recovers_accelerations_without_delay():
    frame, amp, w = synthetic_recording(np.random.default_rng(0))
    s = preprocess(LAYOUTS[0].take(frame))
    t = frame["time"].iloc[0] + s["time"]
    qdd_true = -amp * w**2 * np.sin(w * t[:, None])
    q_true = amp * np.sin(w * t[:, None])
    # a delayed filter would miss by amp * w * delay; 1 ms of delay at 1.3 Hz is 0.0065 rad
    assert np.max(np.abs(s["q"] - q_true)) < 2e-3
    assert np.max(np.abs(s["qdd"] - qdd_true), axis=0) == pytest.approx([0, 0], abs=0.03 * np.max(amp * w**2))
    assert s["q"].shape == s["qdd"].shape == s["tau"].shape and s["q"].shape[1] == 2


def test_preprocess_with_a_too_high_cutoff_is_refused():
    with pytest.raises(ConfigError, match="cutoff_hz"):
        FilterSpec(dt=0.002, cutoff_hz=300.0)
    with pytest.raises(ConfigError, match=r"^cutoff_hz must be positive, got 0$"):  # at the log's own step
        FilterSpec(cutoff_hz=0)


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda f: f.drop(columns=["vel_meas2"]), "missing column.*vel_meas2"),
        (lambda f: f.assign(tau_meas1=f["tau_meas1"].astype(object).where(f.index != 3, "x")), "column tau_meas1 has a non-numeric.*row 4"),
        (lambda f: f.assign(time=f["time"].where(f.index != 10, 0.0)), "column time does not increase"),
    ],
)
def test_bad_raw_files_name_the_file_and_column(tmp_path, edit, message):
    frame, _, _ = synthetic_recording(np.random.default_rng(1), seconds=1.0)
    path = tmp_path / "rec.csv"
    edit(frame).to_csv(path, index=False)
    with pytest.raises(DataError, match=message) as err:
        read_raw(path)
    assert str(path) in str(err.value)


def test_packaged_recordings_have_the_raw_columns():
    system = get_system("dfki_double_pendulum")
    train, test = system.load("train"), opened(system.load("test"))
    assert set(RAW_COLUMNS) <= set(pd.read_csv(system_path("00")).columns)
    assert 3500 < len(train) < 4000 and 1700 < len(test) < 2000
    assert train.meta["filter"]["cutoff_hz"] == DEFAULT_FILTER.cutoff_hz
    # the lab's rows, 2 ms apart with gaps, are put on a uniform 2 ms grid, and the data's source says so
    assert "00 rows 2 to 3." in train.source and "ms apart interpolated onto a uniform 2 ms" in train.source


def system_path(name):
    from systems.dfki_double_pendulum import trajectory_path

    return trajectory_path(name)


def test_the_labs_model_explains_the_measured_torque():
    """Relative angles, hanging-down zero and the sign of gravity are right if the
    lab's identified model explains most of the measured torque's variance."""
    test = opened(get_system("dfki_double_pendulum").load("test"))
    residual = lab_design(test) @ lab_coefficients() - test.tau.ravel()
    explained = 1 - residual.var() / test.tau.ravel().var()
    assert explained > 0.8


def test_rigid_body_form_at_the_labs_values_matches_the_lab_model_without_rotor_and_friction():
    system = get_system("dfki_double_pendulum")
    test = opened(system.load("test")).subset(slice(0, 200))
    from bench.physics.dynamics import euler_lagrange_chunked

    t = test.tensors()
    tau, _ = euler_lagrange_chunked(system.lagrangian, t["q"], t["qd"], t["qdd"])
    coef = lab_coefficients()
    coef[0] -= coef[5] + coef[5] / 36  # remove the rotor inertia from the first column (gr = 6)
    coef[5:] = 0.0
    np.testing.assert_allclose(tau.numpy().ravel(), lab_design(test) @ coef, rtol=1e-9, atol=1e-9)


def test_the_pendulum_declared_as_an_arm_has_the_recordings_and_pinocchio_gives_its_symbolic_forms_torque():
    """``dfki_double_pendulum_arm.toml`` holds the same samples as the registered system, and Pinocchio's
    torque from the lab's description (at its own masses and inertias) is the suite's symbolic form's at the
    same parameters: the description's joint axes, placements and angles are the recordings' coordinates."""
    import torch

    from systems.dfki_double_pendulum import DfkiDoublePendulum, DfkiParams
    from systems.measured_arm import register_measured

    arm = get_system(register_measured("measured:systems/data/dfki_double_pendulum_arm.toml"))
    ours = get_system("dfki_double_pendulum")
    train = arm.load("train")
    assert train.trajectories() == ours.load("train").trajectories() and arm.splits == ours.splits
    np.testing.assert_array_equal(train.tau, ours.load("train").tau)
    form = arm.linear_form()
    assert form.bodies == 2 and form.true_values is None  # the description's inertias are no truth
    # the description's two links as the symbolic form's parameters: centre-of-mass distances from the joint axes,
    # inertias about them (each link's own about its centre of mass, plus m r^2)
    prior = np.asarray(form.prior).reshape(2, 10)  # Pinocchio's order: m, m c, then the inertia about the frame
    m, r = prior[:, 0], np.abs(prior[:, 3] / prior[:, 0])
    p = DfkiParams(m1=m[0], m2=m[1], l1=0.3, r1=r[0], r2=r[1], I1=prior[0, 4], I2=prior[1, 4])
    data = train.subset(slice(0, 400))
    want = DfkiDoublePendulum(params=p).torque(*(torch.tensor(getattr(data, k)) for k in ("q", "qd", "qdd")))[0]
    got = form.torque_regressor(data.q, data.qd, data.qdd) @ np.asarray(form.prior)
    np.testing.assert_allclose(got, want.numpy(), rtol=0, atol=1e-10 * np.abs(got).max())
