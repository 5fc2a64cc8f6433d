"""The standard model a record carries names its joint columns and those the data did not identify, and the
study that reads the pages made against friction alone finds them and gives their factor."""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin

from bench.core.data import Dataset
from bench.evaluation.reference import standard_reference
from bench.studies import standard_model
from systems import SYSTEMS


def _geared(arm, n: int, seed: int) -> Dataset:
    rng = np.random.default_rng(seed)
    q, qd, qdd = (rng.uniform(-1.5, 1.5, (n, arm.dof)) for _ in range(3))
    data = arm.model.createData()
    tau = np.stack([pin.rnea(arm.model, data, *row) for row in zip(q, qd, qdd)])
    tau = tau + 0.5 * qd + 0.8 * np.sign(qd) + np.linspace(0.6, 0.1, arm.dof) * qdd + 0.3
    return Dataset(q, qd, qdd, tau, None, "ur5")


def test_the_records_standard_model_names_its_joint_columns_and_the_one_it_dropped():
    arm = SYSTEMS["ur5"]()
    out = standard_reference(arm, _geared(arm, 400, 0), None)
    assert out["joint_columns"] == ["b", "F_c", "I_a", "tau_0"]
    assert out["dropped_joint_columns"] == ["I_a_1"]  # the first rotor acts as link 1's ZZ does
    assert out["joint_columns_not_significant"] == []
    assert out["train_mse"] < 1e-12


def _record(folder, system: str, split: str | None, test_mse: float | None, k: int) -> None:
    (folder / "records").mkdir(parents=True, exist_ok=True)
    details = {} if test_mse is None else {"standard_model": {"test_mse": test_mse}}
    (folder / "records" / f"r{k}.json").write_text(json.dumps(
        {"system": system, "spec": {"split": split}, "details": details}))


def test_the_published_records_are_grouped_by_folder_system_and_split_and_read_with_their_factor(tmp_path):
    _record(tmp_path / "a", "kuka_lwr4", None, 0.74, 0)
    _record(tmp_path / "a", "kuka_lwr4", "default", 0.74, 1)
    _record(tmp_path / "b", "kuka_lwr4", "swapped", 0.33, 0)
    _record(tmp_path / "b", "double_pendulum", None, None, 1)  # no standard model: not listed
    (tmp_path / "b" / "records" / "broken.json").write_text("{")
    found = standard_model.published(tmp_path)
    assert found == {(str(tmp_path / "a"), "kuka_lwr4", "default"): [0.74, 0.74],
                     (str(tmp_path / "b"), "kuka_lwr4", "swapped"): [0.33]}
    fit = {"train_mse": 0.1, "mass_matrix_positive_definite": True, "dropped_joint_columns": ["I_a_1"],
           "joint_columns_not_significant": []}
    models = {"kuka_lwr4": {"default": {key: {**fit, "test_mse": value} for key, value in (
        ("standard_friction_alone", 0.74), ("standard", 1.48), ("feasible_friction_alone", 0.36),
        ("feasible", 0.18))}}}
    models["kuka_lwr4"]["default"]["factor"] = 0.5
    page = standard_model.report(models, found)
    assert "| kuka_lwr4 | default | standard | 0.1 | 1.48 | 2.000x | yes | I_a_1 | — |" in page
    assert "| kuka_lwr4 | default | feasible | 0.1 | 0.18 | 0.500x |" in page
    assert f"| {tmp_path / 'a'} | kuka_lwr4 | default | 2 | 0.74 | 0.74 | 1.48 | 0.500 |" in page
    assert f"| {tmp_path / 'b'} | kuka_lwr4 | swapped | 1 | 0.33 | — | — | — |" in page
