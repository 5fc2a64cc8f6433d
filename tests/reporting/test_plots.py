"""Plots: the best-so-far step function, convergence figures next to the
tables, residual-versus-state figures."""

from __future__ import annotations

import numpy as np

from bench.core.data import generate
from bench.reporting.plots import best_so_far, convergence_plot, residual_plot
from bench.runner.records import Record, record_path, write_record
from bench.reporting.tables import write_tables
from systems import get_system
from bench.runner.spec import RunSpec

PNG = b"\x89PNG\r\n\x1a\n"


def test_best_so_far_is_a_step_function_of_the_running_minimum():
    curve = [(1.0, 5.0), (2.0, 7.0), (4.0, 1.0)]
    grid = np.array([0.5, 1.0, 1.5, 2.5, 4.0, 9.0])
    np.testing.assert_array_equal(best_so_far(curve, grid), [np.nan, 5.0, 5.0, 5.0, 1.0, 1.0])


def record(method, seed, curve, status="ok"):
    spec = {"system": "double_pendulum", "method": method, "experiment": "direct", "seed": seed, "budget_s": 10.0}
    fields = {"train_mse": curve[-1][1], "test_mse": 1.0, "curve": curve} if status == "ok" else {"error": "x"}
    return Record.new(RunSpec(**spec), status, **fields)


def test_tables_embed_a_convergence_plot_per_section(tmp_path):
    for seed in range(3):
        curve = [(0.1 * (k + 1), 10.0 / (k + 1 + seed)) for k in range(50)]
        for method in ("a", "b"):
            r = record(method, seed, curve)
            write_record(record_path(tmp_path, r.run_id), r)
    text = write_tables(tmp_path)
    image = tmp_path / "convergence_double_pendulum_direct.png"
    assert image.read_bytes()[:8] == PNG and image.stat().st_size > 10000
    assert "![convergence: double_pendulum, direct](convergence_double_pendulum_direct.png)" in text


def test_no_curves_no_plot(tmp_path):
    assert convergence_plot([record("a", 0, [(1.0, 1.0)], status="failed")], tmp_path / "x.png", "t") is None
    assert not (tmp_path / "x.png").exists()


def test_residual_plot_is_written(tmp_path):
    data = generate(get_system("double_pendulum"), 500, 0, cache=False)
    path = residual_plot(data, data.tau * 0.1, tmp_path / "r.png", title="residual", after=data.tau * 0.01)
    assert path.read_bytes()[:8] == PNG
