"""The typed record: JSON round trip, field-by-field validation, and records
written before a field existed."""

from __future__ import annotations

import json
import re

import pytest

from bench.cli import main
from bench.runner.records import ADDED_LATER, Record, RecordError, read_record, read_records, record_path, write_record
from bench.runner.spec import RunSpec

SPEC = RunSpec(system="double_pendulum", method="mlp", experiment="indirect", seed=3, budget_s=5.0, noise=0.1)


def ok_record() -> Record:
    return Record.new(SPEC, "ok", train_mse=0.5, test_mse=0.7, steps=10, curve=[[0.1, 0.9], [1.0, 0.5]])


def test_a_record_round_trips_through_its_file(tmp_path):
    r = ok_record()
    assert r.run_id == "double_pendulum__mlp__indirect__seed3__noise0.1" and r.target == "tau"
    assert r.spec == SPEC.to_dict() and r.provenance["commit"]
    path = record_path(tmp_path, r.run_id)
    write_record(path, r)
    assert read_record(path) == r
    assert list(json.loads(path.read_text())) == [f for f in Record.__dataclass_fields__]  # the file's key order


def test_records_written_before_a_field_existed_read_with_its_old_value(tmp_path):
    obj = ok_record().to_json()
    for name in ADDED_LATER:
        del obj[name]
    r = Record.from_json(obj)
    assert (r.exact, r.noise, r.rollout) == (None, 0.0, None)


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda o: o.pop("status"), "missing field(s) status"),
        (lambda o: o.update(status="done"), "field status must be one of"),
        (lambda o: o.update(train_mse=None), "field train_mse of an ok run must be a finite number"),
        (lambda o: o.update(seed="3"), "field seed must be an integer"),
        (lambda o: o.update(schema="other/1"), "field schema must be"),
        (lambda o: o.update(curve={}), "field curve must be a JSON array"),
        (lambda o: o.update(colour="red"), "unknown record field(s) colour"),
    ],
)
def test_a_bad_field_is_named_with_its_file(tmp_path, change, message):
    obj = ok_record().to_json()
    change(obj)
    path = tmp_path / "records" / "r.json"
    path.parent.mkdir()
    path.write_text(json.dumps(obj))
    with pytest.raises(RecordError, match=re.escape(message)) as err:
        read_records(tmp_path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("content, message", [("x", "not a JSON file"), ("{}", "not a record (missing field"),
                                              ("[1]", "not a record (a JSON list"),
                                              ('{"status": "ok"}', "not a record (missing field")])
def test_a_broken_record_is_moved_aside_and_counted_as_missing_by_the_table(tmp_path, capsys, content, message):
    good = ok_record()
    write_record(record_path(tmp_path, good.run_id), good)
    broken_id = "double_pendulum__mlp__indirect__seed4__noise0.1"
    (tmp_path / "records" / f"{broken_id}.json").write_text(content)
    assert main(["table", str(tmp_path)]) == 0
    err = capsys.readouterr().err
    assert err.startswith("warning: ") and err.count("\n") == 1 and f"{broken_id}.json" in err and message in err
    assert not (tmp_path / "records" / f"{broken_id}.json").exists()
    (moved,) = (tmp_path / "records" / "corrupt").glob(f"{broken_id}.*.json")
    assert moved.read_text() == content
    table = (tmp_path / "tables.md").read_text()
    assert "| Runs | | 1/2 ok (1 missing) |" in table  # the broken run is missing, never ok
    # once the run is redone, it is no longer missing
    write_record(record_path(tmp_path, broken_id), Record.new(SPEC.__class__(**{**SPEC.to_dict(), "seed": 4,
                                                                               "plugins": ()}), "ok", train_mse=0.4))
    assert main(["table", str(tmp_path)]) == 0
    assert "| Runs | | 2/2 ok |" in (tmp_path / "tables.md").read_text()
