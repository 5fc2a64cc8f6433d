"""A matrix of a hybrid, a method with a variant and a plain method, on two arms:
the hybrid is ranked beside the plain methods (seed ranks and the Friedman test),
the variant is not; the hybrid's hyperparameters are filed under its own name; its
run id parses back to its name, so a hybrid's corrupt record counts as missing."""

from __future__ import annotations

from pathlib import Path

from bench.reporting.leaderboard import rank_summary
from bench.reporting.tables import read_for_tables, write_tables
from bench.runner import matrix
from bench.runner.progress import quiet
from bench.runner.records import Record, record_path
from bench.runner.spec import build_specs, parse_run_id

PLUGIN = str(Path(__file__).resolve().parents[1] / "plugins" / "faulty.py")
HYBRID, VARIANT, PLAIN = "standard+toy_constant", "toy_variant", "toy_constant"


def test_a_hybrid_is_ranked_and_named_by_its_parts_and_a_variant_is_not_ranked(tmp_path):
    todo = build_specs(["panda", "ur5"], [HYBRID, VARIANT, PLAIN], ["indirect"], [0, 1], None, steps=1, n_train=256,
                       n_test=64, plugins=(PLUGIN,), rollout=False, hyperparameters={"eval_samples": 64})
    records = matrix.run_matrix(todo, tmp_path, workers=2, report=quiet)
    assert {r.status for r in records} == {"ok"}, [r.error for r in records if r.status != "ok"]

    tables = write_tables(tmp_path)
    assert f"| {VARIANT}@shifted |" in tables
    ranks = [line for line in tables.splitlines() if line.startswith("Mean rank by test MSE")]
    assert len(ranks) == 2 and all(HYBRID in line and PLAIN in line and "@shifted" not in line for line in ranks)
    assert (f"Hyperparameters set beside each method's own: {HYBRID}: eval_samples=64; {PLAIN}: eval_samples=64; "
            f"{VARIANT}: eval_samples=64.") in tables

    summary = rank_summary(read_for_tables(tmp_path))
    assert "Friedman test over the 3 methods" in summary and f"{HYBRID} " in summary and "@shifted" not in summary

    hybrid = next(r for r in records if r.method == HYBRID and r.system == "panda" and r.seed == 0)
    assert parse_run_id(hybrid.run_id)["method"] == HYBRID and hybrid.name.parts == ("standard", PLAIN)
    path = record_path(tmp_path, hybrid.run_id)
    path.write_text("{ not json")
    again = read_for_tables(tmp_path, report=lambda line: None)
    assert [r.status for r in again if r.run_id == hybrid.run_id] == ["missing"]
    assert Record.missing(hybrid.run_id, "corrupt").method == HYBRID
