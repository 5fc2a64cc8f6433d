"""The GPU figures' command runs its whole path on the CPU at toy sizes, from
prepared Panda samples as a bare machine would, and its dry run lists what
would travel with sizes under the limit."""

from __future__ import annotations

import json

import numpy as np

from bench.studies import gpu_figures
from tests.commandline import cli


def test_the_gpu_figures_run_on_the_cpu_from_prepared_samples_and_write_their_page(tmp_path, monkeypatch):
    data, out = tmp_path / "data", tmp_path / "out"
    r = cli("study", "gpu", "--prepare", data)
    assert r.returncode == 0, r.stderr
    with np.load(data / gpu_figures.PANDA_FILE) as f:
        assert f["q"].shape == (gpu_figures.FULL.n_train, 7)
    # as on a bare machine: the arms' engine is missing, so the Panda's samples come from the prepared file
    monkeypatch.setattr("systems.WITHOUT_ARMS", "no Pinocchio here")
    r = cli("study", "gpu", "--device", "cpu", "--tiny", "--data", data, "--out", out)
    assert r.returncode == 0, r.stderr
    result = json.loads((out / "gpu_figures.json").read_text())
    assert result["versions"]["torch"] and result["versions"]["device_type"] == "cpu"
    syrenets = result["syrenets"]
    assert [row["seeds"] for row in syrenets["stacked"]] == list(gpu_figures.TINY.syrenets_seeds)
    assert all(row["steps_per_s"] > 0 and row["x_public"] > 0 for row in syrenets["stacked"])
    for method in ("mlp", "delan"):
        part = result["panda"][method]
        assert part["cpu_core"]["seed_steps_per_s"] > 0
        assert [row["seeds"] for row in part["stacked"]] == list(gpu_figures.TINY.panda_seeds)
    table = result["table"]
    assert table["steps"] == table["steps_wanted"] == gpu_figures.TINY.table_steps and table["probe_steps_per_s"] > 0
    assert all(np.isfinite(table["test_mse"])) and table["published"]["steps"] > 10000
    profiled = result["profile"]
    assert profiled["steps"] == gpu_figures.TINY.profile_steps and profiled["kernels_per_step"] == 0  # no device here
    assert 0 < profiled["operators_cpu_share"] <= 1 and profiled["operators"][0]["calls_per_step"] > 0
    text = (out / "gpu_figures.md").read_text()
    assert "× public code" in text and "× one core" in text and "published, one core each" in text
    assert "| operators, by CPU self time |" in text


def test_without_prepared_samples_or_pinocchio_the_command_says_so_in_one_line(tmp_path, monkeypatch):
    monkeypatch.setattr("systems.WITHOUT_ARMS", "no Pinocchio here")
    r = cli("study", "gpu", "--device", "cpu", "--tiny", "--parts", "panda", "--data", tmp_path, "--out", tmp_path / "o")
    assert r.returncode != 0 and "no Pinocchio here" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_the_dry_run_lists_what_travels_with_sizes_under_the_limit(tmp_path):
    gpu_figures.prepare(tmp_path, 64)
    r = cli("study", "gpu", "--dry-run", "--data", tmp_path, "--wheels", tmp_path / "wheels")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "working tree" in r.stdout and gpu_figures.PANDA_FILE in r.stdout and "MiB  in all" in r.stdout
    assert "to fetch:" in r.stdout and "deap==" in r.stdout  # no wheels there yet: the line that fetches them
    total = float(next(line for line in r.stdout.splitlines() if "in all" in line).split()[0])
    assert 0 < total <= gpu_figures.CARRY_LIMIT_MIB


def test_a_part_that_fails_is_named_on_the_page_and_the_others_still_run(tmp_path, monkeypatch):
    def broken(*args):
        raise RuntimeError("no C++ compiler here\nsecond line")

    monkeypatch.setattr(gpu_figures, "table_part", broken)
    r = cli("study", "gpu", "--device", "cpu", "--tiny", "--parts", "table", "syrenets", "--out", tmp_path)
    assert r.returncode == 1
    text = (tmp_path / "gpu_figures.md").read_text()
    assert "Failed here: table: RuntimeError: no C++ compiler here." in text and "× public code" in text
    assert json.loads((tmp_path / "gpu_figures.json").read_text())["table"] == {"error": "RuntimeError: no C++ compiler here"}
