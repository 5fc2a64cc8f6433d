"""``bench select``: candidates tuned on the training data, one chosen by
validation alone, its page, its JSON and its model file; a second call resumes;
and the test trajectory's torques, read only to score, change no choice."""

from __future__ import annotations

import csv
import gzip
import io
import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from bench.core.budget import Budget
from bench.residual.limits import MAX_ROUNDS
from bench.tools import stack_score
from bench.tools.select import CANDIDATES, FEW_RULE, GP_STEPS, LOWEST_RULE, NETWORK_STEPS, choose, page, specs
from bench.tools.select import rule as select_rule
from systems import SYSTEMS
from bench.core.csv_format import write_csv
from bench.core.scoring import opened
from tests.commandline import cli


@pytest.mark.long
def test_select_chooses_by_validation_and_keeps_the_model(tmp_path):
    out = tmp_path / "sel"
    args = ("select", "--system", "kuka_lwr4", "--candidates", "standard,feasible,feasible+sparse_torque",
            "--steps", "1", "--no-rollout", "--out", out)
    r = cli(*args)
    assert r.returncode == 0, r.stderr
    result = json.loads((out / "select.json").read_text())
    names = [c["name"] for c in result["candidates"]]
    assert names == ["standard", "feasible", "feasible+sparse_torque"]
    for c in result["candidates"]:
        assert c["validation_mse"] > 0 and c["test_mse"] > 0 and c["validation_far_mse"] > 0
    best = min(result["candidates"], key=lambda c: c["validation_mse"])
    assert result["model"] == "model.npz" and (out / result["chosen"]["model"]).exists()  # paths relative to DIR
    assert result["chosen"]["name"] == best["name"] and set(result["chosen"]) >= {"name", "validation_mse", "test_mse"}
    text = (out / "select.md").read_text()
    assert f"| {best['name']} **(chosen)** |" in text and "rank by validation" in text
    assert "(`python -m bench predict --model model.npz --log LOG.csv --out PRED.csv`)" in text  # a built-in arm
    far = min(result["candidates"], key=lambda c: c["validation_far_mse"])["name"]  # and on the farther half
    assert "validation MSE, farther half" in text and f"validation puts {far} first" in text
    for c in result["candidates"]:  # each fold's score, whose mean is the validation MSE, and their spread on the page
        assert len(c["fold_mse"]) >= 2 and min(c["fold_mse"]) <= c["validation_mse"] <= max(c["fold_mse"])
        assert ", ".join(f"{v:.4g}" for v in sorted(c["fold_mse"])) in text
    for c in result["candidates"]:  # under --steps each fold fit does the final fit's work, and the page says so
        assert set(c["work"]["fold_steps"]) == {c["work"]["final_steps"]}
    assert "work: each fold fit → the final fit" in text and " steps, " in text
    write_csv(opened(SYSTEMS["kuka_lwr4"]().load("test")), tmp_path / "test.csv")
    p = cli("predict", "--model", out / "model.npz", "--log", tmp_path / "test.csv", "--out", tmp_path / "p.csv")
    assert p.returncode == 0
    assert float(p.stdout.split("torque MSE ")[1].split()[0]) == pytest.approx(result["chosen"]["test_mse"], rel=1e-5)
    # beside the choice, the candidates' stack: its weights, nested validation and test MSE; scored by the
    # stack's scorer with all its weight on one candidate, that candidate's test MSE as its own run scored it
    stack = result["stack"]
    assert set(stack["weights"]) == set(names) and stack["validation_mse"] > 0 and stack["test_mse"] > 0
    assert "The candidates' stack (convex weights fitted on their held-out predictions" in text
    models = {n: out / m for n, m in stack["models"].items()}
    test = SYSTEMS["kuka_lwr4"]().load("test")
    for c in result["candidates"]:
        alone = {n: float(n == c["name"]) for n in names}
        assert stack_score.test_mse(models, alone, test) == pytest.approx(c["test_mse"], rel=1e-9)
    # SysId's two bodies are two runs of one matrix, each with its own record
    assert len(list((out / "runs" / "records").glob("*.json"))) == 3
    again = cli(*args)  # resumes: every candidate has its record and its model
    assert again.returncode == 0 and "0 run(s) to do" in again.stdout
    assert json.loads((out / "select.json").read_text())["chosen"] == result["chosen"]


def test_select_refuses_in_one_line_what_it_cannot_choose_among(tmp_path):
    r = cli("select", "--system", "double_pendulum", "--out", tmp_path / "s")
    assert r.returncode == 2 and "measured arm" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    r = cli("select", "--system", "dfki_double_pendulum", "--out", tmp_path / "s")  # not an arm; its file is one
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert r.stderr.strip().endswith("(as an arm: --system measured:"
                                     f"{Path('systems/data/dfki_double_pendulum_arm.toml').resolve()})")
    r = cli("select", "--system", "kuka_lwr4", "--candidates", "standard,nonsense", "--out", tmp_path / "s")
    assert r.returncode == 2 and "nonsense" in r.stderr
    assert not (tmp_path / "s" / "select.json").exists()


def test_select_builds_its_system_once_before_its_runs_start(tmp_path, monkeypatch, system_builds):
    """The command builds the arm once, from the split it was given, and hands it down: the checks of its names
    and its candidates, and the data its runs are handed, are that one's."""
    from bench.cli import main
    from bench.tools import select as select_module

    class Started(Exception):
        pass

    def started(name, out, **kwargs):
        raise Started(name, kwargs["split"], len(kwargs["data"][0]))

    monkeypatch.setattr(select_module, "select", started)
    with pytest.raises(Started) as ran:
        main(["select", "--system", "kuka_lwr4", "--split", "swapped", "--out", str(tmp_path / "s")])
    assert system_builds == [("kuka_lwr4", "swapped")]
    assert ran.value.args[:2] == ("kuka_lwr4", "swapped") and ran.value.args[2] > 0


def test_a_candidate_that_failed_or_saved_nothing_is_not_chosen():
    entries = [{"name": "a", "status": "ok", "validation_mse": 0.1, "test_mse": 1.0, "model": None,
                "hyperparameters": {}, "test_over_standard": None, "error": "save failed"},
               {"name": "b", "status": "timeout", "validation_mse": None, "test_mse": None, "model": None,
                "hyperparameters": {}, "test_over_standard": None, "error": "killed"},
               {"name": "c", "status": "ok", "validation_mse": 0.3, "test_mse": 0.2, "model": "c.npz",
                "hyperparameters": {"x": 1}, "test_over_standard": 0.5, "error": None}]
    assert choose(entries)["name"] == "c"
    text = page({"system": "arm", "command": "cmd", "split": None, "budget": "1 steps", "seed": 0, "folds": "f",
                 "chosen": entries[2], "candidates": entries})
    assert "| c **(chosen)** | x=1 |" in text and "timeout: killed" in text


def test_with_two_or_three_trajectories_left_out_whole_select_takes_the_steadiest_within_one_standard_error():
    """The development case ur5_two_drive_0's figures under folds that leave each trajectory out: the lowest
    validation MSE's candidate has the folds that disagree most, and its fit on both trajectories failed on the
    third (16 times the best's test MSE). Under select's default folds, which pool so few trajectories' states
    into regions, the rule is the lowest validation MSE."""
    def entry(name, folds, stderr, test):
        return {"name": name, "status": "ok", "model": f"{name}.npz", "validation_mse": float(np.mean(folds)),
                "validation_stderr": stderr, "fold_mse": folds, "test_mse": test}

    entries = [entry("standard", [0.3096, 0.4093], 0.0498, 0.1827), entry("feasible", [0.2429, 0.3480], 0.0525, 0.1507),
               entry("feasible+gp", [0.2429, 0.3482], 0.0527, 0.1486),
               entry("feasible+sparse_torque", [0.1893, 0.3137], 0.0622, 2.364)]
    assert choose(entries)["name"] == choose(entries, 1)["name"] == choose(entries, 4)["name"] == "feasible+sparse_torque"
    for trajectories in (2, 3):  # within 0.2515 + 0.0622: feasible and feasible+gp agree best over their folds
        assert choose(entries, trajectories)["name"] == choose(entries, trajectories, "auto")["name"] == "feasible"
        assert choose(entries, trajectories, "pooled")["name"] == "feasible+sparse_torque"
    assert select_rule(2) == select_rule(3, "auto") == FEW_RULE
    assert select_rule(4) == select_rule(None) == select_rule(2, "pooled") == select_rule(2, "regions") == LOWEST_RULE
    # a candidate beyond one standard error is not taken, however steady
    steady = entries + [entry("loop", [0.40, 0.41], 0.005, 0.1)]
    assert choose(steady, 2)["name"] == "feasible"


def _arm(folder: Path, test_torque_factor: float) -> Path:
    """The shipped KUKA declared as a measured arm of one's own, its test trajectory's (run 3's) torques
    multiplied by ``test_torque_factor``."""
    data = Path(__file__).resolve().parents[2] / "systems" / "data"
    folder.mkdir()
    for name in ("kuka_lwr4.urdf.gz", "kuka_lwr4_run1.csv.gz", "kuka_lwr4_run2.csv.gz"):
        shutil.copy(data / name, folder / name)
    declared = folder / f"arm_{folder.name}.toml"  # a name of its own: a system is registered by its file's name
    shutil.copy(data / "kuka_lwr4.toml", declared)
    with gzip.open(data / "kuka_lwr4_run3.csv.gz", "rt") as f:
        rows = list(csv.reader(f))
    taus = [i for i, name in enumerate(rows[0]) if name.startswith("tau")]
    for row in rows[1:]:
        for i in taus:
            row[i] = repr(float(row[i]) * test_torque_factor)
    text = io.StringIO()
    csv.writer(text, lineterminator="\n").writerows(rows)
    with gzip.open(folder / "kuka_lwr4_run3.csv.gz", "wt") as f:
        f.write(text.getvalue())
    return declared


@pytest.mark.long
def test_the_test_trajectorys_torques_change_no_choice(tmp_path):
    results = []
    for factor in (1.0, 3.0):
        arm = _arm(tmp_path / f"times{factor:g}", factor)
        out = tmp_path / f"sel{factor:g}"
        r = cli("select", "--system", f"measured:{arm}", "--candidates", "standard,feasible", "--steps", "1",
                "--no-rollout", "--out", out)
        assert r.returncode == 0, r.stderr
        results.append(json.loads((out / "select.json").read_text()))
        # the page's predict line names the file that declares the arm, as predict needs it
        assert f"python -m bench predict --model model.npz --system measured:{arm} --log" in (out / "select.md").read_text()
    same, scaled = results
    assert same["chosen"]["name"] == scaled["chosen"]["name"]
    for a, b in zip(same["candidates"], scaled["candidates"]):
        assert a["validation_mse"] == b["validation_mse"] and a["hyperparameters"] == b["hyperparameters"]
        assert b["test_mse"] > 2 * a["test_mse"]  # the test data were read, to score
    # nor do they change the stack's weights or its validation, only its test figure
    assert same["stack"]["weights"] == scaled["stack"]["weights"]
    assert same["stack"]["validation_mse"] == scaled["stack"]["validation_mse"]
    assert scaled["stack"]["test_mse"] > 2 * same["stack"]["test_mse"]


def test_every_candidate_is_bounded_by_work_whatever_selects_seconds(tmp_path):
    """Without --steps every candidate does its own steps (the same on any machine), the seconds only their
    ceiling: the loop its rounds, the learned residuals their steps (more on more data), the closed-form fits one. Under
    --steps every candidate has the steps."""
    own = {c.name: spec.budget for c, spec in specs("kuka_lwr4", None, 900.0, None, 0, tmp_path, ())}
    assert own["loop"] == Budget(seconds=900.0, steps=MAX_ROUNDS)
    assert own["standard+gp"] == own["loop+gp"] == Budget(seconds=900.0, steps=GP_STEPS)
    assert own["standard+mlp"] == own["feasible+delan"] == Budget(seconds=900.0, steps=NETWORK_STEPS)
    assert own["standard"] == own["feasible+sparse_torque"] == Budget(seconds=900.0, steps=1)
    assert all(b.steps is not None for b in own.values()) and len(own) == len(CANDIDATES)
    # on the KUKA's training samples the GP residuals' passes over the data take no more than their steps;
    # on a longer log they make as many passes, in the GP's batches, and so more steps
    assert {c.name: spec.budget for c, spec in specs("kuka_lwr4", None, 900.0, None, 0, tmp_path, (),
                                                     samples=4926)} == own
    long = {c.name: spec.budget.steps for c, spec in specs("kuka_lwr4", None, 900.0, None, 0, tmp_path, (),
                                                           samples=64240)}
    assert long["standard+gp"] == long["feasible+gp"] == long["loop+gp"] == math.ceil(3.0 * 64240 / 512)
    assert long["standard+mlp"] == long["feasible+delan"] == NETWORK_STEPS  # the networks keep their steps
    assert long["loop"] == MAX_ROUNDS and long["standard"] == 1
    worked = {c.name: spec.budget for c, spec in specs("kuka_lwr4", None, None, 3, 0, tmp_path, (), samples=64240)}
    assert set(worked.values()) == {Budget(steps=3)} and len(worked) == len(CANDIDATES)
    # the driven rollouts, which neither the choice nor the page uses, only where asked for
    assert not any(spec.rollout for _, spec in specs("kuka_lwr4", None, 900.0, None, 0, tmp_path, ()))


def test_selects_default_ceiling_grows_with_the_training_samples_as_the_work_does(tmp_path, monkeypatch):
    """900 s a candidate up to 10,000 training samples, then in proportion: on a longer log the work grows (a
    GP's steps), and the ceiling with it, so that a slower machine finishes it; --budget sets it as given."""
    from bench.cli import select as command

    assert command.ceiling(4926) == command.ceiling(10_000) == 900.0
    assert command.ceiling(64_240) == 5782.0 and command.ceiling(20_001) == 1801.0
    seen = []
    monkeypatch.setattr("bench.tools.select.select", lambda *a, **k: seen.append(k["budget_s"]) or {"chosen": None})
    train = len(SYSTEMS["kuka_lwr4"]().load("train"))
    assert cli("select", "--system", "kuka_lwr4", "--out", tmp_path / "a").returncode == 1
    assert cli("select", "--system", "kuka_lwr4", "--out", tmp_path / "b", "--budget", "30").returncode == 1
    assert seen == [command.ceiling(train), 30.0]


def test_the_candidates_runs_start_the_longest_first_each_at_its_own_place():
    starts = sorted(CANDIDATES, key=lambda c: c.start)
    assert len({c.start for c in CANDIDATES}) == len(CANDIDATES)  # one place each
    assert starts[0].name == "loop"  # the loop's rounds on every fold
    # loop+gp after the longest searches: by then the loop's models, its prior on each fold, are shared
    assert [c.name for c in starts].index("loop+gp") > [c.name for c in starts].index("standard+mlp")
    assert {c.name for c in starts[-2:]} == {"standard", "feasible"}  # closed-form: one step


def test_a_page_whose_test_trajectories_chose_the_filter_says_it_is_test_informed():
    """The DFKI pendulum's swapped split tests on the trajectories that chose its filter's cut-off: its page is
    flagged, on the page itself; a split, or a system, whose tests chose nothing is not."""
    from bench.tools.select import test_informed

    assert test_informed("dfki_double_pendulum", "swapped")["test_informed"] == ["00", "01", "02", "04"]
    assert test_informed("dfki_double_pendulum", None) == {"test_informed": [], "test_informed_by": []}
    # no file declares a simulated system
    assert test_informed("double_pendulum", None) == {"test_informed": [], "test_informed_by": []}
    published = Path("results/measured/select_dfki_swapped")
    result = json.loads((published / "select.json").read_text())
    assert result["test_informed"] == ["00", "01", "02", "04"]
    flag = ("**Test-informed:** the test trajectories 00, 01, 02, 04 were read while these were chosen: the cut-off "
            "of the filter")
    assert page(result).count(flag) == 1
    assert "Test-informed" not in page({**result, "test_informed": []})
    # the KUKA's pages rest on the loop's round rule and the loop_feasible candidate, chosen while its test
    # ranking on both trajectories was known: each says so, from the same field
    for split, trajectory in (("default", "B"), ("swapped", "A")):
        assert test_informed("kuka_lwr4", split)["test_informed"] == [trajectory]
        kuka = json.loads(Path(f"results/measured/select_{split}/select.json").read_text())
        assert kuka["test_informed"] == [trajectory] and "round rule" in kuka["test_informed_by"][0]
        text = Path(f"results/measured/select_{split}/select.md").read_text()
        assert f"**Test-informed:** the test trajectories {trajectory} were read while these were chosen: the " \
               f"residual loop's round rule" in text


def test_page_only_writes_a_select_page_again_from_its_json_running_nothing(tmp_path):
    import shutil

    shutil.copytree("results/measured/select_default", tmp_path / "s", ignore=shutil.ignore_patterns("*.npz"))
    data = json.loads((tmp_path / "s" / "select.json").read_text())
    write_json = __import__("bench.core.fileio", fromlist=["write_json"]).write_json
    write_json(tmp_path / "s" / "select.json", {**data, "test_informed": [], "test_informed_by": []})
    r = cli("select", "--system", "kuka_lwr4", "--out", tmp_path / "s", "--page-only")
    assert r.returncode == 0, r.stderr
    again = json.loads((tmp_path / "s" / "select.json").read_text())
    assert again["test_informed"] == ["B"] and again["candidates"] == data["candidates"]
    assert "written again from its select.json by" in (tmp_path / "s" / "select.md").read_text()
    assert cli("select", "--system", "kuka_lwr4", "--out", tmp_path / "none", "--page-only").returncode == 2


def test_a_stack_of_model_files_without_held_out_predictions_says_how_to_get_them(tmp_path):
    from bench.tools.select import stacked
    from methods import METHODS
    from methods.saving import save_model

    system = SYSTEMS["kuka_lwr4"]()
    train = system.load("train").subset(slice(0, 200))
    fitted = METHODS["sysid"]().fit(train, "indirect", 0, budget=Budget(steps=1), system=system)
    entries = []
    for name in ("a", "b"):  # files saved without their validation's predictions, as before tuning kept them
        save_model(fitted, tmp_path / f"{name}.npz", {"system": system.name, "method": "sysid"}, train, system)
        entries.append({"name": name, "status": "ok", "validation_mse": 0.5, "model": f"{name}.npz"})
    out = stacked(entries, tmp_path, train)
    assert out == {"unavailable": "fewer than two candidates kept their held-out predictions (2 model file(s) made "
                                  "before tuned runs kept them: bench select into a new --out makes them again)"}
    assert "The candidates' stack: unavailable (fewer than two" in page(
        {"system": "arm", "command": "c", "split": None, "budget": "1 steps", "seed": 0, "folds": "f", "chosen": None,
         "candidates": [], "stack": out})
    # predictions whose samples the training data do not hold are not stacked
    for name in ("a", "b"):
        kept = {"index": np.array([0, 500]), "fold": np.array([0, 1]), "prediction": np.zeros((2, 7), np.float32)}
        save_model(fitted, tmp_path / f"{name}.npz", {"system": system.name, "method": "sysid"}, train, system, kept)
    assert stacked(entries, tmp_path, train) == {
        "unavailable": "the candidates' held-out predictions are not of these training data"}



def test_a_stack_whose_test_figure_failed_says_why_on_the_page(tmp_path):
    from bench.tools.select import score_stack

    stack = {"weights": {"a": 1.0}, "validation_mse": 0.3, "models": {"a": "missing.npz"}}
    scored = score_stack(stack, [], tmp_path, SYSTEMS["kuka_lwr4"]().load("test"))
    assert scored["test_mse"] is None and scored["test_error"].startswith("ModelFileError: ")
    assert "missing.npz: no such file" in scored["test_error"]
    text = page({"system": "arm", "command": "c", "split": None, "budget": "1 steps", "seed": 0, "folds": "f",
                 "chosen": None, "candidates": [], "stack": scored})
    assert "validation MSE 0.3 (nested" in text and "; no test figure (ModelFileError: " in text
