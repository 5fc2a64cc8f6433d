"""What one measured trajectory lets validation see: its folds' scored samples
lie next to the states their fold was fitted on; the other trajectory does not."""

from __future__ import annotations

import json

from bench.studies.trajectories import split_figures
from tests.commandline import cli


def test_a_periodic_trajectorys_folds_score_states_far_nearer_than_the_test_trajectory():
    f = split_figures("kuka_lwr4", "swapped")
    assert f["folds"]["kind"] == "spans" and len(f["fold_median_distance"]) == f["folds"]["folds"] >= 2
    assert f["folds"]["gap_samples"] >= 1 and f["train_samples"] + f["test_samples"] > 0
    assert max(f["fold_median_distance"]) < f["test_median_distance"] / 10


def test_the_study_writes_its_figures_and_names_an_unknown_system_in_one_line(tmp_path):
    out = tmp_path / "t.json"
    r = cli("study", "trajectories", "--splits", "swapped", "--out", out)
    assert r.returncode == 0, r.stderr
    written = json.loads(out.read_text())
    assert list(written["splits"]) == ["swapped"] and "trajectories" in written["command"]
    r = cli("study", "trajectories", "--system", "no_such_arm", "--out", tmp_path / "u.json")
    assert r.returncode != 0 and len(r.stderr.strip().splitlines()) == 1 and "no_such_arm" in r.stderr
    assert not (tmp_path / "u.json").exists()
