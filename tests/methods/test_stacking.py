"""Seeds stacked in one model: each seed's fit is the one it makes alone.

The tolerance is floating-point reduction order: the stacked network's
matrix products are batched (one call for every seed) where a seed alone
makes its own. On a CPU, float64 fits agree to 1e-12 of the prediction's
scale (the MLP's torques to the last bit), float32 fits (DeLaN's default)
to 1e-5; each seed's steps, evaluations and best step are the same."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from bench.core.data import generate
from bench.core.errors import ConfigError
from methods import METHODS
from methods.stacking import fit_stacked
from systems import get_system
from tests.contract import OnMeta
from bench.core.budget import Budget

STACKABLE = [n for n in METHODS.names() if METHODS.entry(n).available and METHODS[n].stackable]
SEEDS = [0, 1, 2]


@pytest.fixture(scope="module")
def data():
    s = get_system("double_pendulum")
    return [generate(s, 256, k) for k in SEEDS], generate(s, 64, 1000)


def test_the_suites_plain_torch_methods_stack():
    assert {"mlp", "delan", "syrenets"} <= set(STACKABLE) and not {"sysid", "sparse"} & set(STACKABLE)


@pytest.mark.parametrize("experiment", ["indirect", "direct"])
@pytest.mark.parametrize("name", STACKABLE)
def test_each_stacked_seed_is_the_fit_it_makes_alone(name, experiment, data):
    train, test = data
    cls, smoke = METHODS[name], METHODS[name].smoke_config()
    alone = [cls(**smoke).fit(d, experiment, k, budget=Budget(steps=smoke["max_steps"])) for d, k in zip(train, SEEDS)]
    stacked = fit_stacked([cls(**smoke) for _ in SEEDS], train, experiment, SEEDS, budget=Budget(steps=smoke["max_steps"]))
    tolerance = 1e-12 if alone[0].config.dtype == "float64" else 1e-5
    for a, b in zip(alone, stacked):
        want, got = a.predict(test), b.predict(test)
        assert np.max(np.abs(got - want)) <= tolerance * np.max(np.abs(want))
        for key in ("steps", "best_step", "evaluations", "stop_reason"):
            assert b.fit_info[key] == a.fit_info[key], key
        np.testing.assert_allclose([m for _, m in b.fit_info["curve"]], [m for _, m in a.fit_info["curve"]],
                                   rtol=tolerance)
        assert b.fit_info["stacked"] == len(SEEDS) and "stacked" not in a.fit_info
    # different seeds' fits stay different: no seed reads another's parameters
    assert not np.allclose(stacked[0].predict(test), stacked[1].predict(test))


@pytest.mark.parametrize("experiment", ["indirect", "direct"])
def test_stacked_syrenets_seeds_keep_their_own_selection_replay_probes_and_multi_start_turns(experiment, data):
    """Each seed's networks take their turns, replay their own worst samples
    and draw their own contractive probes: the stacked fits are the fits alone."""
    train, test = data
    config = {**METHODS["syrenets"].smoke_config(), "starts": 2, "replay": 4, "max_steps": 24, "eval_samples": 64,
              "lr_schedule": "cosine"}
    alone = [METHODS["syrenets"](**config).fit(d, experiment, k, budget=Budget(steps=24)) for d, k in zip(train, SEEDS)]
    stacked = fit_stacked([METHODS["syrenets"](**config) for _ in SEEDS], train, experiment, SEEDS, budget=Budget(steps=24))
    for a, b in zip(alone, stacked):
        want, got = a.predict(test), b.predict(test)
        assert np.max(np.abs(got - want)) <= 1e-12 * np.max(np.abs(want))
        assert b.record_details()["starts"] == a.record_details()["starts"]
        for key in ("steps", "best_step", "evaluations", "stop_reason"):
            assert b.fit_info[key] == a.fit_info[key], key
    assert len({str(f.record_details()["starts"]["rounds"]) for f in stacked}) > 1 or \
        not np.allclose(stacked[0].predict(test), stacked[1].predict(test))


@pytest.mark.long
@pytest.mark.xdist_group("torch.compile")  # with the suite's other compiling tests (tests/methods/test_delan.py)
def test_a_compiled_stacked_step_is_compiled_before_the_budget_and_gives_the_fits_alone(data):
    """With ``compile=True`` the stack's torques are compiled, before the budgets start, and
    each seed's fit is the one it makes alone, to float32's rounding. The fits alone are eager:
    a compiled step alone is the eager one to that rounding (tests/methods/test_delan.py), and
    compiling it here too would double the test's compilation."""
    train, test = data
    config = {**METHODS["delan"].smoke_config(), "max_steps": 8}
    alone = [METHODS["delan"](**config | {"compile": False}).fit(d, "indirect", k, budget=Budget(steps=8))
             for d, k in zip(train, SEEDS)]
    stacked = fit_stacked([METHODS["delan"](**config | {"compile": True}) for _ in SEEDS], train, "indirect", SEEDS,
                          budget=Budget(steps=8))
    for a, b in zip(alone, stacked):
        want, got = a.predict(test), b.predict(test)
        assert np.max(np.abs(got - want)) <= 1e-5 * np.max(np.abs(want))
        assert b.fit_info["prepare_seconds"] > 0 and b.fit_info["steps"] == 8


def test_a_stack_keeps_every_tensor_on_its_device(data):
    train, _ = data
    smoke = METHODS["mlp"].smoke_config()
    methods = [METHODS["mlp"](**smoke).use_device("meta") for _ in SEEDS]
    mode = OnMeta()
    with mode:
        fit_stacked(methods, train, "indirect", SEEDS, budget=Budget(steps=smoke["max_steps"]))
    assert not mode.mixed and mode.on_meta > 0


@pytest.mark.parametrize("name, config", [("mlp", {}), ("syrenets", {"starts": 2})])
def test_when_one_seeds_budget_ends_the_stack_stops_together_and_says_it_shared_the_budget(name, config, data):
    """Under a shared wall-clock budget the first seed whose budget ends stops the stack; here, without a
    clock, the first seed's budget is cut to 6 steps of the others' 20 (its Progress's work limit)."""
    train, _ = data
    methods = [METHODS[name](**{**METHODS[name].smoke_config(), "max_steps": None, **config}) for _ in SEEDS]
    begin = methods[0].begin_fit

    def cut(*args, **kwargs):
        started = begin(*args, **kwargs)
        started.progress.work_limit = 6
        return started

    methods[0].begin_fit = cut
    fits = fit_stacked(methods, train, "indirect", SEEDS, budget=Budget(steps=20))
    assert [f.fit_info["steps"] for f in fits] == [6, 6, 6] and all(f.fit_info["stacked"] == 3 for f in fits)
    assert [f.fit_info["stop_reason"] for f in fits] == ["max_steps"] + ["another seed of the stack used up the "
                                                                         "shared budget"] * 2


def test_what_cannot_stack_is_refused(data):
    train, _ = data
    with pytest.raises(ConfigError, match="stackable"):
        fit_stacked([METHODS["sysid"]() for _ in SEEDS], train, "indirect", SEEDS, budget=Budget(steps=1))
    with pytest.raises(ConfigError, match="compiled pass"):
        fit_stacked([METHODS["syrenets"](compile=True) for _ in SEEDS], train, "indirect", SEEDS, budget=Budget(steps=1))
    with pytest.raises(ConfigError, match="one configuration"):
        fit_stacked([METHODS["mlp"](hidden=8), METHODS["mlp"](hidden=16)], train[:2], "indirect", SEEDS[:2], budget=Budget(steps=1))
    with pytest.raises(ConfigError, match="one dataset and one seed"):
        fit_stacked([METHODS["mlp"]()], train, "indirect", SEEDS, budget=Budget(steps=1))
    assert torch.get_default_dtype() == torch.float32  # nothing above changed torch's defaults


def test_the_stacking_measurement_prints_both_rates_and_their_ratio(tmp_path):
    from tests.commandline import cli

    out = tmp_path / "speed.md"
    r = cli("study", "stacking-speed", "--cases", "mlp:double_pendulum", "--n-seeds", "1", "2", "--steps", "2", "--n-train", "64",
            "--out", out)
    assert r.returncode == 0, r.stderr
    assert "mlp on double_pendulum, 2 seed(s): stacked" in r.stdout and "stacked ÷ one by one" in r.stdout
    assert out.read_text().count("| mlp | double_pendulum |") == 2
    bad = cli("study", "stacking-speed", "--cases", "sysid:double_pendulum", "--n-seeds", "1")
    count = cli("study", "stacking-speed", "--cases", "mlp:double_pendulum:1,x")
    assert count.returncode == 2 and "the numbers of seeds must be positive integers" in count.stderr
    assert count.stderr.count("\n") == 1
    assert bad.returncode == 2 and "sysid is not a stackable method" in bad.stderr and bad.stderr.count("\n") == 1


class _Penalised:
    """A plugin's MLP with a weight penalty in extra_loss, which the stacked loop would not see."""

    def extra_loss(self):
        return 1e-2 * sum((p ** 2).sum() for p in self.model.parameters())


def _plugin(honest: bool):
    base = METHODS["mlp"]
    body = {"extra_loss": _Penalised.extra_loss, "__module__": __name__}
    if not honest:  # says, wrongly, that its loss is still the stacked loop's
        body["stacked_loss_is_batch_loss"] = True
    return type("PenalisedMLP", (base,), body)


def test_a_method_that_overrides_its_loss_hooks_trains_alone_and_says_why():
    cls = _plugin(honest=True)
    reason = cls(**cls.smoke_config()).stacking_unavailable_reason()
    assert reason and "PenalisedMLP.extra_loss" in reason and "stacked loop does not call" in reason
    assert METHODS["delan"](**METHODS["delan"].smoke_config()).stacking_unavailable_reason() is None  # it says so


def test_the_contract_catches_a_stacked_fit_that_is_not_the_fit_alone(data):
    from tests.contract import check_stacked

    train, test = data
    cls = _plugin(honest=False)
    with pytest.raises(AssertionError, match="not the fit it makes alone"):
        check_stacked(cls, cls.smoke_config(), train[0], test, "indirect")


def test_stack_seeds_runs_a_plugin_with_its_own_loss_alone_and_says_why(tmp_path):
    from tests.commandline import cli

    r = cli("run", "--systems", "double_pendulum", "--methods", "penalised_mlp", "--experiments", "indirect",
            "--seeds", "0,1", "--steps", "3", "--n-train", "64", "--n-test", "32", "--no-rollout", "--stack-seeds",
            "--plugin", "tests/plugins/penalised.py", "--out", tmp_path / "m")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "--stack-seeds: penalised_mlp runs each seed alone: penalised_mlp overrides PenalisedMLP.extra_loss" in r.stdout
    records = [__import__("json").loads(p.read_text()) for p in (tmp_path / "m" / "records").glob("*.json")]
    assert len(records) == 2 and all(r["status"] == "ok" and "stacked" not in r["details"] for r in records)
