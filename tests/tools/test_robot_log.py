"""The simulated robot log: exact derivatives, the system's range, and a log that bench convert reads."""

from __future__ import annotations

import numpy as np
import pytest

from bench.core.csv_format import read_csv
from bench.core.errors import ConfigError
from bench.tools.robot_log import columns, simulate
from systems import get_system
from tests.commandline import cli


def test_a_trajectory_has_exact_derivatives_and_stays_in_the_systems_range():
    time, data = simulate("double_pendulum", 10.0, 500.0, 0.1, [], 0.0, 3)
    dt = time[1] - time[0]
    np.testing.assert_allclose(np.gradient(data.q, dt, axis=0)[1:-1], data.qd[1:-1], atol=1e-4)
    np.testing.assert_allclose(np.gradient(data.qd, dt, axis=0)[1:-1], data.qdd[1:-1], atol=1e-3)
    system = get_system("double_pendulum")
    for kind, x in (("q", data.q), ("qd", data.qd)):
        lo, hi = system.domain.bounds(kind, system.dof)
        assert (x >= lo).all() and (x <= hi).all(), kind


def test_effects_and_noise_are_added_and_a_measured_system_is_refused():
    _, clean = simulate("double_pendulum", 2.0, 200.0, 0.1, [], 0.0, 0)
    _, rubbed = simulate("double_pendulum", 2.0, 200.0, 0.1, ["viscous_friction=0.8,0.5"], 0.0, 0)
    np.testing.assert_allclose(rubbed.tau - clean.tau, clean.qd * [0.8, 0.5], atol=1e-12)
    _, noisy = simulate("double_pendulum", 2.0, 200.0, 0.1, [], 0.05, 0)
    assert 0 < np.std(noisy.tau - clean.tau) < 0.1 * np.std(clean.tau)
    with pytest.raises(ConfigError, match="measured"):
        simulate("dfki_double_pendulum", 2.0, 200.0, 0.1, [], 0.0, 0)


def test_the_logs_convert_into_the_suites_format_with_one_recording_each(tmp_path):
    r = cli("robot-log", "--system", "double_pendulum", "--recordings", "2", "--seconds", "4", "--effects",
            "coulomb_friction=1.5,0.7", "--out", str(tmp_path / "logs"))
    assert r.returncode == 0, r.stderr
    assert f"--columns {columns(2)}" in r.stdout
    logs = sorted(str(p) for p in (tmp_path / "logs").glob("recording_*.csv"))
    r = cli("convert", "--columns", columns(2), "--out", str(tmp_path / "train.csv"), *logs)
    assert r.returncode == 2 and "name the excitation trajectory that the logs recording_0, recording_1" in r.stderr
    assert not (tmp_path / "train.csv").exists()
    r = cli("convert", "--columns", columns(2), "--distinct", "--out", str(tmp_path / "train.csv"), *logs)
    assert r.returncode == 0, r.stderr
    data = read_csv(tmp_path / "train.csv", system="double_pendulum")
    assert data.recordings() == ["recording_0", "recording_1"] and len(data) > 500
    assert data.trajectories() == ["recording_0", "recording_1"] and np.all(np.diff(data.time[data.recording == "recording_0"]) > 0)
    r = cli("convert", "--columns", columns(2), "--trajectory", "A", "--out", str(tmp_path / "one.csv"), *logs)
    assert r.returncode == 0, r.stderr
    one = read_csv(tmp_path / "one.csv")
    assert one.recordings() == ["recording_0", "recording_1"] and one.trajectories() == ["A"]
    r = cli("convert", "--columns", columns(2), "--trajectory", "A", "B", "C", "--out", str(tmp_path / "bad.csv"), *logs)
    assert r.returncode == 2 and "--trajectory gives 3 names for 2 logs" in r.stderr and not (tmp_path / "bad.csv").exists()


def test_a_measured_system_is_refused_in_one_line_and_nothing_is_written(tmp_path):
    r = cli("robot-log", "--system", "dfki_double_pendulum", "--out", str(tmp_path / "logs"))
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.strip().splitlines() == ["error: dfki_double_pendulum is measured; a log can be simulated for a "
                                             "simulated system only"]
    assert not (tmp_path / "logs").exists()
    r = cli("robot-log", "--system", "double_pendulum", "--effects", "smooth_coulomb=1:0.7", "--out", str(tmp_path / "x"))
    assert r.returncode == 2 and "needs j:F_c,v_s,b items" in r.stderr and not (tmp_path / "x").exists()


def test_a_delayed_torque_is_the_arms_torque_an_instant_earlier_and_a_negative_delay_is_refused(tmp_path):
    time, now = simulate("double_pendulum", 2.0, 200.0, 0.1, [], 0.0, 0)
    _, late = simulate("double_pendulum", 2.0, 200.0, 0.1, [], 0.0, 0, torque_delay=0.01)
    np.testing.assert_allclose(late.q, now.q)  # the states are the ones logged at t
    np.testing.assert_allclose(late.tau[2:], now.tau[:-2], rtol=1e-6, atol=1e-8)  # 10 ms = two samples at 200 Hz
    r = cli("robot-log", "--system", "double_pendulum", "--torque-delay", "-0.005", "--out", str(tmp_path / "logs"))
    assert r.returncode == 2 and "--torque-delay" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "logs").exists()


@pytest.fixture(scope="module")
def panda_log(tmp_path_factory):
    """One 12 s log of the Panda (7 joints), in seconds and radians, and the same log in degrees and in milliseconds."""
    import pandas as pd

    folder = tmp_path_factory.mktemp("panda_log")
    r = cli("robot-log", "--system", "panda", "--recordings", "1", "--seconds", "12", "--out", str(folder))
    assert r.returncode == 0, r.stderr
    log = folder / "recording_0.csv"
    frame = pd.read_csv(log)
    degrees = frame.copy()
    for c in frame.columns:
        if c.endswith(("_position", "_velocity")):
            degrees[c] = frame[c] * 180 / np.pi
    millis = frame.assign(time=frame["time"] * 1000)
    degrees.to_csv(folder / "degrees.csv", index=False)
    millis.to_csv(folder / "millis.csv", index=False)
    return folder


def test_a_log_in_milliseconds_stops_with_one_line_naming_the_time_column(panda_log, tmp_path):
    out = tmp_path / "out.csv"
    r = cli("convert", "--columns", columns(7), "--out", out, panda_log / "millis.csv")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and not out.exists()
    assert "millis.csv: column time" in r.stderr and "--time-unit ms" in r.stderr
    r = cli("convert", "--columns", columns(7), "--time-unit", "ms", "--out", out, panda_log / "millis.csv")
    assert r.returncode == 0, r.stderr
    r = cli("convert", "--columns", columns(7), "--out", tmp_path / "seconds.csv", panda_log / "recording_0.csv")
    assert r.returncode == 0 and "warning" not in r.stderr, r.stderr
    np.testing.assert_allclose(read_csv(out).qdd, read_csv(tmp_path / "seconds.csv").qdd, rtol=1e-9, atol=1e-9)


def test_a_log_in_degrees_is_named_before_any_fit_and_converted_on_request(panda_log, tmp_path):
    out = tmp_path / "deg.csv"
    r = cli("convert", "--columns", columns(7), "--out", out, panda_log / "degrees.csv")
    assert r.returncode == 0 and "beyond ±2π: if the log is in degrees, give --degrees" in r.stderr, r.stderr
    # the arm's joint limits stop the fit, in one line that names the joint, the range seen and the limits
    r = cli("fit", "--system", "panda", "--method", "sysid", "--experiment", "indirect", "--train", out, "--steps", "1")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "is the log in degrees?" in r.stderr, r.stderr
    assert "deg.csv: joint " in r.stderr and "outside its limits [" in r.stderr
    r = cli("residual", "--system", "panda", "--method", "sysid", "--train", out, "--steps", "1")
    assert r.returncode == 2 and "is the log in degrees?" in r.stderr and r.stderr.count("\n") == 1, r.stderr
    r = cli("fit", "--system", "panda", "--method", "sysid", "--experiment", "indirect", "--train", out, "--steps", "1",
            "--ignore-limits")
    assert r.returncode == 0, r.stderr
    r = cli("convert", "--columns", columns(7), "--degrees", "--out", tmp_path / "rad.csv", panda_log / "degrees.csv")
    assert r.returncode == 0 and "warning" not in r.stderr, r.stderr
    r = cli("fit", "--system", "panda", "--method", "sysid", "--experiment", "indirect", "--train", tmp_path / "rad.csv",
            "--steps", "1")
    assert r.returncode == 0, r.stderr


def test_a_measured_arm_file_says_its_units_and_its_logs_in_degrees_stop_at_the_joint_limits(tmp_path):
    """A measured-arm file's logs in degrees or milliseconds are caught as convert's are; the file can say its units."""
    import pandas as pd

    from bench.core.errors import DataError
    from bench.runner.run import given_data
    from systems.measured_arm import measured_arm
    from systems.urdf_arm import DATA_DIR

    r = cli("robot-log", "--system", "ur5", "--recordings", "2", "--seconds", "6", "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    for k in range(2):
        frame = pd.read_csv(tmp_path / f"recording_{k}.csv")
        angles = [c for c in frame.columns if c.endswith(("_position", "_velocity"))]
        frame.assign(**{c: frame[c] * 180 / np.pi for c in angles}).to_csv(tmp_path / f"deg_{k}.csv", index=False)
        frame.assign(time=frame["time"] * 1000).to_csv(tmp_path / f"ms_{k}.csv", index=False)

    def arm(prefix, extra=""):
        toml = tmp_path / f"{prefix}.toml"
        toml.write_text(f'urdf = "{DATA_DIR / "ur5_robot.urdf.gz"}"\ncolumns = "{columns(6)}"\ntest = ["B"]\n{extra}'
                        f'[recordings]\na = {{ file = "{prefix}_0.csv", trajectory = "A" }}\n'
                        f'b = {{ file = "{prefix}_1.csv", trajectory = "B" }}\n')
        return measured_arm(toml, name=f"ur5_{prefix}")()

    with pytest.raises(DataError, match=r"deg.toml:train .*joint 1 .*is the log in degrees\?"):  # names file, joint, degrees
        given_data(arm("deg"), None, None, check_limits=True)
    train, test = given_data(arm("deg", "degrees = true\n"), None, None, check_limits=True)
    assert np.max(np.abs(train.q)) < 2 * np.pi
    with pytest.raises(DataError, match=r"ms_0.csv: column time: .*--time-unit ms"):
        arm("ms").load("train")
    assert len(arm("ms", 'time_unit = "ms"\n').load("train")) == len(train)
    with pytest.raises(DataError, match=r"ms.toml: time_unit must be one of s, ms, us, got 'hours'"):
        arm("ms", 'time_unit = "hours"\n')
    with pytest.raises(DataError, match=r"deg.toml: degrees must be true or false, got 'yes'"):
        arm("deg", 'degrees = "yes"\n')
    # the matrix checks the file as fit does: one line, before any run starts, and nothing written
    arm("deg")  # writes deg.toml
    r = cli("run", "--systems", f"measured:{tmp_path / 'deg.toml'}", "--methods", "sysid", "--experiments", "indirect",
            "--seeds", "0", "--steps", "1", "--no-rollout", "--out", str(tmp_path / "matrix"))
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "deg.toml:train" in r.stderr and "is the log in degrees?" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "matrix" / "records").exists()
