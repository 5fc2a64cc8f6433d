"""The residual acceptance script: what it expects matches what the loop names."""

from __future__ import annotations

from bench.core.undeclared import parse_effects
from bench.experiments.acceptance_scoring import expected
from bench.experiments.residual_acceptance import CASES, run_case


def test_each_case_expects_its_effects_under_the_names_and_joints_the_loop_reports():
    want = {case: expected(parse_effects(items, 2), 2) for case, items in CASES.items()}
    assert want["armature"] == {("armature", (1,)): {"I": 0.3}}
    assert want["elbow_spring"] == {("coupled_spring", (1, 2)): {"k": 3.0}}
    assert want["stribeck"] == {("stribeck_friction", (1,)): {"F_c": 1.0, "F_s": 2.0, "v_s": 0.5, "b": 0.3}}
    assert want["tip_payload"] == {("tip_payload", (1, 2)): {"m": 0.5}}
    assert want["coulomb_viscous"] == {("coulomb_viscous_friction", (1,)): {"F_c": 1.5, "b": 0.8},
                                       ("coulomb_viscous_friction", (2,)): {"F_c": 0.7, "b": 0.5}}
    assert want["smooth_coulomb"][("smooth_coulomb", (2,))] == {"F_c": 0.7, "v_s": 0.02, "b": 0.0}
    assert want["offset_spring"] == {("offset_spring", (2,)): {"k": 2.0, "q0": 0.3}}
    assert want["clean"] == {}


def test_a_case_run_names_the_elbow_spring_and_its_stiffness():
    # bounded by work: under a time budget, on a loaded machine, tracing had no time left now and then
    row = run_case("elbow_spring", 0.0, "sysid", 1500, 500, None, steps=1000)
    assert row["right"] == row["put_in"] == row["reported"] == row["true_reported"] == 1
    assert row["found"] == ["coupled_spring j1-2"] and row["spurious"] == []
    assert row["worst_error"] < 0.02 and row["after"] < 1e-6 * row["before"]
    assert 0 <= row["statistics_seconds"] <= row["seconds"]
