"""Tables are a pure function of the records; checked on synthetic records."""

from __future__ import annotations

import pytest

from bench.evaluation.scores import MEASURED
from bench.reporting.groups import group_stats
from bench.reporting.tables import (build_table, build_tables, expand_variants, constant_line, standard_line,
                                     write_tables)
from bench.runner.records import Record, record_path, write_record
from bench.runner.spec import RunSpec


def rec(method, seed, train, test, status="ok", experiment="direct", system="double_pendulum", error=None):
    spec = {"system": system, "method": method, "experiment": experiment, "seed": seed, "budget_s": 60.0, "profile": "default"}
    fields = {"error": error}
    if status == "ok":
        fields.update(train_mse=train, test_mse=test)
    return Record.new(RunSpec(**spec), status, **fields)


def test_groups_rank_by_training_mse():
    # train MSE 1..10 for seeds 9..0; test MSE = 2 * train
    records = [rec("a", s, float(10 - s), 2.0 * (10 - s)) for s in range(10)]
    g = group_stats(records)
    assert g["best"]["train"] == (1.0, None) and g["best"]["test"] == (2.0, None)
    assert g["best half"]["train"][0] == pytest.approx(3.0)
    assert g["best half"]["train"][1] == pytest.approx(2**0.5)  # population std of 1..5
    assert g["all"]["test"][0] == pytest.approx(11.0)
    assert g["worse half"]["train"][0] == pytest.approx(8.0)
    assert [line.split(" | ")[0] for line in build_table(records).splitlines() if " | train | " in line] == \
        ["| Best", "| 5 Best", "| All 10", "| 5 Worse"]  # the paper's rows


def test_best_row_uses_the_seed_with_lowest_train_not_test():
    records = [rec("a", 0, 1.0, 50.0), rec("a", 1, 2.0, 3.0)]
    assert group_stats(records)["best"]["test"] == (50.0, None)


def test_fewer_seeds_and_failures():
    records = [rec("a", s, float(s + 1), float(s + 1)) for s in range(3)]
    records += [rec("a", 3, None, None, status="timeout", error="killed"), rec("a", 4, None, None, status="failed", error="boom")]
    g = group_stats(records)
    assert g["best half"]["train"][0] == pytest.approx(2.0)  # ⌈5/2⌉ = 3 of 5 seeds: the three that are ok
    assert g["worse half"]["train"][0] == pytest.approx(2.0)
    table = build_table(records)
    assert "| Runs | | 3/5 ok (1 failed, 1 timeout) |" in table
    assert [line.split(" | ")[0] for line in table.splitlines() if " | train | " in line] == \
        ["| Best", "| 3 Best", "| All 5", "| 3 Worse"]


def test_tables_of_three_seeds_say_so_and_have_no_halves():
    records = [rec("a", s, float(s + 1), float(s + 1)) for s in range(3)]
    table = build_table(records)
    assert [line.split(" | ")[0] for line in table.splitlines() if " | train | " in line] == ["| Best", "| All 3"]
    assert not any(word in table for word in ("All 10", "5 Best", "5 Worse"))


def test_bold_marks_the_lowest_mean_of_each_row():
    records = [rec("a", s, 1.0, 5.0) for s in range(2)] + [rec("b", s, 2.0, 4.0) for s in range(2)]
    table = build_table(records).splitlines()
    best_train = next(line for line in table if line.startswith("| Best | train"))
    best_test = next(line for line in table if line.startswith("|  | test"))
    assert best_train == "| Best | train | **1.00e+00** | 2.00e+00 |"
    assert best_test == "|  | test | 5.00e+00 | **4.00e+00** |"
    # two seeds a method: too few to test, so b is marked untested rather than called different
    assert "| All 2 | train | **1.00e+00 (± 0.00e+00)** | 2.00e+00 (± 0.00e+00) † |" in table


def test_unavailable_and_not_applicable_columns():
    records = [rec("a", 0, 1.0, 1.0), rec("pysr", 0, None, None, status="unavailable", error="no Julia"),
               rec("operon", 0, None, None, status="not_applicable", error="direct only")]
    table = build_table(records)
    assert "| Runs | | 1/1 ok | not applicable (see below) | unavailable (see below) |" in table
    assert "- **operon** is not applicable: direct only" in table and "- **pysr** is unavailable: no Julia" in table
    assert "| Best | train | **1.00e+00** | — | — |" in table


def test_document_has_one_section_per_system_and_experiment_with_header(tmp_path):
    records = [rec("a", 0, 1.0, 1.0), rec("a", 0, 2.0, 2.0, experiment="indirect")]
    text = build_tables(records, page=tmp_path / "tables.md")
    assert text.index("## double_pendulum, direct") < text.index("## double_pendulum, indirect")
    assert "Budget: 60 s of wall-clock per run; 1 seed(s) (0)" in text
    assert "Machine: " in text and "Commit: " in text
    for r in records:
        write_record(record_path(tmp_path, r.run_id), r)
    assert write_tables(tmp_path) == text
    assert (tmp_path / "tables.md").read_text() == text


def test_no_records_is_an_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="no records found"):
        write_tables(tmp_path)


def test_variants_get_columns_of_their_own():
    base = rec("syrenets", 0, 1.0, 2.0)
    base = base.replace(details={"variants": {"refined": {"train_mse": 1e-20, "test_mse": 2e-20, "expression": "x"}}})
    table = build_table(expand_variants([base]))
    assert "| Group | Split | syrenets | syrenets@refined |" in table
    assert "| Best | train | 1.00e+00 | **1.00e-20** |" in table


def test_a_failed_variant_is_counted_as_failed():
    ok = rec("syrenets", 0, 1.0, 2.0)
    ok = ok.replace(details={"variants": {"refined": {"status": "ok", "train_mse": 0.5, "test_mse": 0.6, "expression": "x", "exact": False}}})
    missed = rec("syrenets", 1, 1.5, 2.5)
    missed = missed.replace(details={"variants": {"refined": {"status": "failed", "error": "out of budget"}}})
    table = build_table(expand_variants([ok, missed]))
    assert "| Runs | | 2/2 ok | 1/2 ok (1 failed) |" in table
    assert "| Exact | | — | 0/2 seeds exact |" in table


def test_a_systems_published_reference_is_printed_above_its_table():
    text = build_tables([rec("sysid", 0, 1e-3, 2e-3, experiment="indirect", system="delan_characters")])
    section = text.split("## delan_characters, indirect")[1]
    assert "Reference: DeLaN's README reports a test torque MSE of 0.0004327" in section
    assert "Reference" not in build_tables([rec("sysid", 0, 1.0, 1.0, system="single_pendulum")])
    assert "Reference: Valle & Haddadin (2021)" in build_tables([rec("sysid", 0, 1.0, 1.0)])  # the paper's pendulum


def test_rollout_row_gives_the_median_and_what_became_of_the_rest():
    records = []
    for seed, (status, err) in enumerate([("ok", 0.1), ("ok", 0.3), ("ok", 0.2), ("indefinite", None)]):
        records.append(rec("m", seed, 1.0, 1.0).replace(rollout={"status": status, "q_rmse": err}))
    row = [line for line in build_table(records).splitlines() if line.startswith("| Rollout")]
    assert row == ["| Rollout | q RMSE | 2.00e-01 (3/4; 1 indefinite) |"]
    assert "Rollout" not in build_table([rec("m", 0, 1.0, 1.0)])


def test_a_judgement_stopped_at_its_limit_is_said_in_the_exact_row():
    judged = rec("syrenets", 0, 1.0, 2.0).replace(exact=True)
    late = rec("syrenets", 1, 1.5, 2.5).replace(details={"exact_timed_out": 60.0})
    variant = {"status": "ok", "train_mse": 0.5, "test_mse": 0.6, "expression": "x", "exact": None, "exact_timed_out": 60.0}
    judged = judged.replace(details={"variants": {"refined": variant}})
    table = build_table(expand_variants([judged, late]))
    assert "| Exact | | 1/2 seeds exact (1 not judged: the check ran past 60 s) | " in table
    assert "| 0/1 seeds exact (1 not judged: the check ran past 60 s) |" in table  # one run has the variant


def test_tables_open_with_a_link_to_the_guide_that_resolves_and_matches_the_test_they_run(tmp_path):
    from bench.reporting.significance import ALPHA, MIN_SEEDS
    from bench.reporting.tables import GUIDE

    out = tmp_path / "deep" / "run"
    for seed in range(2):
        r = rec("sysid", seed, 1.0, 1.0)
        write_record(record_path(out, r.run_id), r)
    text = write_tables(out, plots=False)
    target = text.splitlines()[2].split("](")[1].rstrip(").")
    assert (out / target).resolve() == GUIDE.resolve() and GUIDE.is_file()
    guide = GUIDE.read_text()
    assert f"α = {ALPHA:g}" in guide and f"fewer than {MIN_SEEDS} seeds" in guide


def test_measured_tables_give_driven_rollouts_the_standard_model_and_each_learners_ratio_to_it():
    standard = {"configuration": "standard", "train_mse": 0.2, "test_mse": 0.5, "mass_matrix_positive_definite": False,
                "mass_matrix_smallest_eigenvalue": -1.5,
                "rollout": {"kind": "driven", "windows": {"0.25": {"windows": 4, "diverged": 4, "median_q_rmse": None,
                                                                   "q_rmse": [None] * 4}}}}

    def runs(per_seed):
        out = []
        for seed, q_rmse in enumerate(per_seed):
            windows = {"0.25": {"windows": 4, "diverged": q_rmse.count(None), "median_q_rmse": None, "q_rmse": q_rmse}}
            r = rec("m", seed, 1.0, 1.0 + seed, experiment="indirect", system="kuka_lwr4")
            out.append(r.replace(rollout={"kind": "driven", "status": "ok", "q_rmse": None, "windows": windows},
                                 details={"standard_model": standard, "exact_not_judged": MEASURED,
                                          "constant_model": {"tau": [0.1], "train_mse": 0.3, "test_mse": 1.5}}))
        return out

    # the median over all 12 windows, the diverged one infinitely far
    records = runs([[0.1, 0.1, 0.2, 0.3], [0.3, None, 0.4, 0.5], [0.2, 0.2, 0.2, 0.2]])
    lines = build_table(records).splitlines()
    assert "| Driven 0.25 s | q RMSE | 2.00e-01 (1/12 windows diverged) |" in lines
    # half of the windows diverged: the few that survived do not make a figure
    survivors = build_table(runs([[0.01, None, None, None], [None, None, 0.02, None], [0.03, 0.01, None, 0.01]]))
    assert "| Driven 0.25 s | q RMSE | diverged (7/12 windows) |" in survivors.splitlines()
    assert "| All 3 / standard | test | 4× |" in lines  # the mean test MSE 2.0 over the standard model's 0.5
    # above the constant's 1.5: marked, and the constant's line says what the mark means
    assert "|  | test | **2.00e+00 (± 8.16e-01)** ‡ |" in lines
    assert "Constant model (each joint's training-mean torque, predicted everywhere): train MSE 3.00e-01, test MSE " \
           "1.50e+00" in constant_line(records)
    assert "| Exact | | not applicable: measured data have no true L |" in lines
    assert not any(line.startswith("| Rollout") for line in lines)
    text = standard_line(records)
    assert "train MSE 2.00e-01, test MSE 5.00e-01" in text and "driven 0.25 s: q RMSE diverged (4/4 windows)" in text
    assert "not positive definite (smallest eigenvalue -1.5" in text
    assert standard_line([rec("m", 0, 1.0, 1.0)]) == ""


def test_a_variant_out_of_budget_reads_as_a_budget_outcome_with_its_reason():
    from bench.physics.models import NoVariant

    why = NoVariant("no refit finished: 8 terms: out of budget", "timeout")
    assert why.status == "timeout" and str(why) == why.reason
    with pytest.raises(ValueError):
        NoVariant("anything", "ok")
    records = [rec("s", k, 1.0, 1.0).replace(details={"variants": {"refined": {"status": why.status, "error": str(why)}}})
               for k in range(2)]
    table = build_table(expand_variants(records))
    assert "| Runs | | 2/2 ok | 0/2 ok (2 timeout) |" in table
    assert "- **s@refined**, seeds 0, 1: timeout: no refit finished: 8 terms: out of budget" in table
    assert "failed" not in table
