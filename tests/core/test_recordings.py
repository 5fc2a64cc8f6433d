"""Robot logs: naming their columns, and logs the filter cannot take."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from bench.core.data import DataError
from bench.core.errors import ConfigError
from tests.commandline import cli
from bench.core.recordings import ColumnMap, FilterSpec, Recording, preprocess, preprocess_segments, resampling


def test_a_column_map_names_every_joints_columns():
    m = ColumnMap.parse("time=t, q_1=p1, qd_1=v1, tau_1=e1, q_2=p2, qd_2=v2, tau_2=e2")
    assert m == ColumnMap("t", ("p1", "p2"), ("v1", "v2"), ("e1", "e2")) and m.dof == 2


def test_a_column_map_without_time_is_a_log_whose_rate_is_stated():
    m = ColumnMap.parse("q_1=p,qd_1=v,tau_1=e")
    assert m.time is None and m.columns == ("p", "v", "e")


@pytest.mark.parametrize("text, message", [
    ("time=t,q_1=p,qd_1=v,tau_1=e,q_3=x,qd_3=y,tau_3=z", "missing q_2, qd_2, tau_2"),
    ("time=t,q_1=p,qd_1=v,tau_1=e,acc_1=a", "unknown role"),
    ("time=t,time=s,q_1=p,qd_1=v,tau_1=e", "time is given twice"),
    ("time=t,q_1", "expected ROLE=COLUMN"),
])
def test_a_bad_column_map_is_refused_in_one_line(text, message):
    with pytest.raises(ConfigError, match=message):
        ColumnMap.parse(text)


def test_a_time_column_spanning_ages_is_refused_before_any_memory_is_taken():
    # found by the generated-input tests: one cell of 1e150 in the time column asked for a grid of 1e152 samples
    t = np.array([0.0, 1.0, 2.0, 1e150])
    rec = Recording(t, np.zeros((4, 1)), np.zeros((4, 1)), np.zeros((4, 1)))
    with pytest.raises(DataError, match="is the time column in seconds"):
        preprocess(rec)


def test_the_filtered_velocity_sign_keeps_viscous_friction_unbiased():
    # Coulomb friction's jump, low-passed with the torque, is rounded over the filter's span: a line
    # through sign(qd) and qd then fits a steeper viscous slope; the same low-pass on sign(qd) does not
    dt, F_c, b = 0.002, 0.5, 0.2
    t = np.arange(0.0, 20.0, dt)
    qd = 0.4 * np.sin(2 * np.pi * 0.7 * t) + 0.3 * np.sin(2 * np.pi * 1.9 * t + 1.0)
    q = np.cumsum(qd) * dt
    rec = Recording(t, q[:, None], qd[:, None], (F_c * np.sign(qd) + b * qd)[:, None])
    s = preprocess(rec, FilterSpec(dt=dt, cutoff_hz=20.0))

    def fit(sign):
        return np.linalg.lstsq(np.c_[sign[:, 0], s["qd"][:, 0]], s["tau"][:, 0], rcond=None)[0]

    assert abs(fit(np.sign(s["qd"]))[1] / b - 1) > 0.05  # the bias the filtered sign removes
    np.testing.assert_allclose(fit(s["sign_qd"]), [F_c, b], rtol=2e-3)


@pytest.fixture(scope="module")
def log_at_100hz(tmp_path_factory):
    """A simulated double pendulum's 100 Hz log, with its time column and without it."""
    folder = tmp_path_factory.mktemp("log")
    assert cli("robot-log", "--system", "double_pendulum", "--recordings", "1", "--seconds", "6", "--rate-hz", "100",
               "--out", folder).returncode == 0
    timed = folder / "recording_0.csv"
    frame = pd.read_csv(timed)
    frame.drop(columns=["time"]).to_csv(folder / "timeless.csv", index=False)
    columns = [c for c in frame.columns if c != "time"]
    mapping = ",".join(f"{role}_{j}={c}" for j in (1, 2) for role, c in
                       zip(("q", "qd", "tau"), [c for c in columns if c.startswith(f"joint{j}_")]))
    return folder, mapping


def test_a_log_without_time_converts_at_its_stated_rate_as_with_its_time_column(log_at_100hz, tmp_path):
    folder, mapping = log_at_100hz
    common = ["--dt", "0.01", "--decimate", "1", "--cutoff-hz", "10", "--trajectory", "a"]
    assert cli("convert", "--columns", f"time=time,{mapping}", *common, "--out", tmp_path / "timed.csv",
               folder / "recording_0.csv").returncode == 0
    r = cli("convert", "--columns", mapping, "--rate", "100", *common, "--out", tmp_path / "rated.csv",
            folder / "timeless.csv")
    assert r.returncode == 0, r.stderr
    timed, rated = pd.read_csv(tmp_path / "timed.csv"), pd.read_csv(tmp_path / "rated.csv")
    for column in ("q_1", "qd_2", "qdd_1", "tau_2", "time"):
        np.testing.assert_allclose(rated[column], timed[column], rtol=1e-9, atol=1e-9)


def test_a_stated_rate_its_velocities_deny_is_refused_with_the_interval_they_suggest(log_at_100hz, tmp_path):
    folder, mapping = log_at_100hz
    out = tmp_path / "rated.csv"
    r = cli("convert", "--columns", mapping, "--rate", "200", "--trajectory", "a", "--out", out, folder / "timeless.csv")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "timeless.csv: the stated rate of 200 Hz puts rows 5 ms apart, but its positions and velocities say " \
           "10 ms (100 Hz)" in r.stderr
    assert not out.exists()
    r = cli("convert", "--columns", mapping, "--trajectory", "a", "--out", out, folder / "timeless.csv")
    assert r.returncode == 2 and "no time column" in r.stderr and not out.exists()


def test_a_measured_systems_file_states_the_rate_of_logs_without_time(log_at_100hz, tmp_path):
    from systems.measured import read_spec

    folder, mapping = log_at_100hz
    lines = (folder / "timeless.csv").read_text().splitlines(keepends=True)
    (folder / "timeless_b.csv").write_text("".join(lines[:-1]))  # another log: one log is one recording
    body = (f'columns = "{mapping}"\ntest = ["b"]\n[recordings]\n'
            f'a = {{ file = "{folder / "timeless.csv"}", trajectory = "a" }}\n'
            f'b = {{ file = "{folder / "timeless_b.csv"}", trajectory = "b" }}\n')
    path = tmp_path / "arm.toml"
    path.write_text(body)
    with pytest.raises(DataError, match="columns name no time column: name it .* or give the logs' rate .rate_hz."):
        read_spec(path)
    path.write_text("rate_hz = 100\n" + body)
    assert read_spec(path).rate_hz == 100.0
    path.write_text("rate_hz = 100\n" + body.replace(f'columns = "', 'columns = "time=time,'))
    with pytest.raises(DataError, match="give one of them"):
        read_spec(path)


def _uniform_recording(dt: float, seconds: float = 4.0) -> Recording:
    t = np.arange(0.0, seconds, dt)
    q = np.sin(2 * np.pi * 0.5 * t)[:, None]
    return Recording(t, q, np.gradient(q[:, 0], t)[:, None], np.cos(t)[:, None])


def test_a_log_keeps_its_own_step_unless_asked_and_a_resampling_is_stated():
    rec = _uniform_recording(0.01)
    kept = preprocess(rec)
    assert resampling(rec, FilterSpec()) is None
    np.testing.assert_allclose(np.diff(kept["time"]), 0.01)
    np.testing.assert_allclose(kept["time"], rec.time[25:-25] - rec.time[0])  # 0.25 s trimmed from each end
    asked = FilterSpec(dt=0.002)
    assert resampling(rec, asked) == "resampled from the log's 10 ms (median step) to 2 ms"
    assert len(preprocess(rec, asked)["q"]) == pytest.approx(5 * len(kept["q"]), abs=10)
    assert resampling(rec, FilterSpec(dt=0.01)) is None  # asking for the log's own step moves nothing


def test_a_log_with_a_gap_is_split_there_each_segment_filtered_on_its_own_and_none_bridged():
    rec = _uniform_recording(0.01, seconds=12.0)
    keep = (rec.time < 4.0) | (rec.time >= 8.0) & (rec.time < 11.6) | (rec.time >= 11.9)  # 4 s lost, then 0.3 s
    gapped = Recording(rec.time[keep], rec.q[keep], rec.qd[keep], rec.tau[keep])
    parts, words = preprocess_segments(gapped, FilterSpec())
    assert len(parts) == 2  # the last 0.1 s is too short for the filter: left out, and counted
    assert words == ("split at 2 gap(s) of 5 steps or more into 3 segments, each filtered on its own and none "
                     "bridged: 2 kept, 660 samples; 1 too short for the filter left out (10 rows)")
    times = np.concatenate([p["time"] for p in parts])
    assert not ((times > 4.0) & (times < 8.0)).any() and not ((times > 11.6) & (times < 11.9)).any()
    np.testing.assert_allclose(parts[1]["time"][0], 8.25)  # counted from the recording's first row, trimmed
    # each segment is the intact log's filtered alone: the samples near its own ends are the filter's, not a bridge
    alone = preprocess(Recording(*(v[(rec.time >= 8.0) & (rec.time < 11.6)] for v in (rec.time, rec.q, rec.qd,
                                                                                     rec.tau))), FilterSpec())
    np.testing.assert_allclose(parts[1]["q"], alone["q"])
    whole, none = preprocess_segments(rec, FilterSpec())
    assert none is None and len(whole) == 1
    with pytest.raises(DataError, match="split it into 2 segments, each too short for the filter"):
        preprocess_segments(Recording(*(v[(rec.time < 0.3) | (rec.time > 11.7)] for v in (rec.time, rec.q, rec.qd,
                                                                                          rec.tau))), FilterSpec())


def test_rows_whose_steps_vary_are_put_on_their_median_step_and_it_is_said():
    rec = _uniform_recording(0.01)
    t = rec.time.copy()
    t[1::7] += 0.004
    moved = Recording(t, rec.q, rec.qd, rec.tau)
    words = resampling(moved, FilterSpec())
    assert words.startswith("rows 6 to 14 ms apart interpolated onto a uniform 10 ms")
    np.testing.assert_allclose(np.diff(preprocess(moved)["time"]), 0.01)


def test_convert_writes_a_log_with_a_gap_as_segments_of_its_trajectory(tmp_path):
    t = np.arange(0.0, 12.0, 0.01)
    t = t[(t < 4.0) | (t >= 8.0)]
    log = tmp_path / "lap.csv"
    pd.DataFrame({"t": t, "p": np.sin(t), "v": np.cos(t), "f": np.sin(2 * t)}).to_csv(log, index=False)
    out = tmp_path / "out.csv"
    r = cli("convert", log, "--columns", "time=t,q_1=p,qd_1=v,tau_1=f", "--cutoff-hz", 10, "--trim", 0.1, "--out", out)
    assert r.returncode == 0, r.stderr
    assert "recording lap: split at 1 gap(s) of 5 steps or more into 2 segments" in r.stdout
    frame = pd.read_csv(out)
    assert frame.groupby("recording").size().to_dict() == {"lap/1": 380, "lap/2": 380}
    assert set(frame["trajectory"]) == {"lap"}
    assert not ((frame["time"] > 4.0) & (frame["time"] < 8.0)).any()
