"""The data format: generation, caching, CSV round trip, and bad input."""

from __future__ import annotations

import gzip
import os

import numpy as np
import pytest

from bench.core.data import DataError, Dataset, add_noise, generate
from bench.core.csv_format import MAX_COLUMNS, read_csv, write_csv


def test_generation_is_a_pure_cached_function(double_pendulum, tmp_path, monkeypatch):
    monkeypatch.setenv("SYRENETS_BENCH_CACHE", str(tmp_path))
    a = generate(double_pendulum, 100, 5)
    files = list(tmp_path.glob("*.npz"))
    assert len(files) == 1
    b = generate(double_pendulum, 100, 5)  # from the cache
    fresh = generate(double_pendulum, 100, 5, cache=False)
    for k in ("q", "qd", "qdd", "tau", "L"):
        assert np.array_equal(getattr(a, k), getattr(b, k))
        assert np.array_equal(getattr(a, k), getattr(fresh, k))
    generate(double_pendulum, 100, 6)
    generate(double_pendulum, 101, 5)
    assert len(list(tmp_path.glob("*.npz"))) == 3


def test_torques_come_from_the_suites_transform(double_pendulum):
    import torch

    from bench.physics.dynamics import euler_lagrange

    d = generate(double_pendulum, 64, 9, cache=False)
    t = d.tensors()
    tau = euler_lagrange(double_pendulum.lagrangian, t["q"], t["qd"], t["qdd"]).numpy()
    np.testing.assert_array_equal(d.tau, tau)
    np.testing.assert_array_equal(d.L, double_pendulum.lagrangian(t["q"], t["qd"]).numpy())
    assert isinstance(t["q"], torch.Tensor)


def test_csv_round_trip_is_exact(small_data, tmp_path):
    train, _ = small_data
    path = tmp_path / "d.csv"
    write_csv(train, path)
    back = read_csv(path, dof=2, system="double_pendulum")
    for k in ("q", "qd", "qdd", "tau", "L"):
        assert np.array_equal(getattr(train, k), getattr(back, k)), k
    header = path.read_text().splitlines()[0]
    assert header == "q_1,q_2,qd_1,qd_2,qdd_1,qdd_2,tau_1,tau_2,L"


def test_csv_without_L_and_with_extra_columns(tmp_path):
    path = tmp_path / "m.csv"
    path.write_text("t,q_1,qd_1,qdd_1,tau_1,label\n0.0,0.1,0.2,0.3,0.4,a\n0.1,0.5,0.6,0.7,0.8,b\n")
    d = read_csv(path)
    assert d.dof == 1 and d.L is None and len(d) == 2
    assert d.tau[1, 0] == 0.8
    with pytest.raises(DataError, match="direct experiment needs column 'L'"):
        d.target("direct")


GOOD = "q_1,q_2,qd_1,qd_2,qdd_1,qdd_2,tau_1,tau_2\n" + "0.1,0.2,0.3,0.4,0.5,0.6,0.7,0.8\n" * 3


@pytest.mark.parametrize(
    "text, message",
    [
        ("", "the file is empty"),
        ("q_1,q_2,qd_1,qd_2,qdd_1,qdd_2,tau_1,tau_2\n", "header but no rows"),
        (GOOD.replace("tau_2", "torque_2"), "missing column\\(s\\) tau_2"),
        (GOOD.replace("0.8\n", "nan\n", 1), "column tau_2 has a NaN or empty value in data row 1"),
        (GOOD.replace("0.8\n", "\n", 1), "column tau_2 has a NaN or empty value in data row 1"),
        (GOOD.replace("0.1,", "inf,", 2), "column q_1 has a inf value in data row 1"),
        (GOOD.replace("0.5,", "fast,", 1), "column qdd_1 has a non-numeric value 'fast' in data row 1"),
        ("a,b\n1,2\n", "no q_1 column"),
        ("q_1,q_2,q_3,qd_1,qd_2,qd_3,qdd_1,qdd_2,qdd_3,tau_1,tau_2,tau_3\n" + "0,0,0,0,0,0,0,0,0,0,0,0\n",
         "3 degrees of freedom .* but system 'double_pendulum' has 2"),
        # values whose square overflows would overflow a least-squares fit
        (GOOD.replace("0.7,", "1e308,", 1), "column tau_1 has a value too large to compute with \\(1e\\+308"),
        (GOOD.replace("0.7,", "-2e154,", 1), "column tau_1 has a value too large"),
        (GOOD.replace("tau_2", "tau_1"), "column name\\(s\\) 'tau_1' appear more than once"),
        (GOOD.replace("q_1,", "q_2,", 1), "column name\\(s\\) 'q_2' appear more than once"),
    ],
)
def test_bad_csv_gets_one_line_error_naming_file_and_problem(tmp_path, text, message):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(DataError, match=message) as info:
        read_csv(path, dof=2, system="double_pendulum")
    assert str(path) in str(info.value)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("separator", [",", ";", "\t", " "])
def test_a_header_wider_than_a_logs_is_refused_before_its_rows_are_read(tmp_path, separator, monkeypatch):
    import pandas as pd

    header = separator.join(["q_1", "qd_1", "qdd_1", "tau_1", *(f"x{k}" for k in range(MAX_COLUMNS))])
    path = tmp_path / "wide.csv.gz"
    with gzip.open(path, "wt") as f:
        f.write(header + "\n" + separator.join(["0"] * (MAX_COLUMNS + 4)) + "\n")
    monkeypatch.setattr(pd, "read_csv", lambda *a, **k: pytest.fail("pandas read the header"))
    with pytest.raises(DataError, match=f"{path}: its header has 10,004 columns or more, more than the 10,000"):
        read_csv(path, dof=1)


def test_missing_file_and_a_folder_given_as_a_file(tmp_path):
    with pytest.raises(DataError, match="no such file"):
        read_csv(tmp_path / "nope.csv")
    with pytest.raises(DataError, match="is a folder, not a file"):
        read_csv(tmp_path)


def test_values_up_to_the_overflow_bound_load(tmp_path):
    path = tmp_path / "big.csv"
    path.write_text(GOOD.replace("0.7,", "1e150,", 1))
    data = read_csv(path, dof=2)
    assert data.tau[0, 0] == 1e150 and np.isfinite(data.tau**2).all()


def test_write_is_atomic(small_data, tmp_path, monkeypatch):
    train, _ = small_data
    path = tmp_path / "out.csv"
    path.write_text("previous content\n")
    import pandas as pd

    def broken(self, *a, **k):
        raise RuntimeError("disk full")

    monkeypatch.setattr(pd.DataFrame, "to_csv", broken)
    with pytest.raises(RuntimeError):
        write_csv(train, path)
    assert path.read_text() == "previous content\n"
    assert os.listdir(tmp_path) == ["out.csv"]


def test_a_write_syncs_its_bytes_before_the_rename_and_its_folder_after(tmp_path, monkeypatch):
    from bench.core import fileio

    events, real_fsync, real_replace = [], os.fsync, os.replace

    def fsync(fd):
        events.append(("fsync", os.path.isdir(f"/proc/self/fd/{fd}") if os.path.exists("/proc/self/fd") else None))
        real_fsync(fd)

    def replace(a, b):
        events.append(("replace", None))
        real_replace(a, b)

    monkeypatch.setattr(fileio.os, "fsync", fsync)
    monkeypatch.setattr(fileio.os, "replace", replace)
    fileio.atomic_write(tmp_path / "record.json", lambda f: f.write("{}"))
    assert [e for e, _ in events] == ["fsync", "replace", "fsync"]
    if events[0][1] is not None:  # the first sync is the file's, the last the folder's
        assert events[0][1] is False and events[2][1] is True
    assert (tmp_path / "record.json").read_text() == "{}"


def test_dataset_checks_shapes():
    z = np.zeros((3, 2))
    with pytest.raises(DataError, match="share one"):
        Dataset(z, z, z, np.zeros((3, 1)))
    with pytest.raises(DataError, match="L must have shape"):
        Dataset(z, z, z, z, L=np.zeros(2))


def test_train_and_test_come_from_different_seeds():
    from bench.runner.run import load_data, make_system
    from bench.runner.spec import RunSpec

    spec = RunSpec("double_pendulum", "mlp", "direct", 3, 1.0, n_train=50, n_test=40)
    train, test = load_data(spec, make_system(spec))
    assert train.source.endswith("seed=3") and test.source.endswith("seed=1003")
    assert not np.isin(test.q[:, 0], train.q[:, 0]).any()


@pytest.mark.parametrize("experiment", ["direct", "indirect"])
def test_noise_is_a_stated_fraction_of_each_targets_std(double_pendulum, experiment):
    clean = generate(double_pendulum, 20000, 0)
    noisy = add_noise(clean, experiment, 0.1, seed=3)
    target, noisy_target = clean.target(experiment), noisy.target(experiment)
    ratio = (noisy_target - target).std(axis=0) / target.std(axis=0)
    np.testing.assert_allclose(ratio, 0.1, rtol=0.03)
    np.testing.assert_array_equal(noisy.q, clean.q)
    other = "tau" if experiment == "direct" else "L"
    np.testing.assert_array_equal(getattr(noisy, other), getattr(clean, other))
    np.testing.assert_array_equal(add_noise(clean, experiment, 0.1, seed=3).target(experiment), noisy_target)
    assert not np.array_equal(add_noise(clean, experiment, 0.1, seed=4).target(experiment), noisy_target)
    assert noisy.meta["noise"] == 0.1 and "0.1 x std noise" in noisy.source


def test_recordings_travel_through_csv_subsets_and_changes(small_data, tmp_path):
    train = small_data[0]
    assert train.recording is None and train.recordings() == []  # generated samples are independent
    labels = np.where(np.arange(len(train)) < len(train) // 3, "run b", "run a")
    data = train.replace(recording=labels)
    path = tmp_path / "r.csv"
    write_csv(data, path)
    back = read_csv(path, dof=2)
    assert back.recordings() == ["run b", "run a"]  # in order of first appearance
    np.testing.assert_array_equal(back.recording, labels)
    assert add_noise(back, "indirect", 0.1, 0).subset(slice(0, 3)).recording.tolist() == ["run b"] * 3


@pytest.mark.parametrize("cell", ["", " "])
def test_an_empty_recording_label_is_refused_naming_the_row(tmp_path, cell):
    path = tmp_path / "r.csv"
    path.write_text(GOOD.replace("tau_2\n", "tau_2,trajectory\n").replace("0.8\n", "0.8,a\n", 1)
                    .replace("0.8\n", f"0.8,{cell}\n", 1).replace("0.8\n", "0.8,b\n"))
    with pytest.raises(DataError, match=f"{path}: column trajectory has an empty value in data row 2"):
        read_csv(path, dof=2)


def test_filtered_velocity_signs_travel_through_csv_and_subsets(small_data, tmp_path):
    train = small_data[0]
    np.testing.assert_array_equal(train.velocity_sign(), np.sign(train.qd))  # no filter: the sign itself
    data = train.replace(sign_qd=np.tanh(train.qd / 0.1))
    path = tmp_path / "s.csv"
    write_csv(data, path)
    back = read_csv(path, dof=2)
    np.testing.assert_array_equal(back.velocity_sign(), data.sign_qd)
    np.testing.assert_array_equal(back.subset(slice(2, 5)).velocity_sign(), data.sign_qd[2:5])


def test_a_filtered_sign_for_some_joints_only_is_refused(tmp_path):
    path = tmp_path / "s.csv"
    path.write_text(GOOD.replace("tau_2\n", "tau_2,sign_qd_1\n").replace("0.8\n", "0.8,1\n"))
    with pytest.raises(DataError, match=f"{path}: has sign_qd_1 but not sign_qd_2"):
        read_csv(path, dof=2)


def test_trajectories_recordings_and_times_travel_through_csv(small_data, tmp_path):
    small_data = small_data[0]
    n = len(small_data)
    recording = np.where(np.arange(n) < n // 2, "run1", "run3")
    data = small_data.replace(recording=recording, trajectory=np.where(recording == "run1", "A", "B"),
                              time=np.arange(n) * 0.01)
    write_csv(data, tmp_path / "d.csv")
    back = read_csv(tmp_path / "d.csv")
    assert back.recordings() == ["run1", "run3"] and back.trajectories() == ["A", "B"]
    np.testing.assert_array_equal(back.time, data.time)
    part = back.subset(slice(0, 3))
    assert part.trajectories() == ["A"] and len(part.time) == 3
    # the trajectory column alone (older files, DFKI): each recording a trajectory of its own
    write_csv(small_data.replace(recording=recording), tmp_path / "old.csv")
    old = read_csv(tmp_path / "old.csv")
    assert old.recordings() == old.trajectories() == ["run1", "run3"] and old.trajectory is None


def test_recordings_without_trajectories_and_a_recording_on_two_are_refused(small_data, tmp_path):
    import pandas as pd

    frame = pd.read_csv(_written(small_data[0], tmp_path))
    frame["recording"] = "run1"
    frame.to_csv(tmp_path / "bare.csv", index=False)
    with pytest.raises(DataError, match=r"bare\.csv: recordings run1 \(column recording\) name no trajectory"):
        read_csv(tmp_path / "bare.csv")
    frame["trajectory"] = np.where(np.arange(len(frame)) % 2, "A", "B")
    frame.to_csv(tmp_path / "two.csv", index=False)
    with pytest.raises(DataError, match=r"two\.csv: recording 'run1' is labelled with two trajectories \(A, B\)"):
        read_csv(tmp_path / "two.csv")


def _written(data, tmp_path):
    path = tmp_path / "plain.csv"
    write_csv(data, path)
    return path


@pytest.mark.parametrize("sep", [";", "\t"])
def test_a_csv_separated_by_semicolons_or_tabs_reads_as_with_commas(tmp_path, sep):
    comma, other = tmp_path / "comma.csv", tmp_path / "other.csv"
    comma.write_text(GOOD)
    other.write_text(GOOD.replace(",", sep))
    a, b = read_csv(comma, dof=2), read_csv(other, dof=2)
    np.testing.assert_array_equal(a.tau, b.tau)
    np.testing.assert_array_equal(a.q, b.q)
    # a decimal comma beside semicolons is named as the value it makes, in one line
    other.write_text(GOOD.replace(",", sep).replace("0.7", "0,7", 1))
    with pytest.raises(DataError, match="column tau_1 has a non-numeric value '0,7' in data row 1"):
        read_csv(other, dof=2)


def test_a_space_separated_log_with_crlf_line_ends_reads_as_with_commas(tmp_path):
    comma, spaced = tmp_path / "comma.csv", tmp_path / "spaced.txt"
    comma.write_text(GOOD)
    lines = ["  ".join(line.split(",")) for line in GOOD.strip().splitlines()]
    spaced.write_bytes(("\r\n".join(lines) + "\r\n").encode())
    a, b = read_csv(comma, dof=2), read_csv(spaced, dof=2)
    np.testing.assert_array_equal(a.tau, b.tau)
    np.testing.assert_array_equal(a.qd, b.qd)


def test_a_header_that_stays_one_column_names_the_separators_tried(tmp_path):
    path = tmp_path / "glued.csv"
    path.write_text("q_1|qd_1|qdd_1|tau_1\n1|2|3|4\n")
    with pytest.raises(DataError) as err:
        read_csv(path)
    text = str(err.value)
    assert str(path) in text and "tried the separators comma, semicolon, tab, whitespace" in text
    assert len(text.splitlines()) == 1
