"""The published leaderboard: tables, plots and a commentary in one document."""

from __future__ import annotations

from pathlib import Path

from bench.reporting.leaderboard import build, read_commentary
from bench.runner.records import Record, record_path, write_record
from bench.runner.spec import RunSpec


def write(run_dir, system, experiment, method, seed):
    spec = {"system": system, "method": method, "experiment": experiment, "seed": seed, "budget_s": 5.0}
    r = Record.new(RunSpec(**spec), "ok", train_mse=1.0 + seed, test_mse=2.0 + seed, curve=[[0.1, 9.0], [1.0, 1.0 + seed]])
    write_record(record_path(run_dir, r.run_id), r)


def test_commentary_goes_under_its_table_and_missing_ones_are_named(tmp_path):
    run_dir = tmp_path / "results" / "lb"
    for seed in range(3):
        write(run_dir, "double_pendulum", "direct", "mlp", seed)
        write(run_dir, "single_pendulum", "indirect", "mlp", seed)
    notes = tmp_path / "commentary.md"
    notes.write_text("## Introduction\nRead me first.\n\n## double_pendulum, direct\nThe MLP learns.\n\n## More runs\nBye.\n")
    text, missing = build(run_dir, read_commentary(notes), tmp_path / "results" / "README.md")
    assert text.startswith("# Leaderboard\n\nRead me first.")
    section = text.split("## double_pendulum, direct experiment")[1].split("## single_pendulum")[0]
    assert "The MLP learns." in section and "| Group | Split | mlp |" in section
    assert "![convergence: double_pendulum, direct](lb/convergence_double_pendulum_direct.png)" in section
    assert (run_dir / "convergence_double_pendulum_direct.png").is_file()
    assert missing == ["single_pendulum, indirect"]
    assert text.rstrip().endswith("## More runs\n\nBye.")


def test_the_methods_mean_ranks_across_sections_follow_the_tables(tmp_path):
    run_dir = tmp_path / "results" / "lb"
    for system in ("double_pendulum", "single_pendulum", "cart_pole"):
        for offset, method in enumerate(("sparse", "mlp", "mggp")):  # sparse lowest everywhere, mggp highest
            for seed in range(5):
                spec = {"system": system, "method": method, "experiment": "indirect", "seed": seed, "budget_s": 5.0}
                r = Record.new(RunSpec(**spec), "ok", train_mse=1.0, test_mse=10.0 ** offset + seed)
                write_record(record_path(run_dir, r.run_id), r)
    notes = tmp_path / "commentary.md"
    notes.write_text("## Introduction\nHi.\n\n## More runs\nBye.\n")
    text, _ = build(run_dir, read_commentary(notes), tmp_path / "results" / "README.md")
    summary = text.split("## Ranks across systems")[1].split("## More runs")[0]
    assert "Each of the 3 sections" in summary and "sparse 1.00, mlp 2.00, mggp 3.00" in summary
    assert "χ² = 6.00, p = 0.05; at α = 0.05 the methods' ranks differ" in summary  # p = exp(-3) = 0.0498


def test_a_users_leaderboard_is_the_users_own_and_lies_in_their_folder(tmp_path):
    from tests.commandline import cli

    run_dir = tmp_path / "my_runs"
    for seed in range(3):
        write(run_dir, "double_pendulum", "direct", "mlp", seed)
    project_page = Path(__file__).parents[2] / "results" / "README.md"
    before = project_page.read_bytes()
    r = cli("leaderboard", run_dir)
    assert r.returncode == 0, r.stderr
    text = (run_dir / "leaderboard.md").read_text()
    assert "| Group | Split | mlp |" in text and "| All 3 | train |" in text
    commentary = (Path(__file__).parents[2] / "results" / "commentary.md").read_text()
    paragraphs = [p.strip() for p in commentary.split("\n\n") if len(p.strip()) > 40 and not p.startswith("#")]
    assert paragraphs and not any(p in text for p in paragraphs)  # nothing of the project's commentary
    assert "no commentary" not in r.stdout and project_page.read_bytes() == before
    r = cli("index", run_dir)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "python -m bench table" in r.stderr
