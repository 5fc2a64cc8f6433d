"""The measured page's blocks on choices made on the training data: tuned
beside default, validation's best against the test's best, and what select chose."""

from __future__ import annotations

import json

from bench.reporting import tuned
from bench.runner.records import Record, write_record
from bench.runner.spec import RunSpec

STANDARD = {"train_mse": 0.5, "test_mse": 1.0}


def _record(method: str, seed: int, test: float, tune: bool, validation: float | None = None,
            chosen: dict | None = None) -> Record:
    spec = RunSpec("kuka_lwr4", method, "indirect", seed, 60.0, tune=tune)
    details = {"standard_model": STANDARD}
    if tune:
        details["tuning"] = {"validation_mse": validation, "chosen": chosen or {}}
    return Record.new(spec, "ok", train_mse=0.1, test_mse=test, details=details)


def test_tuned_beside_default_and_validation_against_test(tmp_path):
    folder = tmp_path / "measured" / "kuka_60s"
    rows = [("mlp", 0.8, 0.6, {"hidden": 64}), ("feasible+gp", 0.4, 0.5, {"samples": "all"})]
    for method, default, tested, chosen in rows:
        for seed in range(3):
            write_record(folder / "records" / f"{method}{seed}.json", _record(method, seed, default, False))
    # validation puts mlp first on seeds 0 and 1; the test puts feasible+gp first on seed 1 only
    for seed, (v_mlp, t_mlp, v_gp, t_gp) in enumerate([(0.1, 0.6, 0.2, 0.7), (0.1, 0.6, 0.2, 0.5),
                                                         (0.3, 0.6, 0.2, 0.7)]):
        write_record(folder / "records" / f"t_mlp{seed}.json", _record("mlp", seed, t_mlp, True, v_mlp, {"hidden": 64}))
        write_record(folder / "records" / f"t_gp{seed}.json",
                     _record("feasible+gp", seed, t_gp, True, v_gp, {"samples": "all"}))
    text = tuned.tuned_beside_default(tmp_path)
    assert "| MLP | default | 0.8× | 2 | 0.6× | 1 | hidden=64 (3) |" in text
    assert "| feasible rigid body + GP | default | 0.4× | 1 | 0.633× | 2 | samples=all (3) |" in text
    cases = tuned.validation_cases(tmp_path)
    assert [(c["validation_best"], c["test_best"]) for c in cases] == [
        ("mlp", "mlp"), ("mlp", "feasible+gp"), ("feasible+gp", "mlp")]
    assert "**1 of 3**" in tuned.validation_against_test(tmp_path)


def test_the_select_block_lists_every_candidate_and_marks_the_chosen(tmp_path):
    folder = tmp_path / "measured" / "select_default"
    folder.mkdir(parents=True)
    candidates = [{"name": "loop+gp", "status": "ok", "validation_mse": 0.3, "test_mse": 0.4, "test_over_standard": 0.54},
                  {"name": "feasible+delan", "status": "timeout", "validation_mse": None, "test_mse": None}]
    (folder / "select.json").write_text(json.dumps({"chosen": candidates[0], "candidates": candidates}))
    text = tuned.selected(tmp_path)
    assert "| default | loop+gp | 0.3 | 0.4 | 0.54× | **chosen** |" in text and "| default | feasible+delan | timeout |" in text
    # the candidates' stack follows them, reported and never chosen
    stack = {"weights": {"loop+gp": 1.0}, "validation_mse": 0.35, "test_mse": 0.41, "test_over_standard": 0.55}
    (folder / "select.json").write_text(json.dumps({"chosen": candidates[0], "candidates": candidates, "stack": stack}))
    text = tuned.selected(tmp_path)
    assert text.splitlines()[-1] == ("| default | the candidates' stack (nested validation) | 0.35 | 0.41 | 0.55× | "
                                     "reported, not chosen |")
