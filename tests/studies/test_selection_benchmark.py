"""The selection benchmark: its cases load as measured arms of one's own with
the layout they declare, its rules choose as stated, and regret and the
summary are computed from the candidates' figures. No test reads its
evaluation set."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest

from bench.studies import selection_benchmark as sb


def _entry(name, validation, test, stderr=None):
    return {"name": name, "status": "ok", "model": f"{name}.npz", "validation_mse": validation, "test_mse": test,
            "validation_stderr": stderr}


def test_a_case_is_a_measured_arm_with_the_layout_it_declares(tmp_path):
    from systems import get_system
    from systems.measured_arm import register_measured

    for case in (sb.Case("ur5", "one", "drive", 0), sb.Case("ur5", "several", "sensor", 0)):
        declared = sb.make(case, tmp_path / case.name)
        system = get_system(register_measured(f"measured:{declared}"))
        train, test = system.load("train"), system.load("test")
        per = int(sb.SECONDS * sb.RATE_HZ)
        if case.layout == "one":
            assert train.trajectories() == ["A"] and len(train) == 2 * per
        else:
            assert len(train.trajectories()) == sb.SEVERAL and len(train) == sb.SEVERAL * per
        assert test.trajectories() == ["T"] and len(test) == per and train.dof == 6
        assert sb.make(case, tmp_path / case.name) == declared  # made once


def test_the_rules_choose_as_stated_and_regret_is_against_the_best_on_the_test():
    entries = [_entry("standard+gp", 0.50, 0.9, 0.05), _entry("standard", 0.53, 0.6, 0.02),
               _entry("standard+mlp", 0.70, 0.3, 0.1), {"name": "loop", "status": "timeout", "model": None, "validation_mse": None, "test_mse": None}]
    assert sb.choose(entries, "lowest")["name"] == "standard+gp"
    assert sb.choose(entries, "one_se")["name"] == "standard"  # within 0.05 of the lowest, and simpler
    assert sb.choose(entries, "farther")["name"] == "standard+gp"  # no figure on the farther half: the lowest
    far = [dict(e, validation_far_mse=f) for e, f in zip(entries[:3], (0.9, 0.8, 0.85))]
    assert sb.choose(far, "farther")["name"] == "standard"  # the lowest on the farther half
    s = sb.scores({"candidates": entries})
    assert s["best"] == "standard+mlp"
    assert s["rules"]["lowest"]["regret"] == pytest.approx(3.0) and s["rules"]["one_se"]["regret"] == pytest.approx(2.0)
    assert s["spearman"] == pytest.approx(-1.0)  # validation ranks them exactly against the test
    assert "stack" not in s["rules"]  # a page made before select stacked its candidates: no figure, no fallback
    # each candidate's figures are kept, so that a rule can be tried on the page's JSON without running the cases
    assert s["candidates"]["standard"] == {"validation_mse": 0.53, "validation_far_mse": None, "validation_stderr": 0.02,
                                           "fold_mse": None, "train_mse": None, "test_mse": 0.6}
    assert s["candidates"]["loop"]["test_mse"] is None
    stacked = {"candidates": entries, "stack": {"validation_mse": 0.4, "test_mse": 0.15}}
    assert sb.scores(stacked)["rules"]["stack"] == {"chosen": "stack", "regret": pytest.approx(0.5)}
    worse = {"candidates": entries, "stack": {"validation_mse": 0.6, "test_mse": 0.15}}
    assert sb.scores(worse)["rules"]["stack"]["chosen"] == "standard+gp"  # validated worse than the lowest
    unscored = {"candidates": entries, "stack": {"weights": {"standard": 1.0}, "validation_mse": 0.4, "test_mse": None}}
    assert "stack" not in sb.scores(unscored)["rules"]  # no test figure: no regret, rather than the lowest's
    table = [{"case": "a", "protocol": "time", "scores": s},
             {"case": "b", "protocol": "time", "scores": sb.scores({"candidates": entries[:2]})}]
    lowest = next(r for r in sb.summary(table) if r["rule"] == "lowest")
    assert lowest["cases"] == 2 and lowest["worst_regret"] == pytest.approx(3.0) and lowest["best_chosen"] == 0
    assert "failed" in sb.page({"command": "c", "set": "development", "cases": ["a"], "candidates": ["x"], "steps": 1,
                                "summary": [], "table": [{"case": "a", "protocol": "time",
                                                          "scores": sb.scores({"candidates": []})}]})


def test_select_default_folds_are_regions_of_one_trajectory_and_whole_trajectories_of_several():
    assert sb.resolve("auto", "one") == "regions" and sb.resolve("auto", "several") == "time"
    assert sb.resolve("knndm", "one") is None and sb.resolve("knndm", "several") == "knndm"
    assert sb.resolve("time", "one") == "time"


def test_real_only_reads_the_real_arms_pages_again_and_keeps_the_cases_rows(tmp_path, monkeypatch):
    import json
    from types import SimpleNamespace

    select = tmp_path / "select.json"
    select.write_text(json.dumps({"folds_protocol": "regions",
                                  "candidates": [_entry("standard", 0.5, 0.8), _entry("loop", 0.6, 0.4)]}))
    monkeypatch.setattr(sb, "REAL", {"an arm": str(select)})
    out = tmp_path / "benchmark.md"
    args = SimpleNamespace(real_only=True, out=out, invocation="python -m bench study selection --real-only")
    from bench.core.errors import UserError

    with pytest.raises(UserError, match="benchmark.json: no page"):  # one line, exit 2, on the command line
        sb.main(args)
    cases = [{"case": "a", "protocol": "time", "scores": sb.scores({"candidates": [_entry("standard", 0.5, 0.6)]})}]
    made = {"command": "the cases' command", "commit": "c0", "set": "evaluation", "cases": ["a"], "candidates": ["x"],
            "steps": 20, "table": cases, "summary": sb.summary(cases), "real": []}
    out.with_suffix(".json").write_text(json.dumps(made))
    assert sb.main(args) == 0
    result = json.loads(out.with_suffix(".json").read_text())
    assert result["table"] == cases and result["command"] == "the cases' command" and result["commit"] == "c0"
    (row,) = result["real"]
    assert row["case"] == "an arm" and row["scores"]["rules"]["lowest"] == {"chosen": "standard", "regret": 2.0}
    text = out.read_text()
    assert "Command: `the cases' command`, at commit c0" in text
    assert "Read again by `python -m bench study selection --real-only`" in text and "standard (2.000)" in text


def test_the_cases_are_jobs_of_the_one_scheduler_and_a_second_run_resumes_from_the_ledger(tmp_path, monkeypatch):
    import json
    from pathlib import Path
    from types import SimpleNamespace

    from bench.runner.ledger import Ledger

    monkeypatch.setattr(sb, "REAL", {})
    case = sb.Case("ur5", "one", "drive", 0)
    out = tmp_path / "benchmark.md"
    job = sb.SelectCase(case.arm, case.layout, case.effects, case.seed, "regions", 2, sb.CANDIDATES, 1,
                        str(tmp_path / "cases_development" / case.name))
    assert sb.SelectCase.from_payload(json.loads(json.dumps(job.payload()))) == job  # it travels as JSON
    assert job.elsewhere(Path("/scratch")).folder() == Path(f"/scratch/{case.name}")  # on a cluster's worker
    kept = sb.scores({"candidates": [_entry("standard", 0.5, 0.6), _entry("feasible", 0.4, 0.3)]})
    Ledger(out).add(f"{case.name} regions", job, kept)  # as a run stopped after this case would have left it
    args = SimpleNamespace(real_only=False, rescore=False, out=out, set="development", cases=[case.name], protocols=["auto"],
                           steps=2, workers=1, cluster=None, invocation="python -m bench study selection",
                           candidates=list(reversed(sb.CANDIDATES)))  # select's order whatever the order given
    assert sb.main(args) == 0  # nothing left to run: no select is started
    result = json.loads(out.with_suffix(".json").read_text())
    assert result["table"] == [{"case": case.name, "protocol": "auto", "folds": "regions", "scores": kept}]
    assert not Ledger(out).path.exists()  # the page is written: its ledger goes
    assert not (tmp_path / "cases_development").exists()


def test_a_real_row_tested_on_recordings_a_choice_read_is_flagged_test_informed():
    """The DFKI pendulum's 6 Hz cut-off was chosen on 00, 01, 02 and 04: its swapped split tests on them, its
    default split (03, 05) does not. The loop's round rule and the loop_feasible candidate were chosen while the
    KUKA's test ranking on both its trajectories was known: both its rows are flagged, saying so."""
    rows = {r["case"]: r for r in sb.real_rows()}
    assert rows["dfki_double_pendulum (swapped split)"]["test_informed"] == ["00", "01", "02", "04"]
    assert rows["dfki_double_pendulum (default split)"]["test_informed"] == []
    assert rows["kuka_lwr4 (default split)"]["test_informed"] == ["B"]
    assert rows["kuka_lwr4 (swapped split)"]["test_informed"] == ["A"]
    assert "round rule" in rows["kuka_lwr4 (default split)"]["test_informed_by"][0]
    made = json.loads(Path("results/selection/development.json").read_text())
    text = sb.page({**made, "real": list(rows.values())})
    assert text.count("**Test-informed:**") == 3
    assert "**Test-informed:** dfki_double_pendulum (swapped split) tests on 00, 01, 02, 04" in text
    assert ("**Test-informed:** kuka_lwr4 (default split) tests on B, read while these were chosen: the residual "
            "loop's round rule and bench select's loop_feasible candidate") in text


@pytest.mark.parametrize("given, said", [(["standard", "nonsense"], "unknown candidate(s) nonsense"),
                                         (["standard", "standard"], "two at least")])
def test_candidates_other_than_selects_or_fewer_than_two_are_refused_in_one_line(tmp_path, given, said):
    from types import SimpleNamespace

    from bench.core.errors import UserError

    args = SimpleNamespace(real_only=False, rescore=False, out=tmp_path / "benchmark.md", set="development", cases=["ur5_one"],
                           protocols=["auto"], steps=2, workers=1, cluster=None, invocation="", candidates=given)
    with pytest.raises(UserError, match=re.escape(said)):
        sb.main(args)
    assert not list(tmp_path.iterdir())


def test_rerun_runs_only_the_named_candidates_and_scores_the_rules_on_the_merged_figures(tmp_path, monkeypatch):
    from types import SimpleNamespace

    from bench.core.errors import UserError
    from bench.studies import selection_rerun

    monkeypatch.setattr(sb, "REAL", {})
    case = sb.Case("ur5", "one", "drive", 0)
    kept = sb.scores({"candidates": [_entry("standard", 0.5, 0.6), _entry("feasible", 0.4, 0.3),
                                     _entry("loop", 0.3, 0.5)], "stack": {"validation_mse": 0.1, "test_mse": 0.1}})
    rows = [{"case": case.name, "protocol": "auto", "folds": "regions", "scores": kept}]
    out = tmp_path / "benchmark.md"
    out.with_suffix(".json").write_text(json.dumps(
        {"command": "the cases' command", "commit": "c0", "set": "development", "cases": [case.name],
         "candidates": ["standard", "feasible", "loop"], "steps": 2, "table": rows, "summary": sb.summary(rows),
         "real": []}))
    ran = {}

    def run_jobs(jobs, *_, **__):  # the loop, run again, is now validated best, and is the best on the test
        ran.update(jobs)
        return {name: sb.scores({"candidates": [_entry("loop", 0.2, 0.1)]}) for name in jobs}

    monkeypatch.setattr(selection_rerun, "run_jobs", run_jobs)
    args = SimpleNamespace(out=out, candidates=["loop"], workers=1, cluster=None,
                           invocation="python -m bench study selection-rerun --candidates loop")
    assert selection_rerun.main(args) == 0
    (job,) = ran.values()
    assert job.candidates == ("loop",) and job.folds == "regions" and job.where.endswith(f"cases_development_rerun/{case.name}")
    result = json.loads(out.with_suffix(".json").read_text())
    s = result["table"][0]["scores"]
    assert s["best"] == "loop" and s["rules"]["lowest"] == {"chosen": "loop", "regret": 1.0}
    assert s["candidates"]["feasible"]["test_mse"] == 0.3 and s["candidates"]["loop"]["test_mse"] == 0.1
    assert "stack" not in s["rules"]  # the stack needs every candidate's held-out predictions
    assert result["commit"] == "c0" and result["reruns"][0]["candidates"] == ["loop"]
    assert "Run again, loop only, by `python -m bench study selection-rerun --candidates loop`" in out.read_text()
    with pytest.raises(UserError, match=re.escape("--candidates: unknown candidate(s) nonsense")):
        selection_rerun.main(SimpleNamespace(**(vars(args) | {"candidates": ["nonsense"]})))
    # a candidate the page lacks is added, in select's order
    monkeypatch.setattr(selection_rerun, "run_jobs", lambda jobs, *_, **__: {
        name: sb.scores({"candidates": [_entry("loop+gp", 0.1, 0.05)]}) for name in jobs})
    assert selection_rerun.main(SimpleNamespace(**(vars(args) | {"candidates": ["loop+gp"]}))) == 0
    result = json.loads(out.with_suffix(".json").read_text())
    assert result["candidates"] == ["standard", "feasible", "loop", "loop+gp"]
    assert result["table"][0]["scores"]["rules"]["lowest"] == {"chosen": "loop+gp", "regret": 1.0}
    assert [r["candidates"] for r in result["reruns"]] == [["loop"], ["loop+gp"]]


def test_the_former_evaluation_sets_are_development_data_and_the_evaluation_set_is_new_and_of_every_layout():
    former, second, third, development, evaluation = (sb.cases(s) for s in (
        sb.FORMER_EVALUATION, sb.SECOND_EVALUATION, sb.THIRD_EVALUATION, sb.DEVELOPMENT, sb.EVALUATION))
    assert {c.seed for c in former} == {5113, 6271} and {c.layout for c in former} == {"one", "several"}
    assert {c.seed for c in second} == {7411, 9043} and {c.seed for c in third} == {3187, 4729}
    tried = former + second + third + development
    assert not {c.seed for c in evaluation} & {c.seed for c in tried}  # seeds no rule was tried on
    for new in (second, third, evaluation):
        assert {c.layout for c in new} == {"one", "several", "two", "three"} and \
            {c.arm for c in new} == set(sb.ARMS) | {sb.GEARED}
    assert not {c.name for c in evaluation} & {c.name for c in tried}
    # the second evaluation set's page, made when it was named evaluation, says it is development data now
    made = json.loads(Path("results/selection/second_evaluation/evaluation.json").read_text())
    assert made["set"] == sb.EVALUATION and sb.set_of(made) == sb.SECOND_EVALUATION
    text = Path("results/selection/second_evaluation/evaluation.md").read_text()
    assert text == sb.page(made) and "which is `--set second_evaluation` now" in text
    assert "Set: second_evaluation (development data: this set (seeds 7411 and 9043) was the evaluation set" in text
    # and so does the third's, on which select's pooled folds were chosen
    made = json.loads(Path("results/selection/third_evaluation/evaluation.json").read_text())
    assert made["set"] == sb.EVALUATION and sb.set_of(made) == sb.THIRD_EVALUATION
    text = Path("results/selection/third_evaluation/evaluation.md").read_text()
    assert text == sb.page(made) and "which is `--set third_evaluation` now" in text
    assert "Set: third_evaluation (development data: this set (seeds 3187 and 4729) was the evaluation set" in text
    # the published pages of the former evaluation set say that it is development data, and how to run it now
    for path in ("results/selection/benchmark.json", "results/selection/all_candidates/benchmark.json"):
        made = json.loads(Path(path).read_text())
        assert sb.set_of(made) == sb.FORMER_EVALUATION
        text = Path(path).with_suffix(".md").read_text()
        assert text == sb.page(made)
        assert "Set: former_evaluation (development data: this set (seeds 5113 and 6271) was the evaluation set" in text
        assert "which is `--set former_evaluation` now" in text


def test_the_select_rule_is_selects_own_and_the_few_trajectories_page_is_scored_by_it(tmp_path):
    from types import SimpleNamespace

    entries = [dict(_entry("standard", 0.30, 0.15, 0.05), fold_mse=[0.25, 0.35]),
               dict(_entry("feasible+sparse_torque", 0.25, 2.4, 0.06), fold_mse=[0.19, 0.31])]
    assert sb.scores({"candidates": entries}, 2)["rules"]["select"] == {"chosen": "standard", "regret": 1.0}
    assert sb.scores({"candidates": entries, "training_trajectories": 4}, 2)["rules"]["select"]["chosen"] == \
        "feasible+sparse_torque"  # what select said it had
    assert sb.scores({"candidates": entries})["rules"]["lowest"]["chosen"] == "feasible+sparse_torque"
    # --rescore reads each case's select page again, and the published page is what it gives
    published = Path("results/selection/few_trajectories/development.md")
    shutil.copytree(published.parent, tmp_path / "few")
    out = tmp_path / "few" / "development.md"
    args = SimpleNamespace(real_only=False, rescore=True, out=out, invocation="python -m bench study selection --rescore")
    assert sb.main(args) == 0
    again, before = json.loads(out.with_suffix(".json").read_text()), json.loads(published.with_suffix(".json").read_text())
    assert again["table"] == before["table"] and again["summary"] == before["summary"]
    select = next(r for r in again["summary"] if r["protocol"] == "auto" and r["rule"] == "select")
    lowest = next(r for r in again["summary"] if r["protocol"] == "auto" and r["rule"] == "lowest")
    assert select["worst_regret"] < 1.25 < lowest["worst_regret"]
