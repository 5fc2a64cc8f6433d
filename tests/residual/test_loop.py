"""The residual loop: it names undeclared effects with their coefficients,
leaves clean and noise-only data alone, and keeps its output contract."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from bench.core.budget import Budget
from bench.core.data import add_noise, generate
from bench.physics.undeclared import add_effects
from bench.physics.models import ExpressionModel
from bench.residual import loop as loop_module, residual_loop, trace, loop_library
from bench.runner.records import read_record, residual_fields
from systems import get_system
from tests.commandline import cli

ROOT = Path(__file__).resolve().parents[2]

#: every loop here is bounded by work, not time (``residual_loop(..., budget=Budget(steps=N))``): the method's fit
#: does N steps, the polish all its starts and the trace until nothing is significant, so what a
#: test sees does not depend on the machine's speed or load. SysId's parameters are polished by the
#: loop anyway; 1000 of its steps leave them far from the optimum on purpose now and then.
SYSID = 1000
#: a solved method (sparse regression, a linear form) does its work in one step
SOLVED = 1
#: the MLP's steps, and a smaller network than its default: enough that it learns the rigid dynamics
#: well enough for the friction to stand out
MLP = 300
SMALL_MLP = {"hidden": 64, "layers": 3, "eval_samples": 256}


def quiet(_line):
    pass


def data_with(effects, n=3000, noise=0.0, system="double_pendulum"):
    s = get_system(system)
    train = add_effects(generate(s, n, 0), effects)
    test = add_effects(generate(s, n // 2, 1000), effects)
    if noise:
        train, test = add_noise(train, "indirect", noise, 0), add_noise(test, "indirect", noise, 1)
    return train, test


def parts(effects: list[dict]) -> list[dict]:
    """The JSON's entries with each law of several parts replaced by its parts."""
    return [p for e in effects for p in e.get("parts", [e])]


@pytest.mark.parametrize(
    "effects",
    [
        {"viscous_friction": (0.8, 0.5)},
        {"coulomb_friction": (1.5, 0.7)},
        {"spring": (2.0, 1.0)},
        {"offset": (0.5, -0.3)},
        {"viscous_friction": (0.8, 0.0), "coulomb_friction": (0.0, 0.7)},
    ],
    ids=["viscous", "coulomb", "spring", "offset", "mixed"],
)
def test_each_effect_is_named_on_its_joint_with_its_coefficient(effects):
    train, test = data_with(effects)
    out = residual_loop("sparse", train, test, budget=Budget(steps=SOLVED), report=quiet)
    want = {(name, j + 1): c for name, coefs in effects.items() for j, c in enumerate(coefs) if c}
    found = {(e["name"], e["joint"]): e["coefficient"] for e in out.effects}
    assert set(found) == set(want)
    for key, c in want.items():
        assert found[key] == pytest.approx(c, rel=0.05)
    assert out.mse_after["test"] <= 1e-3 * out.mse_before["test"]


@pytest.mark.parametrize("method", ["sysid", "sparse"])
@pytest.mark.parametrize("spec", ["coupled_spring=1-2:3.0", "coupled_damper=1-2:0.6"], ids=["elbow spring", "elbow damper"])
def test_an_elbow_spring_or_damper_is_one_effect_with_its_parameter(method, spec):
    # absolute angles: the elbow's relative angle is q_1 - q_2, and its law is one term of L or D
    from bench.physics.undeclared import parse_effects

    effects = parse_effects([spec], 2)
    train, test = data_with(effects)
    out = residual_loop(method, train, test, budget=Budget(steps=SYSID), report=quiet)
    (effect,) = out.effects
    (name, pairs), = effects.items()
    (value,) = pairs.values()
    assert effect["name"] == name and effect["joints"] == [1, 2] and "joint" not in effect
    assert effect["kind"] == ("conservative" if name == "coupled_spring" else "dissipative")
    (param,) = effect["parameters"].values()
    assert param["value"] == pytest.approx(value, rel=0.02)
    assert effect["law"] in ("L += -k*(q_1 - q_2)**2/2", "D = b*(qd_1 - qd_2)**2/2")
    assert out.mse_after["test"] <= 1e-6 * out.mse_before["test"]


def test_armature_is_found_by_sysid_whose_declared_form_cannot_absorb_it():
    # a generic library would absorb qd_1^2 / 2 into L; the declared form cannot
    train, test = data_with({"armature": (0.3, 0.0)}, n=1500)
    out = residual_loop("sysid", train, test, budget=Budget(steps=SYSID), report=quiet)
    assert [(e["name"], e["joint"]) for e in out.effects] == [("armature", 1)]
    assert out.effects[0]["coefficient"] == pytest.approx(0.3, rel=0.05)
    assert out.mse_after["test"] <= 1e-3 * out.mse_before["test"]


def test_clean_data_is_left_alone():
    train, test = data_with({})
    out = residual_loop("sparse", train, test, budget=Budget(steps=SOLVED), report=quiet)
    assert out.effects == [] and out.mse_after == out.mse_before


def test_noise_alone_produces_no_effect_and_noisy_effects_are_still_found():
    train, test = data_with({}, noise=0.05)
    assert residual_loop("sparse", train, test, budget=Budget(steps=SOLVED), report=quiet).effects == []
    train, test = data_with({"viscous_friction": (0.8, 0.5)}, noise=0.01)
    out = residual_loop("sparse", train, test, budget=Budget(steps=SOLVED), report=quiet)
    found = {(e["name"], e["joint"]): e for e in out.effects}
    assert set(found) == {("viscous_friction", 1), ("viscous_friction", 2)}
    for (name, joint), c in {("viscous_friction", 1): 0.8, ("viscous_friction", 2): 0.5}.items():
        e = found[(name, joint)]
        assert abs(e["coefficient"] - c) < 5 * e["stderr"] + 0.02 * c


def test_pure_noise_residual_accepts_nothing():
    data = generate(get_system("double_pendulum"), 5000, 2)
    rng = np.random.default_rng(0)
    traced = trace(rng.normal(size=data.tau.shape), data, loop_library(2))
    assert traced.accepted == [] and traced.steps[-1]["accepted"] is False


def test_cli_data_with_effects_then_residual_writes_json_and_report(tmp_path):
    for name, n, seed in (("train", 2000, 0), ("test", 1000, 1000)):
        r = cli("data", "--system", "double_pendulum", "--n", str(n), "--seed", str(seed),
                "--out", str(tmp_path / f"{name}.csv"), "--effects", "viscous_friction=0.8,0.5", "coulomb_friction=1.5,0.7")
        assert r.returncode == 0, r.stderr
    r = cli("residual", "--system", "double_pendulum", "--method", "sparse", "--train", str(tmp_path / "train.csv"),
            "--test", str(tmp_path / "test.csv"), "--json", str(tmp_path / "out.json"),
            "--report", str(tmp_path / "report.md"), "--set", "samples=4000")
    assert r.returncode == 0, r.stderr
    # without --steps or --budget the loop is bound by the method's own work (sparse regression: one solve)
    assert read_record(tmp_path / "out.json").describe_budget() == "1 steps"
    # the loop runs in its own process; its progress lines reach the terminal as they are printed
    assert "round 0: fitting sparse" in r.stdout and "round 1: adding" in r.stdout
    out = residual_fields(read_record(tmp_path / "out.json"))
    assert {"system", "method", "mse_before", "mse_after", "effects", "rounds", "fit_budget_s", "provenance"} <= set(out)
    assert out["provenance"]["threads"]["torch_intra_op"] == 1  # the loop's process pins its threads like any run
    assert set(out["mse_before"]) == {"train", "test"}
    # the result traces to its inputs: the command line, every --set, the method's whole configuration, the files
    import hashlib

    inputs = out["inputs"]
    assert inputs["command"].startswith("python -m bench residual --system double_pendulum --method sparse")
    assert "--set samples=4000" in inputs["command"] and inputs["set"] == {"samples": 4000}
    assert inputs["hyperparameters"]["samples"] == 4000 and "threshold" in inputs["hyperparameters"]
    for name in ("train", "test"):
        path = str(tmp_path / f"{name}.csv")
        assert inputs["files"][path]["sha256"] == hashlib.sha256((tmp_path / f"{name}.csv").read_bytes()).hexdigest()
    # Coulomb and viscous friction on one joint are one law, with its parts
    assert sorted((e["name"], e["joint"]) for e in out["effects"]) == [
        ("coulomb_viscous_friction", 1), ("coulomb_viscous_friction", 2)]
    assert all(set(e["parameters"]) == {"F_c", "b"} for e in out["effects"])
    assert sorted((p["name"], p["joint"]) for p in parts(out["effects"])) == [
        ("coulomb_friction", 1), ("coulomb_friction", 2), ("viscous_friction", 1), ("viscous_friction", 2)]
    assert all({"name", "joint", "coefficient", "stderr"} <= set(p) for p in parts(out["effects"]))
    report = (tmp_path / "report.md").read_text()
    assert "## Made from" in report and "--set: samples=4000" in report
    assert "| before (declared model only) |" in report and "![residuals before and after](report_residuals.png)" in report
    assert (tmp_path / "report_residuals.png").read_bytes()[:4] == b"\x89PNG"


def test_cli_refuses_bad_input_in_one_line(tmp_path):
    r = cli("data", "--system", "double_pendulum", "--n", "10", "--seed", "0", "--out", str(tmp_path / "x.csv"),
            "--effects", "friction=1,2")
    assert r.returncode == 2 and "unknown effect 'friction'" in r.stderr and r.stderr.count("\n") == 1
    assert not (tmp_path / "x.csv").exists()
    r = cli("data", "--system", "cart_pole", "--n", "10", "--seed", "0", "--out", str(tmp_path / "x.csv"),
            "--effects", "gravity_tilt=0.1")
    assert r.returncode == 2 and r.stderr.count("\n") == 1
    assert "gravity_tilt needs a planar chain that gives its geometry; cart_pole does not" in r.stderr
    assert not (tmp_path / "x.csv").exists()
    r = cli("residual", "--system", "double_pendulum", "--method", "sparse", "--json", str(tmp_path / "o.json"))
    assert r.returncode == 2 and "give --train" in r.stderr and not (tmp_path / "o.json").exists()
    r = cli("residual", "--system", "double_pendulum", "--method", "operon", "--train", "x.csv")
    assert r.returncode == 2 and "operon" in r.stderr


def test_cli_converts_a_raw_dfki_recording(tmp_path):
    from systems.dfki_double_pendulum import trajectory_path

    # the DFKI file's filter: the lab's 2 ms, every fifth sample kept
    r = cli("convert", "--format", "dfki", str(trajectory_path("03")), "--out", str(tmp_path / "t.csv"),
            "--dt", "0.002", "--decimate", "5")
    assert r.returncode == 0, r.stderr
    assert "recording dfki_trajectory_03: rows 2 to 3.597 ms apart interpolated onto a uniform 2 ms" in r.stdout
    from bench.core.csv_format import read_csv

    data = read_csv(tmp_path / "t.csv", dof=2)
    expected = get_system("dfki_double_pendulum").load("test")
    np.testing.assert_allclose(data.qdd, expected.qdd[: len(data)], rtol=1e-12, atol=1e-12)
    # the settings it was made with travel beside it, and a residual loop on it records them
    from bench.residual.job import ResidualJob

    inputs = ResidualJob.of("dfki_double_pendulum", "sysid", train_path=str(tmp_path / "t.csv")).inputs()
    convert = inputs["files"][str(tmp_path / "t.csv")]["convert"]
    assert convert["format"] == "dfki" and convert["filter"]["cutoff_hz"] == 6.0 and convert["time_unit"] == "s"
    assert list(convert["resampled"]) == ["dfki_trajectory_03"]
    assert convert["command"].startswith("python -m bench convert --format dfki")
    assert list(convert["logs"]) == [str(trajectory_path("03"))] and len(convert["logs"][str(trajectory_path("03"))]) == 64
    # a measured system's own split: its recordings are the files
    own = ResidualJob.of("dfki_double_pendulum", "sysid").inputs()["files"]
    assert str(trajectory_path("03")) in own and len(own) == 7  # the declaration file and its six recordings
    assert any(path.endswith("dfki_double_pendulum.toml") for path in own) and all(len(f["sha256"]) == 64 for f in own.values())


def test_a_huge_symbolic_model_is_refitted_like_a_neural_one():
    import sympy

    from bench.core.symbolic import coordinate_symbols
    from bench.residual import strategies

    (q1, q2), (v1, v2) = coordinate_symbols(2)
    huge = sympy.Add(*[sympy.cos(k * q1) * v1**2 for k in range(1, strategies.MAX_SYMBOLIC_TERMS + 2)])
    model = ExpressionModel(huge, 2)
    assert model.structure() == "expression" and strategies.expression_terms(model) is None
    assert isinstance(strategies.strategy_for(model), strategies.KeptFit)
    small = ExpressionModel(sympy.Add(*[sympy.cos(k * q1) * v1**2 for k in range(1, 4)]), 2)
    assert strategies.strategy_for(small).basis.expressions == list(strategies.expression_terms(small))


def test_cli_bad_files_exit_2_in_one_line_and_write_nothing(tmp_path):
    raw = tmp_path / "raw.csv"
    raw.write_text("time,pos_meas1\n0,1\n")
    r = cli("convert", "--format", "dfki", str(raw), "--out", str(tmp_path / "out.csv"))
    assert r.returncode == 2 and r.stderr.count("\n") == 1
    assert f"{raw}: missing column(s) pos_meas2" in r.stderr and not (tmp_path / "out.csv").exists()
    bad = tmp_path / "train.csv"
    bad.write_text("q_1,q_2,qd_1,qd_2,qdd_1,qdd_2,tau_1,tau_2\n1,2,3,4,5,6,7,x\n")
    r = cli("residual", "--system", "double_pendulum", "--method", "sparse", "--train", str(bad),
            "--json", str(tmp_path / "o.json"), "--report", str(tmp_path / "o.md"))
    assert r.returncode == 2 and r.stderr.count("\n") == 1
    assert f"{bad}: column tau_2 has a non-numeric value 'x' in data row 1" in r.stderr
    assert not (tmp_path / "o.json").exists() and not (tmp_path / "o.md").exists()


def test_open_ended_search_names_a_dissipation_outside_the_named_list():
    # quadratic drag on joint 2, D = c |qd_2|^3 / 3: no named effect, one open-ended term of D
    s = get_system("double_pendulum")
    train, test = generate(s, 3000, 0), generate(s, 1500, 1000)
    for d in (train, test):
        d.tau[:, 1] += 0.4 * d.qd[:, 1] * np.abs(d.qd[:, 1])
    out = residual_loop("sparse", train, test, budget=Budget(steps=SOLVED), report=quiet)
    (e,) = out.effects
    assert e["name"] == "symbolic" and e["kind"] == "dissipative" and e["expression"] == "Abs(qd_2)**3/3"
    assert e["joints"] == [2] and e["coefficient"] == pytest.approx(0.4, rel=0.02)
    assert e["law"] == "D = c*qd_2**2*Abs(qd_2)/3"  # sympy writes |qd|^3 so
    assert out.mse_after["test"] <= 1e-3 * out.mse_before["test"]


def test_open_ended_search_names_a_lagrangian_term_the_declared_form_lacks():
    # an inertia coupling the rod form has no freedom for: L += 0.3 qd_1^2 cos(q_2)
    import sympy

    from bench.physics.terms import Term

    q2, v1 = sympy.symbols("q_2 qd_1", real=True)
    extra = Term.lagrangian(0.3 * v1**2 * sympy.cos(q2))
    s = get_system("double_pendulum")
    train, test = (d.replace(tau=d.tau + extra.torque(d)) for d in (generate(s, 3000, 0), generate(s, 1500, 1000)))
    out = residual_loop("sysid", train, test, budget=Budget(steps=SYSID), report=quiet)
    (e,) = [e for e in out.effects if e["kind"] != "structural"]
    assert e["name"] == "symbolic" and e["kind"] == "conservative" and e["expression"] == "qd_1**2*cos(q_2)"
    # a named law that stood in for it (a gain, say) is not reported; what was seen is
    assert all(f["name"] == "unnamed" and f["expression"] == "qd_1**2*cos(q_2)" for f in out.effects if f is not e)
    assert e["joints"] == [1, 2] and e["parameters"]["c"]["value"] == pytest.approx(0.3, rel=0.02)
    assert out.mass_matrix["positive_definite"]
    assert out.mse_after["test"] <= 1e-6 * out.mse_before["test"]


def test_a_named_effect_is_preferred_to_an_open_ended_term_that_mimics_it():
    # SysId's gravity absorbs sin(q_1) of a spring on joint 1, leaving c (q_1 - sin q_1) ~ q_1^3;
    # the spring is tried first and named
    train, test = data_with({"spring": (2.0, 1.0)}, n=2000, noise=0.01)
    out = residual_loop("sysid", train, test, budget=Budget(steps=SYSID), report=quiet)
    assert sorted((e["name"], e["joint"]) for e in out.effects) == [("spring", 1), ("spring", 2)]


def test_no_round_starts_that_would_end_past_the_budget():
    train, test = data_with({"viscous_friction": (0.8, 0.5)}, n=1000)
    out = residual_loop("sparse", train, test, budget=Budget(seconds=1e-6), report=quiet)
    assert [r["round"] for r in out.rounds] == [0, 1] and "budget" in out.rounds[1]["stop"]
    assert out.effects == [] and out.budget_s == 1e-6 and out.fit_budget_s == 0.5e-6


def test_a_trace_cut_short_by_the_budget_says_so_rather_than_that_nothing_is_left(monkeypatch):
    import bench.residual.loop as loop

    monkeypatch.setattr(loop, "TRACE_SHARE", 0.0)  # tracing's time is over as soon as it begins
    train, test = data_with({"viscous_friction": (0.8, 0.5)}, n=1000)
    lines = []
    out = residual_loop("sparse", train, test, budget=Budget(seconds=20), report=lines.append)  # a time budget, as it is of one
    assert out.effects == [] and out.rounds[1]["trace"][-1]["stop"] == "the loop's budget: no further step started"
    assert any("budget ran out before the trace found anything" in line for line in lines), lines
    assert not any("nothing significant left" in line for line in lines)


def test_a_neural_model_keeps_its_fit_and_only_the_effects_are_fitted():
    # under a work budget the fit and each of the two cross-fits do the same steps
    train, test = data_with({"viscous_friction": (0.8, 0.5), "coulomb_friction": (1.5, 0.7)}, n=2000)
    out = residual_loop("mlp", train, test, budget=Budget(steps=MLP), hyperparameters=SMALL_MLP, report=quiet)
    assert out.budget == {"kind": "steps", "steps": MLP, "ceiling_s": None} and out.fit_budget_s is None
    assert out.rounds[0]["cross_fit"]["fit_budget"]["steps"] == MLP
    first, last = out.models
    assert last.rigid is first.rigid  # the MLP was not fitted again
    assert out.effects and out.mse_after["test"] < out.mse_before["test"]
    # its held-out figure holds out only the effects' coefficients, and says so
    assert out.heldout_holds_out == "the effects only: the fit saw every training row"


def test_the_result_is_typed_and_its_json_is_plain():
    train, test = data_with({"offset": (0.5, 0.0)}, n=1000)
    out = residual_loop("sparse", train, test, budget=Budget(steps=SOLVED), report=quiet)
    first, final = out.models
    assert final.predict_torque(test).shape == test.tau.shape and "models" not in out.to_json()
    assert json.loads(json.dumps(out.to_json())) == out.to_json()
    assert [(e["name"], e["joint"]) for e in out.effects] == [("offset", 1)]
    with pytest.raises(dataclasses.FrozenInstanceError):  # a result is what the loop made, as a record is
        out.stopped = "changed afterwards"
    assert out.made_at.startswith("commit ")
    assert out.work().steps == SOLVED


def test_the_loops_job_checks_its_input_once_before_its_process_starts(monkeypatch):
    from bench.core.errors import UserError
    from bench.residual.job import ResidualJob, run_residual
    from bench.runner import job as runner_job

    monkeypatch.setattr(runner_job, "run_watched", lambda *a, **k: pytest.fail("a process started before the refusal"))
    for job, words in ((ResidualJob.of("double_pendulum", "sysid"), "double_pendulum is simulated: give --train"),
                       (ResidualJob.of("double_pendulum", "operon", train_path="t.csv"), "operon cannot run the loop"),
                       (ResidualJob.of("double_pendulum", "sysid", train_path="t.csv", hyperparameters={"nope": 1}),
                        "nope")):
        with pytest.raises(UserError, match=words):
            run_residual(job, quiet)


def test_friction_on_every_joint_of_the_panda_is_found_beside_its_base_parameters():
    panda = get_system("panda")
    effects = {"viscous_friction": tuple(0.1 + 0.05 * j for j in range(7)),
               "coulomb_friction": tuple(0.3 + 0.1 * j for j in range(7))}
    train, test = add_effects(generate(panda, 1000, 0), effects), add_effects(generate(panda, 500, 1000), effects)
    out = residual_loop("sysid", train, test, budget=Budget(steps=SOLVED), report=quiet)
    assert sorted(e["joint"] for e in out.effects) == list(range(1, 8))  # one friction law a joint
    assert {e["name"] for e in out.effects} == {"coulomb_viscous_friction"}
    found = {(e["name"], e["joint"]): e["coefficient"] for e in parts(out.effects)}
    want = {(name, j + 1): c for name, coefs in effects.items() for j, c in enumerate(coefs)}
    assert set(found) == set(want)
    for key, c in want.items():
        assert found[key] == pytest.approx(c, rel=0.05)
    assert out.mse_after["test"] <= 1e-3 * out.mse_before["test"]


def test_the_polish_screens_its_starts_on_a_subsample_and_refines_the_best_on_all_samples(monkeypatch):
    # parameters an optimiser cut short once left (negative masses and lengths): fitted on all 3000
    # samples, this start alone took the whole polish's time and ended in a local minimum
    import bench.residual.strategies as strategies
    from bench.physics.models import ParametricModel

    train, _ = data_with({})
    form = get_system("double_pendulum").parametric_form()
    fitted_on, fit = [], strategies.nonlinear_fit
    monkeypatch.setattr(strategies, "nonlinear_fit", lambda rigid, data, *a: fitted_on.append(len(data)) or fit(rigid, data, *a))
    model = strategies.polish(ParametricModel(form, [-19.7, -0.307, -13.66, -0.186]), train, seed=0)
    assert fitted_on == [strategies.POLISH_SAMPLES] * (strategies.POLISH_STARTS + 1) + [len(train)]
    assert model.rigid.theta == pytest.approx(form.true_values, rel=1e-6)
    assert np.mean((model.predict_torque(train) - train.tau) ** 2) < 1e-12


def _without_timings(obj):
    """The loop's JSON without what measures the machine: seconds, timing, provenance."""
    if isinstance(obj, dict):
        return {k: _without_timings(v) for k, v in obj.items()
                if k not in ("seconds", "fit_seconds", "statistics_seconds", "loop_seconds", "rollout_seconds", "provenance",
                             "curve")}
    if isinstance(obj, list):
        return [_without_timings(v) for v in obj]
    return obj


def test_a_loop_bounded_by_work_gives_the_same_json_apart_from_its_timings():
    # SysId stopped short of its optimum: the polish's starts, the trace and the rounds decide what is
    # found, and under a time budget how many of them ran depended on the machine's load
    from bench.physics.undeclared import parse_effects

    s = get_system("double_pendulum")
    fx = parse_effects(["tip_payload=0.5"], 2)
    train, test = add_effects(generate(s, 1000, 0), fx, s), add_effects(generate(s, 500, 1000), fx, s)
    first, second = (residual_loop("sysid", train, test, budget=Budget(steps=200), report=quiet).to_json() for _ in range(2))
    assert first["budget"] == {"kind": "steps", "steps": 200, "ceiling_s": None}
    assert first["kind"] == "residual" and [e["name"] for e in first["details"]["effects"]] == ["tip_payload"]
    assert _without_timings(first) == _without_timings(second)


@pytest.mark.parametrize("method", ["sysid", "sparse"])
def test_noisy_coulomb_and_viscous_friction_is_that_law_never_a_stribeck_hump(method):
    # with 5 % noise a hump at a large velocity fits nearly as well as Coulomb friction; the loop
    # reports the simpler law the data identify, one friction law a joint, with its parameters
    train, test = data_with({"viscous_friction": (0.8, 0.5), "coulomb_friction": (1.5, 0.7)}, n=3000, noise=0.05)
    out = residual_loop(method, train, test, budget=Budget(steps=SYSID), report=quiet)
    friction = [e for e in out.effects if e["kind"] == "dissipative"]
    assert sorted((e["name"], e["joint"]) for e in friction) == [("coulomb_viscous_friction", 1),
                                                                  ("coulomb_viscous_friction", 2)]
    assert not any("stribeck" in e["name"] for e in out.effects)
    for e, (F_c, b) in zip(sorted(friction, key=lambda e: e["joint"]), ((1.5, 0.8), (0.7, 0.5))):
        for name, true in (("F_c", F_c), ("b", b)):
            p = e["parameters"][name]
            assert abs(p["value"] - true) < 4 * p["stderr"], (e, name)


def test_a_hump_the_data_cannot_tell_from_coulomb_friction_is_replaced_by_it():
    # a Stribeck hump whose velocity is far above every speed in the data is Coulomb friction
    from bench.core.budget import Budget
    from bench.physics.effects import EFFECTS
    from bench.residual.model import LoopModel
    from bench.residual.pruning import simplest_laws
    from bench.residual.strategies import strategy_for
    from methods import METHODS

    train, _ = data_with({"coulomb_friction": (0.0, 0.7)}, n=1500, noise=0.02)
    rigid = METHODS["sparse"]().fit(train, "indirect", 0, Budget(steps=1))
    hump = EFFECTS["stribeck_hump"].term(1, shape=11.9)
    strategy = strategy_for(rigid)
    model = strategy.refit(LoopModel.bare(strategy.rigid_of(rigid)), train, [hump])
    lines = []
    simpler, changes = simplest_laws(strategy, model, train, lines.append)
    assert [t.name for t in simpler.effects] == ["coulomb_friction"] and len(changes) == 1
    assert "replaced by coulomb_friction on joint 2" in changes[0] and "at an end of its range" in changes[0]
    assert simpler.coef[0] == pytest.approx(0.7, rel=0.05)


def test_a_spring_with_a_rest_angle_is_one_law_with_its_stiffness_and_rest_angle():
    from bench.physics.undeclared import parse_effects

    train, test = data_with(parse_effects(["offset_spring=2:2.0,0.3"], 2))
    out = residual_loop("sysid", train, test, budget=Budget(steps=SYSID), report=quiet)
    (spring,) = out.effects
    assert spring["name"] == "offset_spring" and spring["joints"] == [2]
    assert {k: p["value"] for k, p in spring["parameters"].items()} == pytest.approx({"k": 2.0, "q0": 0.3}, rel=1e-6)
    assert sorted(p["name"] for p in spring["parts"]) == ["offset", "spring"]


def test_a_long_log_is_thinned_and_the_result_says_so(monkeypatch):
    train = generate(get_system("double_pendulum"), 800, 0)
    lines = []
    monkeypatch.setattr(loop_module, "MAX_SAMPLES", 200)
    out = residual_loop("sparse", train, None, budget=Budget(steps=SOLVED), report=lines.append)
    assert out.thinned == 4 and out.to_json()["details"]["thinned"] == 4
    assert any("one sample in 4" in line and "200 samples" in line for line in lines)


def test_a_model_of_a_structure_of_its_own_gets_the_strategy_registered_for_it(monkeypatch):
    from types import SimpleNamespace

    from bench.residual import strategies

    class Mine(strategies.KeptFit):
        name = "mine"

    monkeypatch.setitem(strategies.STRATEGIES, "mine", Mine)
    assert type(strategies.strategy_for(SimpleNamespace(structure=lambda: "mine"))) is Mine
    assert type(strategies.strategy_for(SimpleNamespace(structure=lambda: "unheard of"))) is strategies.KeptFit
    with pytest.raises(ValueError, match="'linear' already has a refit strategy, Linear"):
        strategies.refits("linear")(Mine)


def test_the_residual_commands_default_is_the_methods_own_work_and_seconds_only_where_it_has_none():
    from argparse import Namespace

    from bench.cli.options import DEFAULT_BUDGET_S
    from bench.cli.residual import work
    from methods import METHODS

    def given(method, steps=None, budget=None):
        return work(Namespace(method=method, steps=steps, budget=budget))

    assert given("sysid") == (None, 1) and given("sparse_torque") == (None, 1)
    assert given("feasible+gp") == (None, METHODS["gp"].work) == (None, 30)
    assert given("standard+mlp") == (None, METHODS["mlp"].work)
    assert given("mggp") == (DEFAULT_BUDGET_S, None)  # no work of its own: the default seconds
    assert given("sysid", budget=5.0) == (5.0, None) and given("sysid", steps=3) == (None, 3)
    assert given("sysid", steps=3, budget=9.0) == (9.0, 3)
    for name in METHODS:
        own = METHODS[name].work
        assert own is None or (isinstance(own, int) and own >= 1), name
