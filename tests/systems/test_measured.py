"""Every measured system is declared by one file of one shape
(systems/measured.py): the KUKA, the DFKI double pendulum and DeLaN's
characters all give named trajectories, two splits and time, so that each
gets driven rollouts and the laws that need time."""

from __future__ import annotations

import numpy as np
import pytest

from bench.core.data import DataError
from bench.residual.result import ResidualResult
from bench.residual.sensors import Sensor
from systems import SYSTEMS
from systems.measured import read_spec

MEASURED = ("kuka_lwr4", "dfki_double_pendulum", "delan_characters")


@pytest.mark.parametrize("name", MEASURED)
def test_each_measured_system_holds_out_whole_trajectories_with_time_on_both_splits(name):
    for split in ("default", "swapped"):
        system = SYSTEMS[name](split=split)
        train, test = system.load("train"), system.load("test")
        assert train.time is not None and test.time is not None
        assert not set(train.trajectories()) & set(test.trajectories())
        assert set(test.trajectories()) == set(system.measured.parts(split)["test"])
        for index in test.in_time_order():  # time runs forward within each recording
            assert np.all(np.diff(test.time[index]) > 0)
        # a time shift is among the laws the residual loop offers on it
        assert "time_shift" in {t.name for t in Sensor.exact(train).terms(train)}
    default, swapped = SYSTEMS[name](split="default"), SYSTEMS[name](split="swapped")
    assert default.measured.parts("default")["train"] == swapped.measured.parts("swapped")["test"]


def test_the_dfki_and_delan_splits_are_the_published_ones():
    dfki = SYSTEMS["dfki_double_pendulum"]()
    assert dfki.measured.parts("default") == {"train": ("00", "01", "02", "04"), "test": ("03", "05"),
                                             "all": ("00", "01", "02", "03", "04", "05")}
    delan = SYSTEMS["delan_characters"]().load("test")
    assert sorted(delan.recordings()) == ["e", "q", "v"] and len(delan) + len(SYSTEMS["delan_characters"]().load("train")) == 2913
    # DeLaN's rows are the samples as logged, accelerations included: no filter touches them
    assert delan.sign_qd is None and "filter" not in delan.meta


def write(tmp_path, text: str, rows: int = 40):
    t = np.arange(rows) * 0.01
    lines = ["run,t,q_1,qd_1,qdd_1,tau_1"] + [f"{'a' if k < rows // 2 else 'b'},{t[k % (rows // 2)]:.3f},"
                                               f"{np.sin(t[k]):.6f},{np.cos(t[k]):.6f},{-np.sin(t[k]):.6f},{t[k]:.6f}"
                                               for k in range(rows)]
    (tmp_path / "all.csv").write_text("\n".join(lines) + "\n")
    (tmp_path / "system.toml").write_text(text)
    return tmp_path / "system.toml"


def test_one_log_may_hold_every_recording_named_by_a_column(tmp_path):
    spec = read_spec(write(tmp_path, 'columns = "time=t,q_1=q_1,qd_1=qd_1,qdd_1=qdd_1,tau_1=tau_1"\ntest = ["b"]\n'
                                     'as_recorded = true\nrecordings_in = { file = "all.csv", column = "run" }\n'))
    assert [(r.name, r.trajectory) for r in spec.recordings] == [("a", "a"), ("b", "b")]
    assert spec.parts("swapped") == {"train": ("b",), "test": ("a",), "all": ("a", "b")}


def test_a_declaration_says_which_trajectories_chose_its_filter_and_so_which_tests_are_test_informed(tmp_path):
    spec = read_spec(write(tmp_path, 'columns = "time=t,q_1=q_1,qd_1=qd_1,qdd_1=qdd_1,tau_1=tau_1"\ntest = ["b"]\n'
                                     'recordings_in = { file = "all.csv", column = "run" }\n'
                                     '[filter]\ncutoff_hz = 10\nchosen_on = ["a"]\n'))
    assert spec.filter.cutoff_hz == 10 and spec.filter_chosen_on == ("a",)
    assert spec.test_informed("default") == [] and spec.test_informed("swapped") == ["a"]
    # the DFKI pendulum's cut-off was chosen on 00, 01, 02 and 04, which its swapped split tests on
    assert SYSTEMS["dfki_double_pendulum"].measured.test_informed("swapped") == ["00", "01", "02", "04"]
    assert SYSTEMS["dfki_double_pendulum"].measured.test_informed("default") == []
    assert SYSTEMS["kuka_lwr4"].measured.filter_chosen_on == ()
    # a rule chosen while trajectories' test figures were read: a test on them is test-informed, and says by what
    spec = read_spec(write(tmp_path, 'columns = "time=t,q_1=q_1,qd_1=qd_1,qdd_1=qdd_1,tau_1=tau_1"\ntest = ["b"]\n'
                                     'recordings_in = { file = "all.csv", column = "run" }\n'
                                     '[informed]\nrule = "a rule"\ntrajectories = ["b"]\n'))
    assert spec.test_informed("default") == ["b"] and spec.informed_by("default") == ["a rule"]
    assert spec.test_informed("swapped") == [] and spec.informed_by("swapped") == []
    assert SYSTEMS["kuka_lwr4"].measured.test_informed("default") == ["B"]


@pytest.mark.parametrize("text, message", [
    ('columns = "time=t,q_1=q_1,qd_1=qd_1,tau_1=tau_1"\ntest = ["b"]\nas_recorded = true\n'
     'recordings_in = { file = "all.csv", column = "run" }\n', "as_recorded needs the logged accelerations"),
    ('columns = "time=t,q_1=q_1,qd_1=qd_1,tau_1=tau_1"\ntest = ["b"]\n'
     'recordings_in = { file = "all.csv", column = "lap" }\n', "missing column lap"),
    ('columns = "time=t,q_1=q_1,qd_1=qd_1,tau_1=tau_1"\ntest = ["b"]\n'
     'recordings_in = { file = "all.csv", column = "run" }\n[recordings]\nr = { file = "all.csv", trajectory = "x" }\n',
     "one of the two"),
    ('columns = "time=t,q_1=q_1,qd_1=qd_1,tau_1=tau_1"\ntest = ["c"]\n'
     'recordings_in = { file = "all.csv", column = "run" }\n', "test names trajectory"),
    ('columns = "time=t,q_1=q_1,qd_1=qd_1,tau_1=tau_1"\ntest = ["b"]\n'
     'recordings_in = { file = "all.csv", column = "run" }\n[filter]\nchosen_on = ["a", "c"]\n',
     r"\[filter\] chosen_on must list trajectories of the recordings \(a, b\)"),
    ('columns = "time=t,q_1=q_1,qd_1=qd_1,tau_1=tau_1"\ntest = ["b"]\n'
     'recordings_in = { file = "all.csv", column = "run" }\n[filter]\nchosen_on = 3\n', r"\[filter\] chosen_on"),
    ('columns = "time=t,q_1=q_1,qd_1=qd_1,tau_1=tau_1"\ntest = ["b"]\nfilter = 6\n'
     'recordings_in = { file = "all.csv", column = "run" }\n', r"\[filter\] must be a table"),
    # a filter's numbers of the wrong kind, and what the schema holds every field to (its type, its range, a
    # finite number): one line each, never a traceback
    *[('columns = "time=t,q_1=q_1,qd_1=qd_1,tau_1=tau_1"\ntest = ["b"]\n'
       f'recordings_in = {{ file = "all.csv", column = "run" }}\n{setting}\n', message)
      for setting, message in [("[filter]\ndecimate = 1.5", r"\[filter\]: decimate must be a whole number >= 1, got 1.5"),
                               ("[filter]\norder = true", r"\[filter\]: order must be a whole number >= 1, got True"),
                               ("[filter]\ntrim_s = nan", r"filter.trim_s is nan, not a finite number"),
                               ("[filter]\ncutoff_hz = inf", r"filter.cutoff_hz is inf, not a finite number"),
                               ('[filter]\ncutoff_hz = "6"', r"\[filter\]: cutoff_hz must be a finite number, got '6'"),
                               ("rate_hz = inf", r"rate_hz is inf, not a finite number"),
                               ("locked_at = { j = nan }", r"locked_at.j is nan, not a finite number"),
                               ("root = 3", r"root must be a link's name"),
                               ('time_unit = "h"', r"time_unit must be one of s, ms, us"),
                               ("[filter]\norder = 100", r"filter.order: 100 is greater than the maximum of 64")]],
    ('columns = "time=t,q_1=q_1,qd_1=qd_1,tau_1=tau_1"\ntest = ["c"]\n[recordings]\n'
     'r1 = { file = "all.csv", trajectory = "a", rows = 3 }\nr2 = { file = "system.toml", trajectory = "c" }\n',
     r"recordings.r1: Additional properties are not allowed \('rows' was unexpected\)"),
    ('columns = "time=t,q_1=q_1,qd_1=qd_1,tau_1=tau_1"\ntest = ["c"]\n[recordings]\n'
     'r1 = { file = "all.csv", trajectory = { x = 1 } }\nr2 = { file = "system.toml", trajectory = "c" }\n',
     r"recordings.r1.trajectory: \{'x': 1\} is not of type 'string'"),
    # one log as the training and the test trajectory
    ('columns = "time=t,q_1=q_1,qd_1=qd_1,tau_1=tau_1"\ntest = ["c"]\n[recordings]\n'
     'r1 = { file = "all.csv", trajectory = "a" }\nr2 = { file = "all.csv", trajectory = "c" }\n',
     r"recordings 'r1' and 'r2' both read .*all.csv: one log is one recording"),
])
def test_a_bad_declaration_is_refused_in_one_line_naming_the_file(tmp_path, text, message):
    with pytest.raises(DataError, match=message) as caught:
        read_spec(write(tmp_path, text))
    assert "\n" not in str(caught.value) and ("system.toml" in str(caught.value) or "all.csv" in str(caught.value))


def test_a_test_log_that_is_a_copy_of_a_training_log_is_refused(tmp_path):
    path = write(tmp_path, 'columns = "time=t,q_1=q_1,qd_1=qd_1,tau_1=tau_1"\ntest = ["c"]\n[recordings]\n'
                           'r1 = { file = "all.csv", trajectory = "a" }\nr2 = { file = "copy.csv", trajectory = "c" }\n')
    (tmp_path / "copy.csv").write_bytes((tmp_path / "all.csv").read_bytes())
    with pytest.raises(DataError, match="test recording 'r2' \\(copy.csv\\) holds the same log as training recording 'r1'"):
        read_spec(path)
    (tmp_path / "copy.csv").write_text((tmp_path / "all.csv").read_text().replace("0.010", "0.011"))  # same size
    assert [r.name for r in read_spec(path).recordings] == ["r1", "r2"]


def test_a_residual_file_published_under_the_old_key_still_reads():
    result = ResidualResult(system="s", method="sysid", mse_before={"train": 3.0}, mse_after={"train": 1.5},
                            effects=[], rounds=[], lagrangian=None, seconds=0.0, budget_s=60.0, fit_budget_s=30.0,
                            seed=0, train_source="", test_source=None,
                            mse_heldout_trajectories={"before": 2.0, "after": 1.0})
    old = {("mse_heldout_recordings" if k == "mse_heldout_trajectories" else k): getattr(result, k)
           for k in ("system", "method", "mse_before", "mse_after", "effects", "rounds", "lagrangian", "seconds",
                     "budget_s", "fit_budget_s", "seed", "train_source", "test_source", "mse_heldout_trajectories")}
    assert ResidualResult.from_json(old).mse_heldout_trajectories == {"before": 2.0, "after": 1.0}


def test_convert_refuses_logged_accelerations_it_would_not_use(tmp_path):
    from tests.commandline import cli

    path = write(tmp_path, "")
    r = cli("convert", "--columns", "time=t,q_1=q_1,qd_1=qd_1,qdd_1=qdd_1,tau_1=tau_1", str(tmp_path / "all.csv"),
            "--out", str(tmp_path / "out.csv"))
    assert r.returncode == 2 and "as_recorded" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out.csv").exists() and path.exists()


def test_a_log_with_a_gap_is_split_into_segments_of_its_trajectory_none_bridged(tmp_path):
    """Six seconds of rows lost from a training recording of the DFKI pendulum: the recording is two segments of
    its trajectory, each filtered on its own, no sample in the gap; the record says so, and the fit is as good on
    the test trajectories as the intact log's (bridging the gap by interpolation fitted a line through it)."""
    import json
    import shutil

    import pandas as pd

    from bench.runner.plugins import system_plugins
    from systems.urdf_arm import DATA_DIR
    from tests.commandline import cli

    for name in ("dfki_double_pendulum_arm.toml", "dfki_double_pendulum.urdf.gz",
                 *(f"dfki_trajectory_0{k}.csv.gz" for k in range(6))):
        shutil.copy(DATA_DIR / name, tmp_path / name)
    frame = pd.read_csv(tmp_path / "dfki_trajectory_00.csv.gz")
    lost = (frame["time"] > 2.0) & (frame["time"] < 8.0)
    frame[~lost].to_csv(tmp_path / "dfki_trajectory_00.csv.gz", index=False)
    declared = tmp_path / "gapped_arm.toml"  # its own name: the shipped file registers under the other
    (tmp_path / "dfki_double_pendulum_arm.toml").rename(declared)
    (name,), _ = system_plugins([f"measured:{declared}"])
    train = SYSTEMS[name]().load("train")
    segments = [r for r in train.recordings() if r.startswith("00")]
    assert segments == ["00/1", "00/2"]
    inside = np.isin(train.recording, segments)
    assert set(train.trajectory[inside]) == {"00"}
    assert not ((train.time[inside] > 2.0) & (train.time[inside] < 8.0)).any()
    assert "00 split at 1 gap(s) of 5 steps or more into 2 segments" in train.source
    records = {}
    for which, arm in (("gapped", declared), ("intact", DATA_DIR / "dfki_double_pendulum_arm.toml")):
        out = tmp_path / f"{which}.json"
        r = cli("fit", "--system", f"measured:{arm}", "--method", "sysid", "--experiment", "indirect", "--steps", 1,
                "--json", out)
        assert r.returncode == 0, r.stderr
        records[which] = json.loads(out.read_text())
    assert "00 split at 1 gap(s) of 5 steps or more into 2 segments" in records["gapped"]["details"]["train_source"]
    assert records["gapped"]["test_mse"] < 1.05 * records["intact"]["test_mse"]
