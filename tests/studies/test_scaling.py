"""The scaling study: its systems, and its table from records."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from bench.studies import scaling
from bench.runner.plugins import import_plugins
from bench.runner.records import Record
from systems import SYSTEMS
from bench.runner.spec import RunSpec

ROOT = Path(__file__).resolve().parents[2]


def record(method, system, seed, status="ok", steps=10, fit=2.0, mse=1.0, memory=(300.0, 350.0)):
    spec = {"system": system, "method": method, "experiment": "indirect", "seed": seed, "budget_s": 5.0}
    fields = {"steps": steps, "fit_seconds": fit, "train_mse": mse, "test_mse": mse,
              "details": {"memory": {"start_mb": memory[0], "peak_mb": memory[1]}}} if status == "ok" else {"error": "too big"}
    return Record.new(RunSpec(**spec), status, **fields)


def test_the_pendulums_are_registered_only_by_the_plugin():
    code = "import bench.cli; from systems import SYSTEMS; print('pendulum_7link' in SYSTEMS)"
    listed = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT).stdout.strip()
    assert listed == "False"  # the command line and `bench list` do not show the study's pendulums
    import_plugins([scaling.PLUGIN])
    assert [SYSTEMS[n]().dof for n in scaling.studied_systems()] == [1, 2, 3, 4, 5, 6, 7, 6, 7]


def test_the_table_gives_medians_over_the_ok_seeds_and_why_others_did_not_run():
    import_plugins([scaling.PLUGIN])
    records = [record("mlp", "pendulum_2link", s, steps=10 * (s + 1), fit=2.0, mse=float(s + 1)) for s in range(3)]
    records += [record("sparse", "panda", s, status="not_applicable") for s in range(2)]
    rows = scaling.summarize(records)
    (mlp,) = [r for r in rows if r["method"] == "mlp"]
    assert mlp["dof"] == 2 and mlp["ok"] == 3 and mlp["steps"] == 20 and mlp["test_mse"] == 2.0
    assert mlp["step_s"] == 0.1 and mlp["memory_mb"] == 50.0
    text = scaling.table(rows)
    assert "| mlp | indirect | pendulum_2link | 2 | 3/3 | 0.1 | 20 | 50 | 2 |" in text
    assert "| sparse | indirect | panda | 7 | 0/2 | — | — | — | not_applicable: too big |" in text


def test_a_reason_keeps_its_status_and_first_clause():
    why = "not_applicable: Operon fits y = f(X) to samples of y; the indirect experiment has no samples of L"
    assert scaling.reason(why) == "not_applicable: Operon fits y = f(X) to samples of y"
    long = "timeout: " + "word " * 60
    cut = scaling.reason(long, limit=40)
    assert cut.startswith("timeout: word") and cut.endswith(" …") and len(cut) <= 42
    assert scaling.reason("failed: a | b") == "failed: a \\| b"  # a pipe would split the table's cell


def test_growth_divides_the_largest_pendulum_by_the_smallest():
    import_plugins([scaling.PLUGIN])
    records = [record("mlp", f"pendulum_{n}link", 0, steps=10, fit=float(n), memory=(0.0, 100.0 * n)) for n in (1, 4)]
    records += [record("sparse", "pendulum_1link", 0), record("sparse", "pendulum_2link", 0, status="timeout")]
    text = scaling.growth(scaling.summarize(records))
    assert "| mlp | indirect | 1–4 DoF | 4× | 4× |" in text
    assert "sparse" not in text  # one pendulum ran: nothing to divide


def test_a_study_of_one_method_keeps_the_others_rows_at_its_budget_and_seeds(tmp_path):
    from bench.runner.records import record_path, write_record

    import_plugins([scaling.PLUGIN])
    earlier = [record("mlp", "panda", s) for s in range(3)] + [record("mlp", "double_pendulum", 0)]
    other_budget = Record.new(RunSpec("ur5", "mggp", "indirect", 0, 60.0),
                              "failed", error="x")
    for r in earlier + [other_budget]:
        write_record(record_path(tmp_path, r.run_id), r)
    (tmp_path / "records" / "broken.json").write_text("{")
    new = [record("delan", "panda", 0), record("mlp", "panda", 0, mse=0.5)]  # mlp seed 0 redone
    merged = scaling.with_earlier(new, tmp_path, 5.0, (0, 1))
    assert sorted((r.method, r.system, r.seed, r.test_mse) for r in merged) == [
        ("delan", "panda", 0, 1.0), ("mlp", "panda", 0, 0.5), ("mlp", "panda", 1, 1.0)]
