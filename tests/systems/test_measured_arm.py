"""Measured arms: the KUKA LWR4+'s recordings by trajectory, the split that
holds a whole trajectory out, a user's measured-arm file and its bad input,
and the standard model fitted without the URDF's placeholder inertias."""

from __future__ import annotations

import gzip
import re

import numpy as np
import pinocchio as pin
import pytest

from bench.core.budget import Budget
from bench.core.data import DataError, Dataset
from bench.core.errors import ConfigError
from methods import METHODS
from systems import SYSTEMS
from systems.measured_arm import DATA_DIR, measured_arm
from bench.core.scoring import opened
from tests.commandline import cli

KUKA_COLUMNS = ",".join(f"{k}_{i}={c}{i}" for i in range(1, 8) for k, c in (("q", "q"), ("qd", "dq"), ("tau", "tau")))


def test_the_default_split_holds_out_a_whole_trajectory_and_swapped_exchanges_them():
    default, swapped = SYSTEMS["kuka_lwr4"](), SYSTEMS["kuka_lwr4"](split="swapped")
    train, test = default.load("train"), opened(default.load("test"))
    assert (train.recordings(), train.trajectories()) == (["run1", "run2"], ["A"])
    assert (test.recordings(), test.trajectories()) == (["run3"], ["B"])
    assert not set(train.trajectories()) & set(test.trajectories())
    assert swapped.load("train").trajectories() == ["B"] and swapped.load("test").trajectories() == ["A"]
    assert train.dof == 7 and train.L is None and train.time is not None
    # samples 10 ms apart within each recording, from the filter's trim on
    step = np.diff(train.time[train.recording == "run1"])
    np.testing.assert_allclose(step, 0.01, atol=1e-9)


def test_fit_says_which_recordings_it_put_on_a_uniform_grid():
    result = cli("fit", "--system", "kuka_lwr4", "--method", "sysid", "--experiment", "indirect", "--steps", "1")
    assert result.returncode == 0, result.stderr
    said = [line for line in result.stdout.splitlines() if "interpolated onto a uniform" in line]
    assert {line.split(":")[0] for line in said} == {"train", "test"}  # the KUKA's rows lie 3 to 7 ms apart
    assert any(line.startswith("train: recording run1: rows ") for line in said)


def test_run_says_which_recordings_it_put_on_a_uniform_grid(tmp_path):
    result = cli("run", "--systems", "kuka_lwr4", "--methods", "sysid", "--experiments", "indirect", "--seeds", "0",
                 "--steps", "1", "--no-rollout", "--workers", "1", "--out", str(tmp_path / "out"))
    assert result.returncode == 0, result.stderr
    said = [line for line in result.stdout.splitlines() if line.startswith("kuka_lwr4: ") and "interpolated" in line]
    assert {line.split(":")[1].strip() for line in said} == {"train", "test"}
    assert any(line.startswith("kuka_lwr4: train: recording run1: rows ") for line in said)


def test_an_unknown_split_is_refused_in_one_line():
    result = cli("fit", "--system", "kuka_lwr4", "--method", "sysid", "--experiment", "indirect", "--steps", "1",
                 "--split", "sideways")
    assert result.returncode == 2
    assert "--split sideways: kuka_lwr4 offer(s) only default, swapped" in result.stderr
    # the declaration itself names no other split, rather than taking any other name as swapped
    with pytest.raises(ConfigError, match="no split 'sideways'"):
        SYSTEMS["kuka_lwr4"].measured.parts("sideways")
    with pytest.raises(ValueError, match="part must be one of train, test, all"):
        SYSTEMS["kuka_lwr4"]().load("validation")


def _arm_file(tmp_path, recordings: str, urdf: str = "kuka_lwr4.urdf.gz", columns: str = KUKA_COLUMNS):
    path = tmp_path / "arm.toml"
    shipped = (DATA_DIR / "kuka_lwr4.toml").read_text()
    pre = shipped[shipped.index("[filter]"):shipped.index("[recordings]")]  # the KUKA's own pre-processing
    path.write_text(f'urdf = "{urdf}"\ncolumns = "time=time,{columns}"\ntest = ["B"]\n{pre}[recordings]\n{recordings}')
    return path


def _kuka_recordings(trajectories=("A", "A", "B")) -> str:
    lines = []
    for run, t in zip((1, 2, 3), trajectories):
        trajectory = f', trajectory = "{t}"' if t else ""
        lines.append(f'run{run} = {{ file = "{DATA_DIR / f"kuka_lwr4_run{run}.csv.gz"}"{trajectory} }}')
    return "\n".join(lines) + "\n"


def test_a_recording_without_a_trajectory_is_refused_naming_both_and_nothing_is_written(tmp_path):
    spec = _arm_file(tmp_path, _kuka_recordings(("A", "", "B")))
    (tmp_path / "kuka_lwr4.urdf.gz").write_bytes((DATA_DIR / "kuka_lwr4.urdf.gz").read_bytes())
    out = tmp_path / "out"
    result = cli("run", "--systems", f"measured:{spec}", "--methods", "sysid", "--steps", "1", "--out", out)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "arm.toml" in lines[0] and "run2" in lines[0] and "names no trajectory" in lines[0]
    assert not out.exists() or not any(out.rglob("*.json"))


def test_a_urdf_whose_joint_count_differs_from_the_logs_is_refused_naming_both(tmp_path):
    six = ",".join(f"{k}_{i}={c}{i}" for i in range(1, 7) for k, c in (("q", "q"), ("qd", "dq"), ("tau", "tau")))
    (tmp_path / "kuka_lwr4.urdf.gz").write_bytes((DATA_DIR / "kuka_lwr4.urdf.gz").read_bytes())
    spec = _arm_file(tmp_path, _kuka_recordings(), columns=six)
    out = tmp_path / "out"
    result = cli("run", "--systems", f"measured:{spec}", "--methods", "sysid", "--steps", "1", "--out", out)
    assert result.returncode == 2
    line = result.stderr.strip()
    assert "\n" not in line and "arm.toml" in line and "kuka_lwr4.urdf.gz has 7 joint(s)" in line and "name 6" in line
    assert "kuka_lwr4_run1.csv.gz" in line
    assert not out.exists() or not any(out.rglob("*.json"))


def test_a_log_missing_a_mapped_column_is_refused_naming_the_log(tmp_path):
    (tmp_path / "kuka_lwr4.urdf.gz").write_bytes((DATA_DIR / "kuka_lwr4.urdf.gz").read_bytes())
    spec = _arm_file(tmp_path, _kuka_recordings(), columns=KUKA_COLUMNS.replace("tau_7=tau7", "tau_7=torque7"))
    with pytest.raises(DataError, match=r"kuka_lwr4_run1\.csv\.gz: missing column\(s\) torque7"):
        measured_arm(spec, name="bad_columns")


def _fit_torques(system, config: dict) -> np.ndarray:
    train, test = system.load("train"), opened(system.load("test"))
    method = METHODS["sysid"](**config)
    method.fit(train, "indirect", 0, Budget(steps=1), system=system)
    return method.predict_torque(test)


@pytest.mark.parametrize("config", [{"feasible": False, "friction": True}, {}], ids=["standard", "feasible"])
def test_no_fit_needs_the_urdfs_placeholder_inertias(tmp_path, config):
    """The URDF's masses are placeholders: with every link's mass and inertia
    tripled, the identified model's test torques stay the same."""
    text = gzip.decompress((DATA_DIR / "kuka_lwr4.urdf.gz").read_bytes()).decode()
    heavier = re.sub(r'<mass value="([0-9.]+)"', lambda m: f'<mass value="{3 * float(m.group(1))}"', text)
    heavier = re.sub(r'(i[xyz]{2})="([-0-9.e]+)"', lambda m: f'{m.group(1)}="{3 * float(m.group(2))}"', heavier)
    assert heavier != text
    (tmp_path / "heavy.urdf").write_text(heavier)
    spec = _arm_file(tmp_path, _kuka_recordings(), urdf="heavy.urdf")
    heavy = measured_arm(spec, name=f"heavy_{len(config)}")()
    assert not np.allclose(heavy.inertial_parameters(), SYSTEMS["kuka_lwr4"]().inertial_parameters())
    mine, theirs = _fit_torques(heavy, config), _fit_torques(SYSTEMS["kuka_lwr4"](), config)
    assert np.sqrt(np.mean((mine - theirs) ** 2)) < 1e-4 * np.sqrt(np.mean(theirs ** 2))


def _geared_ur5_torques(arm, n: int, seed: int, b, fc, rotor, offset):
    """States drawn at random and their torques: Pinocchio's RNEA plus, on each joint, viscous and Coulomb friction,
    a rotor's inertia and an offset."""
    model, data = arm.model, arm.model.createData()
    rng = np.random.default_rng(seed)
    q, qd, qdd = (rng.uniform(-1.5, 1.5, (n, arm.dof)) for _ in range(3))
    tau = np.stack([pin.rnea(model, data, *row) for row in zip(q, qd, qdd)])
    return q, qd, qdd, tau + b * qd + fc * np.sign(qd) + rotor * qdd + offset


def test_the_standard_model_recovers_friction_rotor_inertia_and_offsets_on_torques_from_pinocchio():
    """Rigid-body torques from Pinocchio's RNEA plus known friction, rotor inertias and offsets: the standard
    model identifies each exactly, but the rotor inertias of joints 1 and 2: the first acts as the first link's
    ZZ does, and is named in the record as dropped; the second's base parameter is a combination with the
    inertia of the links about the parallel axes that follow it."""
    arm = SYSTEMS["ur5"]()
    b, fc = np.linspace(0.2, 0.8, arm.dof), np.linspace(1.0, 0.4, arm.dof)
    rotor, offset = np.linspace(0.5, 0.1, arm.dof), np.linspace(-0.6, 0.9, arm.dof)
    q, qd, qdd, tau = _geared_ur5_torques(arm, 600, 0, b, fc, rotor, offset)
    train = Dataset(q, qd, qdd, tau, None, "ur5")
    method = METHODS["sysid"](**METHODS["sysid"].configuration("standard"))
    method.fit(train, "indirect", 0, Budget(steps=1), system=arm)
    found = {k.rstrip("+"): v for k, v in method.linear.parameters().items()}
    for j in range(arm.dof):
        assert found[f"b_{j + 1}"] == pytest.approx(b[j], rel=1e-6)
        assert found[f"F_c_{j + 1}"] == pytest.approx(fc[j], rel=1e-6)
        assert found[f"tau_0_{j + 1}"] == pytest.approx(offset[j], rel=1e-6)
        if j >= 2:
            assert found[f"I_a_{j + 1}"] == pytest.approx(rotor[j], rel=1e-6)
    assert "I_a_1" not in found
    facts = method.record_details()
    assert facts["dropped_joint_columns"] == ["I_a_1"] and facts["joint_columns_not_significant"] == []
    np.testing.assert_allclose(method.predict_torque(train), tau, atol=1e-8)


def test_the_standard_models_test_error_is_plain_least_squares_with_rotor_inertia_and_offset_columns():
    """On noisy torques of a geared arm, the standard model's test MSE is that of numpy's least squares on
    Pinocchio's joint torque regressor with each joint's friction, rotor inertia and offset columns, built here."""
    arm = SYSTEMS["ur5"]()
    b, fc = np.linspace(2.0, 8.0, arm.dof), np.linspace(10.0, 4.0, arm.dof)
    rotor, offset = np.linspace(3.0, 0.5, arm.dof), np.linspace(-2.0, 3.0, arm.dof)
    rng = np.random.default_rng(7)
    (q, qd, qdd, tau), test = (_geared_ur5_torques(arm, n, seed, b, fc, rotor, offset) for n, seed in ((1500, 1), (500, 2)))
    tau = tau + rng.normal(0.0, 0.1 * tau.std(axis=0), tau.shape)
    model, data = arm.model, arm.model.createData()

    def columns(q, qd, qdd):
        rows = [np.hstack([pin.computeJointTorqueRegressor(model, data, *row), np.diag(row[1]), np.diag(np.sign(row[1])),
                           np.diag(row[2]), np.eye(arm.dof)]) for row in zip(q, qd, qdd)]
        return np.vstack(rows)

    coef = np.linalg.lstsq(columns(q, qd, qdd), tau.ravel(), rcond=None)[0]
    expected = np.mean((columns(*test[:3]) @ coef - test[3].ravel()) ** 2)
    method = METHODS["sysid"](**METHODS["sysid"].configuration("standard"))
    method.fit(Dataset(q, qd, qdd, tau, None, "ur5"), "indirect", 0, Budget(steps=1), system=arm)
    mine = np.mean((method.predict_torque(Dataset(*test, None, "ur5")) - test[3]) ** 2)
    assert mine == pytest.approx(expected, rel=1e-6)
