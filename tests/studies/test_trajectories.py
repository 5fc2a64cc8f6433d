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
    # select's regions of the states reach far further than spans do; the arm's joint ranges lie further still
    assert f["regions_median_distance_median"] > 100 * max(f["fold_median_distance"])
    assert f["joint_ranges_median_distance"] > 2 * f["test_median_distance"]


def test_the_joint_ranges_are_states_inside_the_arms_sampling_domain():
    from bench.studies.trajectories import joint_ranges
    from systems import SYSTEMS

    arm = SYSTEMS["kuka_lwr4"]()
    states = joint_ranges(arm, n=500)
    for name in ("q", "qd"):
        lo, hi = arm.default_domain.bounds(name, arm.dof)
        values = getattr(states, name)
        assert values.shape == (500, arm.dof) and (values >= lo).all() and (values <= hi).all()
        assert (values.max(axis=0) - values.min(axis=0) > 0.9 * (hi - lo)).all()  # they span the ranges


def test_the_study_writes_its_figures_and_names_an_unknown_system_in_one_line(tmp_path):
    out = tmp_path / "t.json"
    r = cli("study", "trajectories", "--splits", "swapped", "--out", out)
    assert r.returncode == 0, r.stderr
    written = json.loads(out.read_text())
    assert list(written["splits"]) == ["swapped"] and "trajectories" in written["command"]
    r = cli("study", "trajectories", "--system", "no_such_arm", "--out", tmp_path / "u.json")
    assert r.returncode != 0 and len(r.stderr.strip().splitlines()) == 1 and "no_such_arm" in r.stderr
    assert not (tmp_path / "u.json").exists()
