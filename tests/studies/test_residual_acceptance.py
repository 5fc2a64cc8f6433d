"""The residual acceptance script: what it expects matches what the loop names."""

from __future__ import annotations

import json

import pytest

from bench.physics.undeclared import parse_effects
from bench.studies.acceptance_scoring import expected, score
from bench.studies.acceptance_cases import DEVELOPMENT, DEVELOPMENT_CASES, EVALUATION, effects
from bench.runner.ledger import Ledger
from bench.studies.residual_acceptance import Case, run_case, worth
from tests.commandline import cli


def test_each_case_expects_its_effects_under_the_names_and_joints_the_loop_reports():
    want = {case: expected(parse_effects(items, 2), 2) for case, items in DEVELOPMENT_CASES.items()}
    assert want["armature"] == {("armature", (1,)): {"I": 0.3}}
    assert want["elbow_spring"] == {("coupled_spring", (1, 2)): {"k": 3.0}}
    assert want["stribeck"] == {("stribeck_friction", (1,)): {"F_c": 1.0, "F_s": 2.0, "v_s": 0.5, "b": 0.3}}
    assert want["tip_payload"] == {("tip_payload", (1, 2)): {"m": 0.5}}
    assert want["coulomb_viscous"] == {("coulomb_viscous_friction", (1,)): {"F_c": 1.5, "b": 0.8},
                                       ("coulomb_viscous_friction", (2,)): {"F_c": 0.7, "b": 0.5}}
    assert want["smooth_coulomb"][("smooth_coulomb", (2,))] == {"F_c": 0.7, "v_s": 0.02, "b": 0.0}
    assert want["offset_spring"] == {("offset_spring", (2,)): {"k": 2.0, "q0": 0.3}}
    assert want["load_coulomb"] == {("load_friction", (1,)): {"mu": 0.1}, ("coulomb_friction", (1,)): {"F_c": 0.5}}
    assert want["clean"] == {}


def test_a_case_run_names_the_elbow_spring_and_its_stiffness():
    # bounded by work: under a time budget, on a loaded machine, tracing had no time left now and then
    row = run_case("elbow_spring", 0.0, "sysid", 1500, 500, None, steps=1000)
    assert row["right"] == row["put_in"] == row["reported"] == row["true_reported"] == 1
    assert row["found"] == ["coupled_spring j1-2"] and row["spurious"] == []
    assert row["worst_error"] < 0.02 and row["after"] < 1e-6 * row["before"]
    assert 0 <= row["statistics_seconds"] <= row["seconds"]


def test_a_gain_is_expected_relative_to_the_loops_reference_joint():
    fx = parse_effects(["torque_gain=1.1,0.99"], 2)
    assert expected(fx, 2, reference=0) == {("torque_gain", (2,)): {"g": pytest.approx(0.9)}}
    assert expected(fx, 2, reference=1) == {("torque_gain", (1,)): {"g": pytest.approx(1.1 / 0.99)}}
    assert expected(parse_effects(["periodic_torque=1:0.3,6,0.5"], 2), 2) == {
        ("periodic_torque", (1,)): {"A": pytest.approx(0.3), "N": 6.0, "phi": pytest.approx(0.5)}}


def test_a_run_is_scored_by_law_joints_and_parameters():
    want = {("coulomb_viscous_friction", (1,)): {"F_c": 1.5, "b": 0.8}, ("torque_gain", (2,)): {"g": 0.96}}
    found = {("coulomb_friction", (1,)): {"F_c": 2.2},  # the simpler law it contains: put in, not right
             ("torque_gain", (2,)): {"g": 0.9635},  # within 1 % of the gain
             ("armature", (2,)): {"I": 0.3}}  # not put in
    s = score(want, found)
    assert (s["right"], s["put_in"], s["reported"], s["true_reported"]) == (1, 2, 3, 2)
    assert s["spurious"] == ["armature j2"]
    assert s["as"] == {"coulomb_viscous_friction j1": "coulomb_friction j1", "torque_gain j2": "torque_gain"}
    off = score({("torque_gain", (2,)): {"g": 0.96}}, {("torque_gain", (2,)): {"g": 0.97}})
    assert off["right"] == 0 and off["as"] == {"torque_gain j2": "torque_gain (off by more than 1%)"}
    # off by more than 10 %, but within two of its standard errors: consistent with the truth, not right
    loose = score({("viscous_friction", (1,)): {"b": 0.8}}, {("viscous_friction", (1,)): {"b": 0.95}},
                  {("viscous_friction", (1,)): {"b": 0.1}})
    assert (loose["right"], loose["consistent"]) == (0, 1)
    tight = score({("viscous_friction", (1,)): {"b": 0.8}}, {("viscous_friction", (1,)): {"b": 0.95}},
                  {("viscous_friction", (1,)): {"b": 0.05}})
    assert (tight["right"], tight["consistent"]) == (0, 0)
    wrong_n = score({("periodic_torque", (1,)): {"A": 0.3, "N": 6.0, "phi": 0.5}},
                    {("periodic_torque", (1,)): {"A": 0.3, "N": 5.0, "phi": 0.5}})
    assert wrong_n["right"] == wrong_n["consistent"] == 0 and wrong_n["true_reported"] == 1


def test_the_evaluation_set_draws_each_case_from_its_ranges_and_no_test_reads_its_seeds():
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    # the draw, tried on seeds of the development set's, never the evaluation set's own
    for case in DEVELOPMENT_CASES:
        drawn = [effects(EVALUATION, case, seed) for seed in (0, 1)]
        assert drawn[0] == effects(EVALUATION, case, 0)  # the same seed draws the same values
        for items in drawn:
            assert set(expected(parse_effects(items, 2), 2)) == set(expected(parse_effects(DEVELOPMENT_CASES[case], 2), 2))
        assert case == "clean" or drawn[0] != drawn[1] != DEVELOPMENT_CASES[case]
    assert effects(DEVELOPMENT, "spring", 5) == DEVELOPMENT_CASES["spring"]
    # the evaluation seeds, read from the module's text, appear in no test
    source = (root / "bench" / "studies" / "acceptance_cases.py").read_text()
    names = ["EVALUATION" + "_SEEDS", "EVALUATION" + "_CASES"]  # spelled so that this file does not hold them
    held_out = re.search(rf"^{names[0]} = \((.*?)\)", source, re.M)[1].split(",")
    assert len(held_out) == 3
    for path in (root / "tests").rglob("*.py"):
        text = path.read_text()
        assert not any(name in text for name in names), path
        assert not any(re.search(rf"\b{seed.strip()}\b", text) for seed in held_out), path


def test_every_method_is_judged_on_the_same_cases():
    rows = [{"set": "evaluation", "case": "spring", "seed": 5, "method": m, "noise": z, "before": b, "rows": 100,
             "floor": f} for m, z, b, f in (("sysid", 0, 2.0, 0.0), ("sparse", 0, 0.5, 0.0),
                                            ("sysid", 0.1, 3.0, 1.0), ("sparse", 0.1, 3.0, 1.0))]
    worth(rows)
    assert [r["worth"] for r in rows if r["noise"]] == [50.0, 50.0]  # the least of the methods' clean residuals


def test_the_study_resumes_from_the_runs_it_kept_and_drops_them_once_its_page_is_written(tmp_path):
    out = tmp_path / "acceptance.md"
    kept = Case(DEVELOPMENT, "spring", 0.0, "sysid", 300, 150, None, 10, 0)
    ledger = Ledger(out)
    # a run finished before the study stopped; its seconds mark it as the one kept
    finished = {**run_case(**kept.payload()), "seconds": 12345.0}
    ledger.add("development spring noise=0 seed=0 sysid", kept, finished)
    r = cli("study", "residual-acceptance", "--cases", "spring", "--methods", "sysid", "--noise", "0", "0.01",
            "--sets", DEVELOPMENT, "--seeds", "0", "--n-train", 300, "--n-test", 150, "--steps", 10,
            "--workers", 1, "--out", out)
    assert r.returncode == 0, r.stderr
    assert f"1 of 2 job(s) finished before, by this code: taken from {ledger.path}" in r.stdout
    rows = json.loads(out.with_suffix(".json").read_text())
    assert [(row["noise"], row["seconds"] == 12345.0) for row in rows] == [(0.0, True), (0.01, False)]
    assert rows[1]["right"] == 2  # the run it did make names both springs
    assert not ledger.path.exists() and out.is_file()
