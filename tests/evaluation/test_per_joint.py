"""The test error per joint and per test trajectory, checked against scikit-learn's metrics,
and the page ``bench table --per-joint`` writes from a run on a measured system."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from sklearn.metrics import mean_squared_error, r2_score

from bench.cli import main
from bench.core.data import Dataset
from bench.evaluation.per_joint import per_joint
from systems.delan_characters import DATA as CHARACTERS
from tests.commandline import cli
from bench.runner.spec import RunSpec


def _data(rng, n=300, dof=3):
    tau = rng.normal(size=(n, dof)) * np.array([1.0, 5.0, 0.2])
    zeros = np.zeros((n, dof))
    labels = np.where(np.arange(n) < 200, "a", "b")
    return Dataset(zeros, zeros, zeros, tau, recording=labels, trajectory=labels)


def test_each_trajectorys_mse_and_nmse_per_joint_are_sklearns():
    rng = np.random.default_rng(0)
    data = _data(rng)
    guess = data.tau + rng.normal(size=data.tau.shape) * 0.3
    logged = data.tau + rng.normal(size=data.tau.shape) * 0.1
    out = per_joint(guess, data, logged)["trajectories"]
    assert list(out) == ["a", "b"] and out["a"]["n"] == 200 and out["b"]["n"] == 100
    for name, rows in (("a", slice(0, 200)), ("b", slice(200, None))):
        tau, g, raw = data.tau[rows], guess[rows], logged[rows]
        np.testing.assert_allclose(out[name]["mse"], mean_squared_error(tau, g, multioutput="raw_values"), rtol=1e-5)
        # nMSE = MSE / variance = 1 - R² (both about the trajectory's own mean)
        np.testing.assert_allclose(out[name]["nmse"], 1 - r2_score(tau, g, multioutput="raw_values"), rtol=1e-5)
        np.testing.assert_allclose(out[name]["nmse_logged"], 1 - r2_score(raw, g, multioutput="raw_values"), rtol=1e-5)
        np.testing.assert_allclose(out[name]["noise_floor"], mean_squared_error(raw, tau, multioutput="raw_values"),
                                   rtol=1e-5)


def test_a_model_of_the_filtered_torque_scores_the_noise_floor_against_the_logged_one():
    rng = np.random.default_rng(1)
    data = _data(rng)
    logged = data.tau + rng.normal(size=data.tau.shape) * 0.1
    out = per_joint(data.tau, data, logged)["trajectories"]["a"]
    assert out["mse"] == [0, 0, 0] and out["mse_logged"] == out["noise_floor"]
    assert out["nmse_logged"] == out["noise_floor_nmse"]
    assert "mse_logged" not in per_joint(data.tau, data)["trajectories"]["a"]


def test_a_run_on_a_measured_arm_records_its_error_per_joint_and_the_page_gives_it(tmp_path):
    out = tmp_path / "runs"
    r = cli("run", "--systems", "dfki_double_pendulum", "--methods", "sysid", "--experiments", "indirect",
            "--seeds", "0", "--steps", "1", "--out", out, "--workers", "1")
    assert r.returncode == 0, r.stderr
    record = json.loads(next((out / "records").glob("*.json")).read_text())
    entry = record["details"]["per_joint"]["trajectories"]
    assert list(entry) == ["03", "05"] and sum(e["n"] for e in entry.values()) == record["details"]["n_test"]
    # the headline is the mean of the per-joint MSEs, weighted by each trajectory's samples
    pooled = sum(e["n"] * np.mean(e["mse"]) for e in entry.values()) / record["details"]["n_test"]
    assert pooled == pytest.approx(record["test_mse"], rel=1e-4)
    assert all(min(e["noise_floor"]) > 0 for e in entry.values())
    r = cli("table", out, "--per-joint")
    assert r.returncode == 0, r.stderr
    page = (out / "per_joint.md").read_text()
    assert page == r.stdout.rstrip("\n") + "\n"
    assert "## dfki_double_pendulum, split default: test trajectory 05" in page
    floor = " | ".join(f"{100 * x:.3g}" for x in entry["05"]["noise_floor_nmse"])
    assert f"| the filter's noise floor | — | {floor} |" in page
    assert f"| sysid | 1 | {entry['03']['mse'][0]:.4g} | {entry['03']['mse'][1]:.4g} |" in page
    assert "Per joint and per test trajectory" in (out / "tables.md").read_text()  # the headline table points to it


def test_a_run_on_files_given_for_a_measured_system_scores_per_joint_against_the_files_alone(tmp_path):
    """The system's logged torque is its own test trajectories'; files given for it have other samples."""
    frame = pd.read_csv(CHARACTERS)
    frame = frame.rename(columns={"character": "trajectory", "t": "time"})
    held = frame["trajectory"].isin(["g", "r"])
    train, test = tmp_path / "train.csv", tmp_path / "test.csv"
    frame[~held & ~frame["trajectory"].isin(["e", "q", "v"])].to_csv(train, index=False)
    frame[held].to_csv(test, index=False)
    out = tmp_path / "run.json"
    assert main(["fit", "--system", "delan_characters", "--method", "sysid", "--experiment", "indirect",
                 "--train", str(train), "--test", str(test), "--steps", "1", "--json", str(out)]) == 0
    record = json.loads(out.read_text())
    assert record["failed_stages"] == {}
    entry = record["details"]["per_joint"]["trajectories"]
    assert sorted(entry) == ["g", "r"] and sum(e["n"] for e in entry.values()) == int(held.sum())
    assert all("mse_logged" not in e for e in entry.values())


def test_the_page_takes_learners_whose_records_lack_the_logged_figures():
    from bench.reporting.per_joint import build_per_joint
    from bench.runner.records import Record

    def record(method: str, logged: bool) -> Record:
        entry = {"n": 10, "mse": [1.0, 2.0], "nmse": [0.1, 0.2]}
        if logged:
            entry.update(mse_logged=[1.5, 2.5], nmse_logged=[0.15, 0.25], noise_floor=[0.2, 0.3],
                         noise_floor_nmse=[0.02, 0.03])
        spec = {"system": "dfki_double_pendulum", "method": method, "experiment": "indirect", "seed": 0,
                "budget_s": None, "steps": 1}
        return Record.new(RunSpec(**spec), "ok", details={"per_joint": {"trajectories": {"03": entry}}})

    page = build_per_joint([record("sysid", True), record("mlp", False)])
    assert "| mlp | 0 | — | — | — |" in page  # in the logged tables: it has no such figure
    assert "| mlp | 1 | 1 | 2 | 1.5 |" in page  # in the filtered ones: it has
