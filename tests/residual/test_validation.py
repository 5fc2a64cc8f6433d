"""Held-out validation by whole recordings, and the loop's rule that a round
which does not lower the held-out error is undone."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from bench.core.budget import Budget
from bench.core.data import generate
from bench.physics.effects import EFFECTS
from bench.physics.laws import LAWS
from bench.physics.undeclared import add_effects
from bench.physics.terms import TermLibrary
from bench.residual import loop, residual_loop, strategies, trace
from bench.residual import model as model_module
from bench.core.folds import MAX_SPANS as BLOCKS, folds
from bench.residual.criteria import MAX_WEIGHT_RATIO, joint_weights
from bench.residual.validation import cv_mse, describe
from systems import get_system
from tests.residual.test_loop import SOLVED, SYSID, quiet


def test_folds_are_whole_recordings_where_the_data_name_them_and_blocks_otherwise():
    data = generate(get_system("double_pendulum"), 1000, 0)
    blocks = folds(data).held
    assert len(blocks) == BLOCKS and all(b.sum() == 250 for b in blocks)
    assert all(np.ptp(np.flatnonzero(b)) == 249 for b in blocks)  # contiguous
    assert describe(data) == f"{BLOCKS} contiguous blocks of samples without recordings"
    labelled = data.replace(recording=np.array(list("abc"))[np.arange(1000) % 3])
    by_recording = folds(labelled).held
    assert [int(f.sum()) for f in by_recording] == [334, 333, 333]
    assert all(len(set(labelled.recording[f])) == 1 for f in by_recording)
    assert np.logical_or.reduce(by_recording).all()  # every sample held out once
    assert describe(labelled) == "leave one trajectory out, over 3 trajectories"


def test_recordings_of_one_trajectory_are_held_out_together():
    data = generate(get_system("double_pendulum"), 1200, 0)
    recording = np.repeat(["run1", "run2", "run3"], 400)
    grouped = data.replace(recording=recording, trajectory=np.where(recording == "run3", "B", "A"))
    by_trajectory = folds(grouped).held
    assert [sorted(set(grouped.recording[f])) for f in by_trajectory] == [["run1", "run2"], ["run3"]]
    assert describe(grouped) == "leave one trajectory out, over 2 trajectories (3 recordings)"
    # one trajectory: spans in time, each span of every recording of it in one fold
    one = grouped.subset(grouped.trajectory == "A")
    one = one.replace(time=np.tile(np.arange(400) * 0.01, 2)[::-1].copy())  # time runs backwards through the rows
    spans = folds(one).held
    assert len(spans) == BLOCKS and np.logical_or.reduce(spans).all() and sum(int(f.sum()) for f in spans) == 800
    for f in spans:
        assert sorted(set(one.recording[f])) == ["run1", "run2"]
        for name in ("run1", "run2"):  # the same span of time in both recordings
            times = one.time[f & (one.recording == name)]
            assert np.ptp(times) == pytest.approx(0.99, abs=1e-9)
        assert set(np.round(one.time[f & (one.recording == "run1")], 6)) == set(np.round(one.time[f & (one.recording == "run2")], 6))
    assert folds(one).describe().startswith(f"{BLOCKS} contiguous spans in time of one trajectory")
    # the loop holds out regions of the state space of one trajectory instead: spans only interpolate
    assert "regions of the states" in describe(one)


def test_cv_mse_scores_each_fold_by_a_fit_on_the_others():
    F = np.array([[1.0], [1.0], [1.0], [1.0]])
    y = np.array([0.0, 0.0, 2.0, 2.0])
    held = [np.array([True, True, False, False]), np.array([False, False, True, True])]
    assert cv_mse(F, y, held) == pytest.approx(4.0)  # each half predicted by the other's mean
    assert cv_mse(np.zeros((4, 0)), y, held) == pytest.approx(2.0)


def test_an_effect_of_one_recording_is_refused_when_recordings_are_held_out():
    # a bias on joint 1 in one of four recordings, their samples interleaved: held-out blocks
    # each contain some of that recording and accept an offset; holding out whole recordings does not
    data = generate(get_system("double_pendulum"), 4000, 3)
    labels = np.array(list("abcd"))[np.arange(len(data)) % 4]
    residual = np.zeros_like(data.tau)
    residual[labels == "a", 0] = 0.5
    residual += np.random.default_rng(0).normal(0, 0.01, residual.shape)
    pool = TermLibrary([EFFECTS["offset"].term(0)])
    assert [t.name for t in trace(residual, data, pool).accepted] == ["offset"]
    refused = trace(residual, data.replace(recording=labels), pool)
    assert refused.accepted == [] and refused.steps[-1]["heldout_gain"] < 0


def test_a_round_that_does_not_lower_the_held_out_error_is_undone(monkeypatch):
    s = get_system("double_pendulum")
    train = add_effects(generate(s, 2000, 0), {"viscous_friction": (0.8, 0.5)})
    test = add_effects(generate(s, 1000, 1), {"viscous_friction": (0.8, 0.5)})
    calls = iter([1.0, 2.0])  # round 0, then the refitted round 1: worse
    monkeypatch.setattr(loop, "heldout", lambda strategy, model, data, scale=None: next(calls))
    out = residual_loop("sparse", train, test, budget=Budget(steps=SOLVED), report=quiet)
    assert out.effects == [] and out.mse_after == out.mse_before
    last = out.rounds[-1]
    assert last["stop"].startswith("undone") and last["undone_heldout_mse"] == 2.0 and last["heldout_mse"] == 1.0
    assert [r["heldout_mse"] for r in out.rounds] == [1.0, 1.0]


def test_a_round_that_leaves_the_mass_matrix_not_positive_definite_is_undone(monkeypatch):
    s = get_system("double_pendulum")
    train = add_effects(generate(s, 2000, 0), {"viscous_friction": (0.8, 0.5)})
    real = loop.smallest_mass_eigenvalue
    # the rod pendulum's own mass matrix is positive definite; pretend the effects spoil it
    monkeypatch.setattr(loop, "smallest_mass_eigenvalue", lambda model, data: real(model, data) - 1e3 * bool(model.effects))
    out = residual_loop("sparse", train, None, budget=Budget(steps=SOLVED), report=quiet)
    assert out.effects == [] and out.mass_matrix["positive_definite"]
    assert out.mass_matrix["smallest_eigenvalue_before"] == out.mass_matrix["smallest_eigenvalue_after"] > 0
    assert "mass matrix is not positive definite" in out.rounds[-1]["stop"]
    assert real(out.models[1], train) == pytest.approx(out.mass_matrix["smallest_eigenvalue_after"])


def _with_force(data, term):
    return data.replace(tau=data.tau + term.torque(data))


def test_a_tip_payload_under_the_rod_form_is_found_as_one_payload_with_its_mass():
    # a point mass at the tip of link 2: the rod form alone explains it only with a negative rotor
    # inertia; the payload's own L-term explains it with one admissible parameter
    from bench.physics.undeclared import parse_effects

    s = get_system("double_pendulum")
    fx = parse_effects(["tip_payload=0.5"], 2)
    train, test = add_effects(generate(s, 3000, 0), fx, s), add_effects(generate(s, 1500, 1000), fx, s)
    out = residual_loop("sysid", train, test, budget=Budget(steps=SYSID), report=quiet)
    (payload,) = out.effects
    assert payload["name"] == "tip_payload" and payload["kind"] == "conservative" and payload["joints"] == [1, 2]
    assert payload["parameters"]["m"]["value"] == pytest.approx(0.5, rel=0.02)
    assert out.mse_after["test"] < 1e-6 * out.mse_before["test"]
    assert out.mass_matrix["positive_definite"]


def test_a_lighter_tip_than_the_rod_form_allows_is_a_structural_finding():
    # a tapered second link (a uniform rod less a mass at its tip): only a negative inertia or
    # payload explains it, so the loop names the missing freedom and adds nothing impossible
    s = get_system("double_pendulum")
    lighter = EFFECTS["tip_payload"].term(system=s)
    train, test = (d.replace(tau=d.tau - 0.3 * lighter.torque(d)) for d in (generate(s, 3000, 0), generate(s, 1500, 1000)))
    out = residual_loop("sysid", train, test, budget=Budget(steps=SYSID), report=quiet)
    for e in out.effects:
        if e["kind"] != "structural":
            assert LAWS.arm[e["name"]].check(tuple(v["value"] for v in e["parameters"].values())), e
    findings = [e for e in out.effects if e["kind"] == "structural"]
    assert findings and all(f["parameters"] == {} and "lacks this freedom" in f["finding"] for f in findings)
    assert findings[0]["name"] in ("armature", "tip_payload")
    assert out.mse_after["test"] <= out.mse_before["test"]


@pytest.mark.parametrize("alpha", [0.05, -0.12])
def test_a_gravity_tilt_is_found_as_one_tilt_with_its_angle(alpha):
    from bench.physics.undeclared import parse_effects

    s = get_system("double_pendulum")
    fx = parse_effects([f"gravity_tilt={alpha}"], 2)
    train, test = add_effects(generate(s, 3000, 0), fx, s), add_effects(generate(s, 1500, 1000), fx, s)
    out = residual_loop("sysid", train, test, budget=Budget(steps=SYSID), report=quiet)
    (tilt,) = out.effects
    assert tilt["name"] == "gravity_tilt" and tilt["law"].startswith("L += sin(alpha)*")
    assert tilt["parameters"]["alpha"]["value"] == pytest.approx(alpha, rel=0.02)
    assert out.mse_after["test"] < 1e-6 * out.mse_before["test"]


@pytest.mark.parametrize("method", ["sparse", "sysid"])
def test_stribeck_friction_is_found_as_its_law_with_its_four_parameters(method):
    from bench.physics.undeclared import parse_effects

    s = get_system("double_pendulum")
    fx = parse_effects(["stribeck_friction=1:1.0,2.0,0.5,0.3"], 2)
    train, test = add_effects(generate(s, 3000, 0), fx), add_effects(generate(s, 1500, 1000), fx)
    out = residual_loop(method, train, test, budget=Budget(steps=SYSID), report=quiet)
    (law,) = out.effects  # one entry, not a viscous term of the wrong sign and polynomials
    assert law["name"] == "stribeck_friction" and law["kind"] == "dissipative" and law["joints"] == [1]
    want = {"F_c": 1.0, "F_s": 2.0, "v_s": 0.5, "b": 0.3}
    assert {k: p["value"] for k, p in law["parameters"].items()} == pytest.approx(want, rel=0.05)
    assert out.mse_after["test"] < 1e-6 * out.mse_before["test"]


def test_friction_outside_the_laws_is_never_reported_with_an_impossible_coefficient():
    # a friction curve that rises with speed below 0.5 rad/s (no law here has that shape)
    import sympy

    from bench.physics.terms import Term

    qd = sympy.Symbol("qd_1", real=True)
    rising = Term.force((1.5 - sympy.exp(-(qd / 0.5) ** 2)) * sympy.sign(qd) + 0.3 * qd, 0)
    s = get_system("double_pendulum")
    train, test = _with_force(generate(s, 3000, 0), rising), _with_force(generate(s, 1500, 1000), rising)
    out = residual_loop("sparse", train, test, budget=Budget(steps=SOLVED), report=quiet)
    for e in out.effects:
        if e["kind"] == "structural":
            assert e["parameters"] == {} and "not physical" in e["finding"]
        elif e["name"] in LAWS.arm:  # each law by its own condition (the Stribeck law's F_s >= F_c >= 0, say)
            assert LAWS.arm[e["name"]].check(tuple(v["value"] for v in e["parameters"].values())), e
    assert out.mse_after["test"] <= out.mse_before["test"]


class _Memoriser:
    """A method whose fit knows the rigid dynamics and, on the samples it was
    fitted on, predicts their torque less ``bias`` on joint 1: an offset in
    its training residual that no new sample has."""

    bias = 0.0

    def fit(self, train, experiment, seed, budget_s):
        from bench.physics.models import LagrangianFunction

        system = get_system(train.system)
        memory = {row.tobytes(): tau - [self.bias, 0.0] for row, tau in zip(train.q, train.tau)}

        class Fit(LagrangianFunction):
            def lagrangian(self, q, qd):
                return system.lagrangian(q, qd)

            def predict_torque(self, data):
                tau = super().predict_torque(data)
                return np.array([memory.get(row.tobytes(), t) for row, t in zip(data.q, tau)])

        return Fit()


class _Biased(_Memoriser):
    bias = 0.5


def test_an_effect_only_in_a_kept_fits_own_training_residual_is_undone_by_its_cross_fits(monkeypatch):
    # the offset is in what the fit leaves on every training recording, so leaving one recording out
    # cannot tell; the method fitted on half the recordings leaves nothing on the other half
    monkeypatch.setattr(model_module, "METHODS", {"biased": _Biased})
    s = get_system("double_pendulum")
    train = generate(s, 1200, 0).replace(recording=np.array(list("abcd"))[np.arange(1200) // 300])
    test = generate(s, 600, 5000)
    out = residual_loop("biased", train, test, budget=Budget(steps=SOLVED), report=quiet, open_ended=False)
    assert out.rounds[0]["cross_fit"]["in_sample_mse"] == pytest.approx(0.125)  # 0.5**2 on one of two joints
    assert out.rounds[0]["cross_fit"]["out_of_fold_mse"] < 1e-20
    assert out.rounds[1]["accepted"] == ["offset on joint 1"] and "for each half" in out.rounds[1]["stop"]
    assert out.effects == [] and out.mse_after == out.mse_before
    # given a fit made on other data, what it leaves here is out of sample: the loop neither cross-fits nor refuses
    given = _Biased().fit(train, "indirect", 0, Budget(seconds=1.0))
    out = residual_loop("biased", train, test, budget=Budget(steps=SOLVED), report=quiet, fitted=given, open_ended=False)
    assert "cross_fit" not in out.rounds[0] and [e["name"] for e in out.effects] == ["offset"]


def test_the_cross_fit_deals_the_recordings_into_two_halves_each_predicted_by_the_other():
    s = get_system("double_pendulum")
    train = generate(s, 800, 0).replace(recording=np.array(list("abcd"))[np.arange(800) // 200])
    seen = []

    class Fitter:
        method, budget = "recorder", Budget(seconds=1.0)

        def fit(self, data):
            seen.append("".join(data.recordings()))
            return _Biased().fit(data, "indirect", 0, Budget(seconds=1.0))

    full = _Biased().fit(train, "indirect", 0, Budget(seconds=1.0))
    cross, info = strategies.cross_fit(Fitter(), full, train, quiet)
    assert seen == ["bd", "ac"] and info["in_sample_mse"] == pytest.approx(0.125)
    assert [np.flatnonzero(h)[[0, -1]].tolist() for h in cross.halves] == [[0, 599], [200, 799]]
    rigid = s.torque(*(torch.from_numpy(a) for a in (train.q, train.qd, train.qdd)))[0].numpy()
    np.testing.assert_allclose(cross.torque, rigid)  # each half predicted by the fit that did not see it
    np.testing.assert_allclose(cross.predict_torque(train), rigid - [0.5, 0.0])  # it predicts as the fit on all


def test_held_out_fits_with_added_columns_equal_refitting_without_each_fold():
    from bench.residual.validation import FoldFits, cv_mse

    rng = np.random.default_rng(3)
    D, G = rng.normal(size=(600, 5)) * np.logspace(-2, 2, 5), rng.normal(size=(600, 2))
    y = D @ rng.normal(size=5) + G @ [0.5, -1.0] + rng.normal(size=600)
    held = [np.arange(600) * 3 // 600 == k for k in range(3)]
    fits = FoldFits(D, y, held)
    assert fits.cv() == pytest.approx(cv_mse(D, y, held), rel=1e-10)
    assert fits.cv(G) == pytest.approx(cv_mse(np.hstack([D, G]), y, held), rel=1e-10)
    overlapping = [np.arange(600) < 400, np.arange(600) >= 200]  # not a split: refitted fold by fold
    assert FoldFits(D, y, overlapping).cv(G) == pytest.approx(cv_mse(np.hstack([D, G]), y, overlapping), rel=1e-12)


def test_an_extended_basis_spans_what_a_fresh_one_spans():
    from bench.residual.basis import extend_basis, orthonormal_basis

    rng = np.random.default_rng(4)
    A, B = rng.normal(size=(300, 4)), rng.normal(size=(300, 3))
    B[:, 2] = A[:, 0] - B[:, 1]  # adds nothing new
    Q = extend_basis(orthonormal_basis(A), B)
    assert Q.shape[1] == 6
    np.testing.assert_allclose(Q.T @ Q, np.eye(6), atol=1e-12)
    fresh = orthonormal_basis(np.hstack([A, B]))
    np.testing.assert_allclose(Q @ (Q.T @ fresh), fresh, atol=1e-10)


@pytest.mark.parametrize("trajectories", [True, False])
def test_on_trajectories_a_round_must_save_one_percent_of_the_held_out_error(trajectories, monkeypatch):
    # a round whose held-out error falls by 0.5 %: kept on independent samples, undone on trajectories,
    # whose held-out spans are not independent of the rest of their motion
    from bench.tools.robot_log import simulate
    from bench.residual import loop as loop_module

    parts = []
    for k in range(2):
        time, d = simulate("double_pendulum", 6.0, 100.0, 0.2, ["viscous_friction=0.8,0.5"], 0.01, k)
        label = np.asarray([f"r{k}"] * len(d))
        parts.append(d.replace(recording=label, trajectory=label, time=time) if trajectories else d)
    join = lambda name: None if getattr(parts[0], name) is None else np.concatenate([getattr(p, name) for p in parts])  # noqa: E731
    train = parts[0].replace(**{k: join(k) for k in ("q", "qd", "qdd", "tau", "L", "recording", "trajectory", "time")})
    calls = []

    def heldout(self, model, train=None, sensor=None):
        calls.append(model)
        return 1.0 if len(calls) == 1 else 0.995

    def by_joint(strategy, model, train, scale=None):  # each joint's error falls by as much as the pooled one
        return np.full(train.dof, 1.0 if model is calls[0] else 0.995)

    monkeypatch.setattr(loop_module._Loop, "heldout", heldout)
    monkeypatch.setattr(loop_module, "heldout_by_joint", by_joint)
    out = residual_loop("sysid", train, None, budget=Budget(steps=SOLVED), report=quiet, open_ended=False)
    first = out.rounds[1]
    if trajectories:
        assert first["stop"].startswith("undone: the refitted model does not lower the held-out error by 1%")
        assert out.effects == [] or all(e["kind"] != "dissipative" for e in out.effects)
    else:
        assert first.get("stop") is None and any(e["name"] == "viscous_friction" for e in out.effects)


def _two_friction_trajectories():
    """Two recordings of the double pendulum with viscous friction, each its own trajectory, as one training set."""
    from bench.tools.robot_log import simulate

    parts = []
    for k in range(2):
        time, d = simulate("double_pendulum", 6.0, 100.0, 0.2, ["viscous_friction=0.8,0.5"], 0.01, k)
        label = np.asarray([f"r{k}"] * len(d))
        parts.append(d.replace(recording=label, trajectory=label, time=time))
    join = lambda name: np.concatenate([getattr(p, name) for p in parts])  # noqa: E731
    return parts[0].replace(**{k: join(k) for k in ("q", "qd", "qdd", "tau", "L", "recording", "trajectory", "time")})


def test_a_round_that_pays_on_one_joint_in_its_own_units_is_kept(monkeypatch):
    # pooled, the held-out error falls by 0.5 %; the small joint's own error by a third: the round stays
    from bench.residual import loop as loop_module

    train = _two_friction_trajectories()
    calls = []

    def heldout(self, model, train=None, sensor=None):
        calls.append(model)
        return 1.0 if len(calls) == 1 else 0.995

    def by_joint(strategy, model, train, scale=None):
        return np.array([1.0, 0.01]) if model is calls[0] else np.array([0.995, 0.0066])

    monkeypatch.setattr(loop_module._Loop, "heldout", heldout)
    monkeypatch.setattr(loop_module, "heldout_by_joint", by_joint)
    out = residual_loop("sysid", train, None, budget=Budget(steps=SOLVED), report=quiet, open_ended=False)
    assert out.rounds[1].get("stop") is None and any(e["kind"] == "dissipative" for e in out.effects)


def test_the_trace_weighs_each_joint_by_its_own_residual():
    # joint 1's residual is noise a hundred times joint 2's, and joint 2's is half a rotor inertia:
    # pooled, its share of the residual is 0.01 %, below every test; each joint in its own units, it is found
    data = generate(get_system("double_pendulum"), 4000, 3)
    rng = np.random.default_rng(0)
    armature = EFFECTS["armature"].term(1)
    column = armature.column(data, "indirect").reshape(data.tau.shape)
    residual = np.column_stack([rng.normal(0, 100.0, len(data)), rng.normal(0, 1.0, len(data))])
    residual += column / np.sqrt(np.mean(column[:, 1] ** 2))
    traced = trace(residual, data, TermLibrary([EFFECTS["armature"].term(0), armature]))
    assert traced.accepted == [armature] and traced.weights[1] / traced.weights[0] == pytest.approx(100 / np.sqrt(2), rel=0.05)
    assert joint_weights(residual.ravel(), np.zeros((residual.size, 0)), data)[1] == pytest.approx(traced.weights[1])
    # a joint fitted to round-off is weighed at most MAX_WEIGHT_RATIO times the largest
    flat = np.column_stack([rng.normal(0, 1.0, 10), np.zeros(10)]).ravel()
    w = joint_weights(flat, np.zeros((flat.size, 0)), data.subset(np.arange(10)))
    assert w[1] / w[0] == pytest.approx(MAX_WEIGHT_RATIO)
    # one trajectory's rows are pooled as measured: the same residual, as one recording, is weighed 1 a row
    one = data.replace(recording=np.array(["A"] * len(data)), trajectory=np.array(["A"] * len(data)))
    assert np.all(joint_weights(residual.ravel(), np.zeros((residual.size, 0)), one) == 1.0)
    assert np.all(trace(residual, one, TermLibrary([EFFECTS["armature"].term(0), armature])).weights == 1.0)


def test_a_round_whose_every_law_the_joint_refit_drops_ends_the_loop_unscored(monkeypatch):
    # the model is then the one before the round: nothing is scored on held-out data, and the loop says why it ends
    from bench.residual import loop as loop_module
    from bench.residual.library import label as term_label

    train = _two_friction_trajectories()
    scored = []
    real_heldout = loop_module._Loop.heldout

    def heldout(self, model, train=None, sensor=None):
        scored.append(model)
        return real_heldout(self, model, train, sensor)

    def tidy(self, proposed, findings):
        return proposed, [term_label(e) for e in proposed.effects], {}

    monkeypatch.setattr(loop_module._Loop, "heldout", heldout)
    monkeypatch.setattr(loop_module._Loop, "tidy", tidy)
    out = residual_loop("sysid", train, None, budget=Budget(steps=SOLVED), report=quiet, open_ended=False)
    assert out.ending["reason"] == "redundant" and out.ending["round"] == 1
    assert out.effects == [] and len(scored) == 1  # round 0's model only
