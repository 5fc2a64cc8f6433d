"""Hybrid learners, PRIOR+RESIDUAL: one composition for every pair, each a method
like any other (the contract), learning what the prior lacks, falling back to
the prior where the data end, and refused in one line where a name is wrong."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import torch

from bench.core.data import generate, mse
from bench.physics.models import FittedModel
from bench.physics.undeclared import add_effects
from methods import METHODS
from methods.saving import load_model
from systems import get_system
from tests.commandline import cli
from tests.contract import check_method
from bench.core.budget import Budget

#: what the standard model of the Panda lacks: an offset and a spring on each joint
EFFECTS = {"offset": (0.5, -0.3, 0.4, -0.2, 0.3, -0.4, 0.2), "spring": (2.0, 1.0, 2.0, 1.0, 2.0, 1.0, 1.0)}
SMALL_GP = {"inducing": 32, "batch_size": 256, "lr": 0.05}
SMALL_MLP = {"hidden": 32, "layers": 2, "batch_size": 64}


@pytest.fixture(scope="module")
def panda():
    system = get_system("panda")
    return system, add_effects(generate(system, 600, 0), EFFECTS), add_effects(generate(system, 200, 1000), EFFECTS)


@pytest.mark.parametrize("name", ["standard+gp", "feasible+mlp", "feasible+delan"])
def test_a_hybrid_keeps_the_method_contract(name, panda):
    _, train, test = panda
    check_method(METHODS[name], train.subset(slice(0, 256)), test.subset(slice(0, 64)), "indirect")


def test_a_gp_on_the_standard_model_learns_what_the_rigid_body_lacks_and_is_scored_against_its_prior(panda):
    system, train, test = panda
    hybrid = METHODS["standard+gp"](**SMALL_GP).fit(train, "indirect", seed=0, budget=Budget(steps=150), system=system)
    prior = mse(hybrid.prior.predict_torque(test), test.tau)
    assert mse(hybrid.predict_torque(test), test.tau) < 0.5 * prior
    assert hybrid.references() == {"prior": hybrid.prior} and hybrid.record_details()["gated"] is False


@pytest.mark.parametrize("name, hyperparameters", [("standard+gp", SMALL_GP), ("standard+mlp", SMALL_MLP)])
def test_far_from_every_training_state_a_hybrid_predicts_its_prior(name, hyperparameters, panda):
    system, train, test = panda
    hybrid = METHODS[name](**hyperparameters).fit(train, "indirect", seed=0, budget=Budget(steps=50), system=system)
    far = test.replace(q=test.q + 8 * train.q.std(axis=0), qd=test.qd + 8 * train.qd.std(axis=0))
    near = test
    assert np.abs(hybrid.residual_torque(near)).max() > 1e-2  # it learned something where the data are
    np.testing.assert_allclose(hybrid.predict_torque(far), hybrid.prior.predict_torque(far), rtol=0, atol=1e-3)
    # the GP by its zero mean; the MLP, whose own torque does not vanish there, by the gate
    assert hybrid.record_details()["gated"] is (name == "standard+mlp")
    if name == "standard+mlp":
        assert np.abs(hybrid.residual.predict_torque(far)).max() > 1e-2 and hybrid.weight(far).max() < 1e-6


def test_hybrid_names_are_refused_in_one_line_and_nothing_is_written(tmp_path):
    out = tmp_path / "run.json"
    for method, words in (("foo+gp", "unknown prior 'foo' in 'foo+gp'"),
                          ("standard+operon", "operon cannot learn a residual torque"),
                          ("standard+nothing", "unknown residual learner"),
                          ("standard+gp", "the prior standard is SysId identified on an arm's linear form"),
                          ("standard+gp+mlp", "the residual of a hybrid cannot be a hybrid"),
                          ("sys-id", "unknown method 'sys-id'; did you mean 'sysid'?")):  # no hybrid: the registry's words
        r = cli("fit", "--system", "double_pendulum", "--experiment", "indirect", "--method", method, "--steps", "1",
                "--json", out)
        assert r.returncode == 2 and r.stderr.count("\n") == 1 and words in r.stderr, (method, r.stderr)
        assert not out.exists()
    r = cli("list")
    assert "a hybrid is named PRIOR+RESIDUAL" in r.stdout


def test_a_matrix_runs_a_hybrid_by_its_name_and_records_its_prior(tmp_path):
    r = cli("run", "--systems", "panda", "--methods", "standard+gp", "--experiments", "indirect", "--seeds", "0",
            "--steps", "5", "--set", "standard+gp.inducing=16", "--n-train", "200", "--n-test", "50", "--no-rollout",
            "--out", tmp_path / "m")
    assert r.returncode == 0, r.stdout + r.stderr
    (path,) = (tmp_path / "m" / "records").glob("*.json")
    record = json.loads(path.read_text())
    assert record["method"] == "standard+gp" and record["status"] == "ok"
    prior = record["details"]["references"]["prior"]
    assert {"train_mse", "test_mse", "ratio", "worse_share", "worse_by"} <= set(prior)
    again = cli("rerun", path)
    assert again.returncode == 0 and "the same up to" in again.stdout, again.stdout + again.stderr


def test_the_fitted_gps_mean_is_gpytorchs(panda, monkeypatch):
    """After the fit (its kept weights), during it (the weights of its parameters then) and where
    ``K_ZZ`` needs more jitter (GPyTorch's own path) alike."""
    system, train, test = panda
    gp = METHODS["gp"](**SMALL_GP).fit(train, "indirect", seed=0, budget=Budget(steps=20), system=system)
    fast = gp.predict_torque(test)
    gpytorchs = gp._predict_through_gpytorch(test)  # through GPyTorch's variational strategy
    np.testing.assert_allclose(fast, gpytorchs, rtol=1e-9, atol=1e-9 * np.abs(fast).max())
    gp._weights = None  # as during the fit
    np.testing.assert_allclose(gp.predict_torque(test), gpytorchs, rtol=1e-9, atol=1e-9 * np.abs(fast).max())

    def singular():
        raise torch.linalg.LinAlgError("not positive definite")

    monkeypatch.setattr(gp, "_mean_weights", singular)
    np.testing.assert_array_equal(gp.predict_torque(test), gpytorchs)


def test_the_gps_elbo_counts_the_independent_samples_of_a_recording(panda):
    system, train, _ = panda
    gp = METHODS["gp"](**SMALL_GP).fit(train, "indirect", seed=0, budget=Budget(steps=2), system=system)
    assert gp.record_details()["effective_samples"] == [float(len(train))] * train.dof  # generated: independent
    recorded = train.replace(recording=np.array(["a"] * len(train)), time=np.arange(len(train)) * 0.01)
    smooth = np.sin(np.linspace(0, 4 * np.pi, len(train)))[:, None] * np.ones(train.dof)
    gp = METHODS["gp"](**SMALL_GP).fit(recorded.replace(tau=smooth), "indirect", seed=0, budget=Budget(steps=2), system=system)
    assert max(gp.record_details()["effective_samples"]) < 0.1 * len(train)
    every = METHODS["gp"](**SMALL_GP, samples="all").fit(recorded.replace(tau=smooth), "indirect", seed=0, budget=Budget(steps=2),
                                                          system=system)
    assert every.record_details()["effective_samples"] == [float(len(train))] * train.dof


@pytest.mark.parametrize("name, hyperparameters", [("standard+gp", SMALL_GP), ("standard+mlp", SMALL_MLP),
                                                   ("standard+sparse_torque", {})])
def test_a_hybrids_mass_matrix_and_bias_are_its_torques_and_a_residual_of_the_state_is_asked_once_a_state(
        name, hyperparameters, panda, monkeypatch):
    system, train, test = panda
    hybrid = METHODS[name](**hyperparameters).fit(train, "indirect", seed=0, budget=Budget(steps=5), system=system)
    q, qd = test.q[:40], test.qd[:40]
    asked = []
    own = type(hybrid.residual).predict_torque
    monkeypatch.setattr(type(hybrid.residual), "predict_torque", lambda self, d: asked.append(len(d)) or own(self, d))
    M, c = hybrid.mass_and_bias(q, qd)
    # what the torques at dof + 1 accelerations a state give (the default of every model)
    M_torques, c_torques = FittedModel.mass_and_bias(hybrid, q, qd)
    np.testing.assert_allclose(M, M_torques, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(c, c_torques, rtol=1e-9, atol=1e-9)
    per_state = 1 if name != "standard+mlp" else system.dof + 1  # the MLP's torque takes accelerations
    assert asked[0] == per_state * len(q)


def test_two_fits_on_the_same_samples_share_their_priors_torques_and_give_the_same_numbers(panda, monkeypatch):
    """As a tuned hybrid's fold fits do, one for each combination: the prior is identified once and its torque at
    the training and at the held-out states computed once; other samples are computed afresh."""
    from methods import hybrid as hybrid_module

    system, train, test = panda
    train = train.subset(slice(0, 256))
    hybrid_module._torques.clear()
    first = METHODS["standard+mlp"](**SMALL_MLP).fit(train, "indirect", seed=0, budget=Budget(steps=3), system=system)
    asked = []
    real = type(first.prior).predict_torque
    monkeypatch.setattr(type(first.prior), "predict_torque", lambda self, data: asked.append(len(data)) or real(self, data))
    first_test = first.predict_torque(test)
    second = METHODS["standard+mlp"](**{**SMALL_MLP, "lr": 3e-4}).fit(train, "indirect", seed=0, budget=Budget(steps=3),
                                                                      system=system)
    assert second.prior is first.prior and asked == [len(test)]  # the training samples' torque was kept
    second.predict_torque(test)
    assert asked == [len(test)]
    np.testing.assert_array_equal(first.prior.predict_torque(test), hybrid_module.prior_torque(first.prior, test))
    second.predict_torque(test.subset(slice(0, 50)))
    assert asked == [len(test), len(test), 50]
    assert np.isfinite(first_test).all()


def test_a_prior_shared_through_a_folder_is_read_by_another_process_and_only_from_the_same_code(panda, tmp_path,
                                                                                                 monkeypatch):
    """Where a process shares priors (``bench select``'s runs), a prior identified by one is written as a model
    file and read back by the next, giving the same torques to the bit; one written by other code is not read."""
    from methods import hybrid as hybrid_module

    system, train, test = panda
    train = train.subset(slice(0, 256))
    code = {"digest": "code A"}
    monkeypatch.setattr(hybrid_module, "_SHARED", dict(hybrid_module._SHARED))
    hybrid_module.share_priors(tmp_path, lambda: code["digest"])
    hybrid_module._priors.clear()
    first = hybrid_module.identified_prior("standard", train, system, 0)
    (written,) = tmp_path.glob("standard-*.npz")

    identified = []
    real = hybrid_module.PRIORS["standard"]
    monkeypatch.setitem(hybrid_module.PRIORS, "standard", dataclasses.replace(
        real, identify=lambda *args: identified.append(1) or real.identify(*args)))
    hybrid_module._priors.clear()  # another process: nothing kept in memory
    read = hybrid_module.identified_prior("standard", train, system, 0)
    assert identified == [] and read is not first  # read from the file, not identified
    np.testing.assert_array_equal(read.predict_torque(test), first.predict_torque(test))

    code["digest"] = "code B"  # the code changed: the file is not its prior
    hybrid_module._priors.clear()
    hybrid_module.identified_prior("standard", train, system, 0)
    assert identified == [1] and len(list(tmp_path.glob("standard-*.npz"))) == 2

    written.write_bytes(b"not a model file")  # left unreadable: identified again and written anew, no error
    code["digest"] = "code A"
    hybrid_module._priors.clear()
    again = hybrid_module.identified_prior("standard", train, system, 0)
    assert identified == [1, 1] and load_model(written, system)[0] is not None
    np.testing.assert_array_equal(again.predict_torque(test), first.predict_torque(test))

    monkeypatch.setattr(hybrid_module, "save_model", lambda *args: 1 / 0)  # cannot be written: the fit goes on
    hybrid_module._priors.clear()
    assert hybrid_module.identified_prior("standard", train.subset(slice(0, 200)), system, 0) is not None
    assert identified == [1, 1, 1] and len(list(tmp_path.glob("standard-*.npz"))) == 2


def test_a_tuned_hybrids_search_computes_its_priors_torque_on_each_of_its_folds_sets_once(panda, monkeypatch):
    """The search fits every combination on every fold before the next combination (:mod:`bench.evaluation.tuning`),
    and each fit asks for the prior's torque on its fold's fitted, evaluated and scored samples (three sets where the
    training MSE is evaluated on a subset): all of them are kept through the search, so that no combination makes
    them again."""
    from bench.core.protocols import folds
    from bench.evaluation.tuning import MAX_FOLDS, tune
    from methods import hybrid as hybrid_module

    system, train, _ = panda
    train = train.replace(recording=np.repeat(np.arange(6), len(train) // 6))
    assert len(folds(train, None, MAX_FOLDS)) == MAX_FOLDS
    hybrid_module._torques.clear()
    made, get = [], hybrid_module._torques.get
    monkeypatch.setattr(hybrid_module._torques, "get", lambda key, make: get(key, lambda: made.append(key) or make()))
    tuned = tune(METHODS["standard+mlp"], {**SMALL_MLP, "eval_samples": 128}, train, "indirect", 0, Budget(steps=3),
                 system=system)
    assert len(tuned.details["combinations"]) == 4
    assert len(made) > 8 and len(made) == len(set(made))
