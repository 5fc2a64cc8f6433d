"""Adapting to a change in the system: the error over time after the training
stream switches to the same system plus an undeclared effect.

The paper's abstract says SyReNets "remains flexible enough to adapt to an
unforeseen change in the physical system structure". This experiment makes
that measurable. Protocol, per seed:

1. **Before the switch.** Each learner is fitted for ``--before`` seconds on
   ``--n-train`` torque samples of the system (indirect experiment: torques
   only, as a robot would log them).
2. **The switch.** The training stream becomes ``--n-train`` fresh samples of
   the same system plus the undeclared effect(s) ``--effects`` (default: a
   spring of 5 N m/rad on joint 1, which changes the Lagrangian's structure:
   L gains -5 q1^2 / 2). Nothing tells a learner that the system changed.
3. **After the switch.** The test torque MSE on ``--n-test`` held-out samples
   of the changed system is recorded at the training times ``--checkpoints``
   (seconds of fitting after the switch, the first being 0: the model as it
   was at the switch).

Learners:

* ``sysid`` (fixed structure), ``mlp`` and ``syrenets`` continue their fit on
  the new stream from their state at the switch: the same parameters and
  optimiser state (:meth:`methods.base.Method.fit` with ``warm_start``).
  SyReNets runs without its exact-recovery refinement (``refine=False``,
  ``post_fraction=0``): its frozen equation is what is scored, at every
  checkpoint.
* ``sysid then loop``: SysId's fit, and at the switch the residual loop
  (:func:`bench.residual.residual_loop`) starts from the pre-switch SysId fit
  and runs on the new stream (polish, trace, add, refit, repeat). Its error
  is the pre-switch model's until the loop's round 0 (the polished declared
  model) ends, then each finished round's; its time axis is the loop's own
  wall-clock time.

A checkpoint's time is the fitting time actually spent (each segment of fit
stops a little before its budget); evaluating the test MSE is not counted.
Each learner and seed runs in its own process through the runner
(:mod:`bench.runner.isolation`). Usage::

    python -m bench study adaptation [--seeds 5] [--effects spring=5,0] [--out results/residual/adaptation]
"""

from __future__ import annotations

import json
import statistics
from dataclasses import asdict, dataclass
from pathlib import Path

from bench.core.budget import Budget
from bench.core.arguments import positive, positive_int, add_workers
from bench.core.data import generate, mse
from bench.physics.undeclared import add_effects, parse_effects
from bench.core.errors import ConfigError
from bench.core.fileio import atomic_write, check_output, link, write_json
from bench.reporting.plots import adaptation_plot, step_values
from bench.residual.loop import residual_loop
from bench.runner.job import KILL_FACTOR, CaseJob
from bench.runner.schedule import run_jobs
from bench.runner.progress import Report, quiet
from bench.runner.provenance import machine, made_at, provenance
from bench.runner.spec import TEST_SEED_OFFSET
from methods import METHODS
from systems import SYSTEMS

#: each learner's label: the method fitted before the switch, and whether the residual loop takes over at it
LEARNERS = {"sysid": ("sysid", False), "mlp": ("mlp", False), "syrenets": ("syrenets", False),
            "sysid then loop": ("sysid", True)}
#: hyperparameters on top of each method's defaults
HYPERPARAMETERS = {"syrenets": {"refine": False, "post_fraction": 0.0}}
#: seeds of the switched stream are offset from the ones before it
SWITCH_SEED_OFFSET = 500
#: the residual loop's whole budget
LOOP_BUDGET_S = 120.0


@dataclass(frozen=True)
class Setup:
    system: str = "double_pendulum"
    effects: tuple[str, ...] = ("spring=5,0",)
    before_s: float = 20.0
    checkpoints: tuple[float, ...] = (0.0, 1.0, 2.0, 5.0, 10.0, 20.0, 40.0)
    n_train: int = 4000
    n_test: int = 2000
    #: a work budget for the fit before the switch and for the residual loop, instead of
    #: ``before_s`` and :data:`LOOP_BUDGET_S` (the checkpoints after the switch stay in seconds)
    steps: int | None = None

    def check(self) -> None:
        system = SYSTEMS[self.system]()
        if not system.simulated:
            raise ConfigError(f"--system {self.system}: the experiment needs a simulated system")
        parse_effects(list(self.effects), system.dof)
        c = self.checkpoints
        if not c or c[0] != 0 or any(b <= a for a, b in zip(c, c[1:])):
            raise ConfigError(f"--checkpoints must start at 0 and increase, got {list(c)}")
        if self.before_s <= 0 or self.n_train <= 0 or self.n_test <= 0:
            raise ConfigError("--before, --n-train and --n-test must be positive")


def streams(setup: Setup, seed: int):
    """``(train before, test before, train after, test after)`` for ``seed``."""
    system = SYSTEMS[setup.system]()
    effects = parse_effects(list(setup.effects), system.dof)
    after = seed + SWITCH_SEED_OFFSET
    return (
        generate(system, setup.n_train, seed),
        generate(system, setup.n_test, seed + TEST_SEED_OFFSET),
        add_effects(generate(system, setup.n_train, after), effects),
        add_effects(generate(system, setup.n_test, after + TEST_SEED_OFFSET), effects),
    )


def run_learner(learner: str, setup: Setup, seed: int) -> dict:
    """One learner on one seed: its errors before the switch and its curve after."""
    train_a, test_a, train_b, test_b = streams(setup, seed)
    base, loop = LEARNERS[learner]
    method = METHODS[base](**HYPERPARAMETERS.get(base, {}))
    method.fit(train_a, "indirect", seed, Budget(steps=setup.steps) if setup.steps else Budget(seconds=setup.before_s))

    def error(data):
        return mse(method.predict_torque(data), data.tau)

    out = {"learner": learner, "seed": seed, "before": error(test_a), "fit_before_s": method.fit_info["fit_seconds"]}
    curve = [[0.0, error(test_b)]]
    if loop:
        result = residual_loop(base, train_b, test_b, seed=seed, fitted=method, report=quiet,
                               budget=Budget(steps=setup.steps) if setup.steps else Budget(seconds=LOOP_BUDGET_S))
        curve += [[r["seconds"], r["mse"]["test"]] for r in result.rounds if "seconds" in r]
        out["effects"] = [{"name": e["name"], "joints": e["joints"], "law": e["law"], "parameters": e["parameters"]}
                          for e in result.effects]
    else:
        spent = 0.0
        for t in setup.checkpoints[1:]:
            method.fit(train_b, "indirect", seed, Budget(seconds=max(t - spent, 1e-3)), warm_start=True)
            spent += method.fit_info["fit_seconds"]
            curve.append([spent, error(test_b)])
    out["curve"] = curve
    return out


def at(curve: list, t: float) -> float:
    """The test MSE of a ``[(seconds, mse), ...]`` curve at time ``t``: the last value reached by then."""
    return float(step_values(curve, [t], tolerance=1e-9)[0])


@dataclass(frozen=True)
class LearnerJob(CaseJob):
    """One learner on one seed in its own process (:func:`run_learner`), killed
    at 1.5 x its fitting time plus its loop's budget."""

    learner: str
    setup: Setup
    seed: int

    def payload(self) -> dict:
        return {"learner": self.learner, "setup": asdict(self.setup), "seed": self.seed}

    @classmethod
    def from_payload(cls, obj: dict) -> "LearnerJob":
        setup = obj["setup"]
        return cls(obj["learner"], Setup(**{**setup, "effects": tuple(setup["effects"]),
                                            "checkpoints": tuple(setup["checkpoints"])}), obj["seed"])

    def run_limit(self) -> float:
        return KILL_FACTOR * (self.setup.before_s + self.setup.checkpoints[-1] + LOOP_BUDGET_S)

    def compute(self) -> dict:
        return run_learner(self.learner, self.setup, self.seed)


def run(setup: Setup, seeds: list[int], workers: int, report: Report = print, cluster=None) -> list[dict]:
    """Every learner on every seed, ``workers`` processes at a time, each
    killed at 1.5 x its fitting time plus its loop's budget."""
    jobs = {f"{learner} seed={s}": LearnerJob(learner, setup, s) for s in seeds for learner in LEARNERS}

    def describe(r: dict) -> str:
        return f"before {r['before']:.3g}, at the switch {r['curve'][0][1]:.3g}, last {r['curve'][-1][1]:.3g}"

    results = run_jobs(jobs, workers, describe, report, cluster=cluster)
    return sorted(results.values(), key=lambda r: (list(LEARNERS).index(r["learner"]), r["seed"]))


def table(results: list[dict], setup: Setup) -> str:
    """Median test MSE over seeds per learner: before the switch, at it, at
    each checkpoint after it, and the final one with the time it was reached."""
    cols = list(setup.checkpoints)
    head = ("| learner | before the switch | " + " | ".join(f"t = {t:g} s" for t in cols)
            + " | final | final reached at (s) | final ÷ at the switch |")
    lines = [head, "|---|" + "---:|" * (len(cols) + 4)]
    for learner in LEARNERS:
        rs = [r for r in results if r["learner"] == learner]
        if not rs:
            continue
        before = statistics.median(r["before"] for r in rs)
        values = [statistics.median(at(r["curve"], t) for r in rs) for t in cols]
        final = statistics.median(r["curve"][-1][1] for r in rs)
        reached = statistics.median(r["curve"][-1][0] for r in rs)
        ratio = statistics.median(r["curve"][-1][1] / r["curve"][0][1] for r in rs)
        lines.append(f"| {learner} | {before:.3g} | " + " | ".join(f"{v:.3g}" for v in values)
                     + f" | {final:.3g} | {reached:.1f} | {ratio:.3g} |")
    return "\n".join(lines)


def effects_found(results: list[dict]) -> str:
    rs = [r for r in results if "effects" in r]
    if not rs:
        return ""
    lines = ["| seed | effects the loop added (coefficient ± std. error) | loop time (s) |", "|---:|---|---:|"]
    for r in rs:
        text = ", ".join(f"{e['name']} on joint{'s' if len(e['joints']) > 1 else ''} {'-'.join(map(str, e['joints']))}: "
                         + ", ".join(f"{k} = {p['value']:.4g} ± {p['stderr']:.2g}" for k, p in e["parameters"].items())
                         for e in r["effects"]) or "none"
        lines.append(f"| {r['seed']} | {text} | {r['curve'][-1][0]:.1f} |")
    return "\n".join(lines)


def write(results: list[dict], setup: Setup, seeds: list[int], out: Path, command: str) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    plot = adaptation_plot(results, setup.checkpoints, out / "adaptation.png",
                           title=f"{setup.system} + undeclared {' '.join(setup.effects)}: test MSE after the switch")
    prov = provenance()
    text = "\n".join([
        "# Adapting to a change in the system",
        "",
        f"Generated by `{command}` ({made_at(prov)}, "
        f"{machine(prov)}). Protocol: [bench/studies/adaptation.py]({link(__file__, out / 'README.md')}).",
        "",
        f"System `{setup.system}`; before the switch each learner fits {setup.before_s:g} s on {setup.n_train} torque "
        f"samples of it; then the stream becomes {setup.n_train} samples of the same system plus the undeclared "
        f"`{' '.join(setup.effects)}`. Test torque MSE on {setup.n_test} held-out samples of the changed system "
        f"(before the switch: of the original system), median over {len(seeds)} seeds, at t seconds of fitting after "
        "the switch. Learners fit on one core each.",
        "",
        table(results, setup),
        "",
        effects_found(results),
        "",
        f"![test MSE after the switch]({plot.name})",
        "",
    ])
    write_json(out / "adaptation.json", {"setup": asdict(setup), "seeds": seeds, "results": results, "provenance": prov})
    atomic_write(out / "README.md", lambda f: f.write(text))
    return out / "README.md"


#: the subcommand's one-line help


def add_arguments(parser) -> None:
    parser.add_argument("--system", default=Setup.system, help=f"a simulated system (default {Setup.system})")
    parser.add_argument("--effects", nargs="+", default=list(Setup.effects), metavar="NAME=c1,...",
                        help="the undeclared effect(s) after the switch, one coefficient per joint (default: spring=5,0)")
    parser.add_argument("--n-seeds", type=positive_int, default=5, help="seeds 0..N-1 (default 5)")
    parser.add_argument("--before", type=positive, default=Setup.before_s, help="seconds of fitting before the switch (default 20)")
    parser.add_argument("--checkpoints", type=positive, nargs="+", default=list(Setup.checkpoints),
                        help="seconds of fitting after the switch at which the test MSE is measured, from 0")
    parser.add_argument("--n-train", type=positive_int, default=Setup.n_train, help=f"training samples per stream (default {Setup.n_train})")
    parser.add_argument("--n-test", type=positive_int, default=Setup.n_test, help=f"test samples (default {Setup.n_test})")
    add_workers(parser, "jobs")
    parser.add_argument("--out", type=Path, default=Path("results/residual/adaptation"), help="output folder (default results/residual/adaptation)")


def main(args) -> int:
    check_output(args.out, folder=True)
    setup = Setup(args.system, tuple(args.effects), args.before, tuple(args.checkpoints), args.n_train, args.n_test)
    setup.check()
    seeds = list(range(args.n_seeds))
    results = run(setup, seeds, args.workers, cluster=args.cluster)
    path = write(results, setup, seeds, args.out, args.invocation)
    print(json.dumps({"table": str(path)}))
    print((args.out / "README.md").read_text())
    return 0
