"""Warm starts and the adaptation-to-change experiment (bench.studies.adaptation)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from bench.cli import main
from bench.core.data import generate, mse
from bench.physics.undeclared import add_effects
from bench.core.errors import ConfigError
from bench.studies import adaptation
from methods import METHODS
from systems import SYSTEMS
from bench.core.budget import Budget


def test_warm_start_continues_parameters_and_optimiser_state():
    system = SYSTEMS["double_pendulum"]()
    a, b = generate(system, 256, seed=0), add_effects(generate(system, 256, seed=1), {"spring": (5.0, 0.0)})
    m = METHODS["mlp"](max_steps=30, hidden=16, layers=2, lr=3e-2)
    m.fit(a, "indirect", 0, Budget(seconds=10.0))
    steps = m._optimizer.state_dict()["state"][0]["step"].item()
    error_at_switch = mse(m.predict_torque(b), b.tau)
    m.fit(b, "indirect", 0, Budget(seconds=10.0), warm_start=True)
    assert m._optimizer.state_dict()["state"][0]["step"].item() == steps + 30  # the same Adam, further on
    # the continued fit's first evaluation (on all of b) is the pre-switch model's error
    assert m.fit_info["curve"][0][1] == pytest.approx(error_at_switch, rel=1e-9)
    cold = METHODS["mlp"](max_steps=30, hidden=16, layers=2, lr=3e-2).fit(b, "indirect", 0, Budget(seconds=10.0))
    assert cold.fit_info["curve"][0][1] != pytest.approx(error_at_switch, rel=1e-3)


def test_warm_start_is_refused_where_it_cannot_continue():
    data = generate(SYSTEMS["double_pendulum"](), 128, seed=0)
    with pytest.raises(ConfigError, match="cannot continue"):
        METHODS["sparse"]().fit(data, "indirect", 0, Budget(seconds=5.0), warm_start=True)
    with pytest.raises(ConfigError, match="needs an earlier fit"):
        METHODS["mlp"](max_steps=1).fit(data, "indirect", 0, Budget(seconds=5.0), warm_start=True)
    m = METHODS["mlp"](max_steps=1).fit(data, "indirect", 0, Budget(seconds=5.0))
    with pytest.raises(ConfigError, match="continues a indirect fit"):
        m.fit(data, "direct", 0, Budget(seconds=5.0), warm_start=True)


def test_step_function_of_a_curve():
    curve = [[0.0, 10.0], [2.5, 1.0], [7.0, 0.1]]
    assert [adaptation.at(curve, t) for t in (0, 1, 2.5, 5, 100)] == [10.0, 10.0, 1.0, 1.0, 0.1]


def test_setup_errors_name_the_option():
    with pytest.raises(ConfigError, match="--checkpoints"):
        adaptation.Setup(checkpoints=(1.0, 2.0)).check()
    with pytest.raises(ConfigError, match="simulated"):
        adaptation.Setup(system="dfki_double_pendulum").check()
    with pytest.raises(ConfigError, match="unknown effect"):
        adaptation.Setup(effects=("stiction=1,1",)).check()


SMALL = adaptation.Setup(before_s=1.0, checkpoints=(0.0, 0.5, 1.0), n_train=400, n_test=200)


def test_continued_learner_records_a_curve_at_its_checkpoints():
    r = adaptation.run_learner("mlp", SMALL, seed=0)
    t = [p[0] for p in r["curve"]]
    assert len(t) == 3 and t[0] == 0 and 0 < t[1] < t[2]
    assert all(np.isfinite(p[1]) for p in r["curve"]) and r["before"] > 0


@pytest.mark.slow  # it times the machine
def test_a_continued_learner_reaches_each_checkpoint_within_a_fifth_of_a_second():
    t = [p[0] for p in adaptation.run_learner("mlp", SMALL, seed=0)["curve"]]
    assert t[1] <= 0.5 + 0.2 and t[2] <= 1.0 + 0.2


def test_residual_driven_sysid_names_the_new_spring_and_reaches_round_off():
    r = adaptation.run_learner("sysid then loop", dataclasses.replace(SMALL, steps=300), seed=0)
    (effect,) = r["effects"]
    assert effect["name"] == "spring" and effect["joints"] == [1]
    assert effect["parameters"]["k"]["value"] == pytest.approx(5.0, rel=0.05)
    assert r["curve"][-1][1] <= 1e-6 * r["curve"][0][1]
    assert all(b[0] >= a[0] for a, b in zip(r["curve"], r["curve"][1:]))


def test_outputs_table_plot_and_json(tmp_path):
    setup = adaptation.Setup(checkpoints=(0.0, 1.0))
    results = [
        {"learner": "mlp", "seed": s, "before": 1.0, "curve": [[0.0, 4.0], [0.9, 2.0 + s]]} for s in range(2)
    ] + [{"learner": "sysid then loop", "seed": 0, "before": 1.0, "curve": [[0.0, 4.0], [3.0, 1e-20]],
          "effects": [{"name": "spring", "joints": [1], "law": "L += -k*q_1**2/2", "parameters": {"k": {"value": 5.0, "stderr": 1e-9}}}]}]
    path = adaptation.write(results, setup, [0, 1], tmp_path, "python -m bench study adaptation")
    text = path.read_text()
    assert "| mlp | 1 | 4 | 2.5 | 2.5 | 0.9 | 0.625 |" in text  # medians over the two seeds
    assert "| sysid then loop | 1 | 4 | 4 | 1e-20 | 3.0 | 2.5e-21 |" in text  # the loop ends after the last checkpoint
    assert "spring on joint 1: k = 5 ± 1e-09" in text
    assert (tmp_path / "adaptation.png").stat().st_size > 10000
    assert (tmp_path / "adaptation.json").exists()


def test_command_refuses_a_bad_setup_in_one_line_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "adaptation"
    assert main(["study", "adaptation", "--checkpoints", "1", "2", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: --checkpoints must start at 0") and "\n" not in err
    assert not out.exists()
