"""The residual loop's result is a record of the suite's one schema, of kind ``residual``."""

from __future__ import annotations

import json

import pytest

from bench.residual.result import ResidualResult
from bench.runner.records import RecordError, read_record, read_records, residual_fields, write_record
from bench.runner.spec import RunSpec


def result(**changes) -> ResidualResult:
    fields = dict(system="double_pendulum", method="sysid", mse_before={"train": 3.0, "test": 4.0},
                  mse_after={"train": 1.5, "test": 2.5}, effects=[{"name": "viscous_friction", "joint": 1}],
                  rounds=[{"round": 0, "mse": {"train": 3.0}, "heldout_mse": 3.2}], lagrangian="qd_1**2/2",
                  seconds=12.5, budget_s=60.0, fit_budget_s=30.0, seed=3, train_source="train.csv",
                  test_source="test.csv", budget={"kind": "seconds", "seconds": 60.0}, provenance={"commit": "abc"})
    return ResidualResult(**{**fields, **changes})


def test_the_loops_result_is_a_record_of_kind_residual_and_reads_back(tmp_path):
    spec = RunSpec(system="double_pendulum", method="sysid", experiment="indirect", seed=3, budget_s=60.0,
                   train_path="train.csv").to_dict()
    out = result(spec=spec, code={"hash": "0123"})
    write_record(tmp_path / "loop.json", out.to_record())
    record = read_record(tmp_path / "loop.json")
    assert record.kind == "residual" and record.spec == spec and record.run_id == "double_pendulum__sysid__indirect__seed3"
    assert (record.train_mse, record.test_mse, record.fit_seconds, record.expression) == (1.5, 2.5, 12.5, "qd_1**2/2")
    assert record.details["mse_before"] == {"train": 3.0, "test": 4.0} and "mse_after" in record.details
    assert not {"system", "method", "seed", "lagrangian", "seconds", "spec"} & set(record.details)
    assert ResidualResult.from_json(json.loads((tmp_path / "loop.json").read_text())) == out
    # among a matrix's records it is not one of the runs its tables count
    assert read_records(tmp_path) == [] and read_records(tmp_path, kind="residual") == [record]


def test_a_result_without_a_spec_gets_one_from_its_own_fields():
    record = result(budget={"kind": "steps", "steps": 40, "ceiling_s": None}, budget_s=None).to_record()
    assert RunSpec.from_dict(record.spec).budget.steps == 40 and record.system == "double_pendulum"


def test_the_loops_json_as_written_before_reads_as_a_record():
    old = {k: v for k, v in dataclass_fields(result()).items() if k not in ("spec", "code")}
    record = ResidualResult.from_json(old).to_record()
    assert record.kind == "residual" and record.test_mse == 2.5 and residual_fields(record)["effects"] == old["effects"]
    with pytest.raises(RecordError, match="old.json: not a record of the residual loop"):
        ResidualResult.from_json({**old, "mse_after": None, "budget": "sixty"}, "old.json")


def test_a_round_written_when_a_term_was_called_a_candidate_reads_under_todays_names():
    rounds = [{"round": 0, "mse": {"train": 3.0}, "heldout_mse": 3.2},
              {"round": 1, "mse": {"train": 2.0}, "heldout_mse": 3.0, "candidate_heldout_mse": 3.1, "stop": "undone",
               "trace": [{"candidate": "viscous_friction[1]", "bic_drop": 40.0, "accepted": True}, "not a step"]}]
    read = ResidualResult.from_json(result(rounds=rounds).to_json()).rounds
    assert read[0] == rounds[0] and read[1]["undone_heldout_mse"] == 3.1 and "candidate_heldout_mse" not in read[1]
    assert read[1]["trace"] == [{"term": "viscous_friction[1]", "bic_drop": 40.0, "accepted": True}, "not a step"]


def test_a_record_of_a_run_is_not_read_as_the_loops(tmp_path):
    record = result().to_record().replace(kind="run")
    with pytest.raises(RecordError, match="not of the residual loop"):
        residual_fields(record)
    write_record(tmp_path / "run.json", record)
    with pytest.raises(RecordError, match=r"^\S*run\.json: a record of a run, not of the residual loop$"):
        residual_fields(read_record(tmp_path / "run.json"), tmp_path / "run.json")
    with pytest.raises(RecordError, match="run.json: a record of a run"):
        ResidualResult.from_json(record.to_json(), str(tmp_path / "run.json"))
    with pytest.raises(RecordError, match="field kind must be one of run, residual"):
        write_record(tmp_path / "x.json", record.replace(kind="study")) or read_record(tmp_path / "x.json")


def dataclass_fields(obj) -> dict:
    import dataclasses

    return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj) if f.name != "models"}
