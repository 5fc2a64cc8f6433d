"""The geared arm of the selection benchmark's development cases: its URDF, its cases, and a residual that is
mostly viscous friction on two training trajectories, which the loop finds in its first round."""

from __future__ import annotations

import gzip

import numpy as np
import pytest

from bench.core.budget import Budget
from bench.core.data import Dataset
from bench.residual import residual_loop
from bench.runner.plugins import register_by_file
from bench.studies import geared_arm, selection_benchmark
from systems import get_system

VISCOUS = (150.0, 160.0, 80.0, 40.0, 30.0, 20.0)


@pytest.fixture(scope="module")
def arm():
    return get_system(register_by_file(f"urdf:{geared_arm.URDF}"))


def test_the_shipped_urdf_is_the_one_written_from_the_ur5_and_is_a_large_arm(arm):
    assert gzip.decompress(geared_arm.URDF.read_bytes()).decode() == geared_arm.urdf_text()
    ur5 = get_system("ur5")
    assert sum(i.mass for i in arm.model.inertias) == pytest.approx(
        geared_arm.MASS * sum(i.mass for i in ur5.model.inertias))
    assert [(lo, hi, v) for lo, hi, v in zip(arm.model.lowerPositionLimit, arm.model.upperPositionLimit,
                                             arm.model.velocityLimit)] == list(geared_arm.LIMITS)
    # the shoulder holds the arm stretched out: gravity scales with mass times length
    q = np.zeros((1, 6))
    ratio = arm.inverse_dynamics(q, q, q)[0, 1] / ur5.inverse_dynamics(q, q, q)[0, 1]
    assert ratio == pytest.approx(geared_arm.MASS * geared_arm.LENGTH, rel=1e-6)


def test_the_development_set_holds_the_geared_arm_and_two_and_three_trajectories_each_recorded_twice(tmp_path):
    names = [c.name for c in selection_benchmark.cases("development")]
    assert "geared_two_geared_0" in names
    assert {f"{a}_{lay}_{e}_0" for a in selection_benchmark.ARMS for lay in ("two", "three")
            for e in ("drive", "sensor")} <= set(names)
    assert not any("two" in c.name or "three" in c.name or "geared" in c.name
                   for c in selection_benchmark.cases("former_evaluation"))
    assert selection_benchmark.resolve("auto", "two") == selection_benchmark.resolve("auto", "several")
    declared = selection_benchmark.make(selection_benchmark.Case("ur5", "three", "drive", 0), tmp_path)
    text = declared.read_text()
    assert [text.count(f'trajectory = "{t}"') for t in ("A0", "A1", "A2", "T")] == [2, 2, 2, 1]


def _recordings(arm, effects: list[str], seconds: float) -> Dataset:
    """Two trajectories, each recorded twice with noise of its own, as one training set."""
    parts = [(f"A{k}", k + 1, 11 + 2 * k + r) for k in range(2) for r in range(2)]
    made = [selection_benchmark.recording(arm, effects, t, n, selection_benchmark.BASE_HZ, seconds, geared_arm.NOISE)
            for _, t, n in parts]
    label = lambda values: np.concatenate([np.full(len(d), v) for d, v in zip(made, values)])
    return Dataset(*(np.concatenate([getattr(d, f) for d in made]) for f in ("q", "qd", "qdd", "tau")),
                   system=arm.name, recording=label([f"rec{k}" for k in range(4)]),
                   trajectory=label([p[0] for p in parts]), time=np.concatenate([d.time for d in made]))


def test_a_residual_mostly_viscous_friction_on_two_trajectories_is_found_in_round_1(arm):
    effects = [f"viscous_friction={','.join(map(str, VISCOUS))}", "armature=4,4,2,0.6,0.5,0.3"]
    train = _recordings(arm, effects, 8.0)
    out = residual_loop("sysid", train, None, budget=Budget(steps=1), seed=0, max_rounds=1, report=lambda line: None)
    residual = train.tau - out.models[0].predict_torque(train)
    viscous = np.asarray(VISCOUS) * train.qd
    assert 1 - np.sum((residual - viscous) ** 2) / np.sum(residual ** 2) > 0.5  # mostly viscous friction
    accepted = out.rounds[1]["accepted"]
    assert all(f"viscous_friction on joint {j}" in accepted for j in range(1, 7)), accepted
    found = {e["joints"][0]: e["parameters"]["b"]["value"] for e in out.effects if e["name"] == "viscous_friction"}
    assert [found[j] for j in range(1, 7)] == pytest.approx(list(VISCOUS), rel=0.1)
    assert out.unexplained["train"] < 0.05

