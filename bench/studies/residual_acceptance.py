"""The residual loop's benchmark of undeclared effects: recall, precision and
confusion, per effect and noise level, over several data seeds and methods,
on a development set and on an evaluation set held out from development
(:mod:`bench.studies.acceptance_cases`).

For each case (an effect, a chosen pair of effects, or clean data), each
noise level, each data seed and each method, the double pendulum's torques
get the effects (:func:`bench.physics.undeclared.add_effects`) and Gaussian
noise on train and test torques (a fraction of each joint's torque standard
deviation); the loop (:func:`bench.residual.residual_loop`) runs, each case in
its own process through the runner, under a work budget (the runs finished
are kept as they finish, and the same command resumes from them:
:mod:`bench.runner.ledger`), and its report is scored (:mod:`bench.studies.acceptance_scoring`):

* **recall**: of the laws put in, the share found as the right law on the
  right joints with every parameter within 10 %;
* **precision**: of the laws reported, the share that were put in (a
  structural or other finding is not a law); **precision with parameters**:
  the share that were put in and have every parameter right;
* **confusion**: what each law put in was reported as.

The page gives them per method and noise level over every case, on the
evaluation set beside the development set, then per case and the confusion
per method on the evaluation set, the cases' values and seeds, and which of
the loop's rules were chosen on which data; a JSON file beside it holds every
run. Usage::

    python -m bench study residual-acceptance [--noise 0 0.01 0.05 0.1] [--methods sysid sparse] \\
        [--sets development evaluation] --steps 2000 [--out results/residual/acceptance.md]
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from collections import Counter
from pathlib import Path

import numpy as np

from bench.core.budget import Budget
from bench.core.arguments import noise_level, positive, positive_int, seed_list, add_workers
from bench.core.data import add_noise, generate
from bench.physics.undeclared import add_effects, parse_effects
from bench.core.fileio import atomic_write, check_output, link, write_json
from bench.studies.acceptance_cases import (CASES, DEVELOPMENT, DEVELOPMENT_SEEDS, EVALUATION, EVALUATION_CASES,
                                                EVALUATION_SEEDS, SETS, effects)
from bench.studies.acceptance_scoring import CONSISTENT, GAIN_WITHIN, WITHIN, expected, reported, score
from bench.residual.beyond_data import MIN_GAIN as BEYOND_GAIN
from bench.residual.criteria import AS_WELL, MIN_BIC_DROP, MIN_HELDOUT_CHI2, MIN_HELDOUT_GAIN, MIN_T
from bench.residual.loop import residual_loop
from bench.residual.sensors import Sensor
from bench.runner.job import CaseJob, fit_limit
from bench.runner.schedule import run_jobs
from bench.runner.ledger import Ledger
from bench.runner.progress import print_now, quiet
from bench.runner.provenance import made_at, provenance
from systems import SYSTEMS

def run_case(case: str, noise: float, method: str, n_train: int, n_test: int, budget: float | None,
             steps: int | None = None, seed: int = 0, set: str = DEVELOPMENT) -> dict:
    """One run: the loop on ``case`` of the set ``set`` at ``noise`` with ``method``,
    on the data of ``seed`` (training samples from ``seed``, test samples from
    ``1000 + seed``, the noise from their own streams of them; the effects as
    :func:`~bench.studies.acceptance_cases.effects` gives them), within
    ``budget`` seconds or, with ``steps``, that work budget; scored against
    what was put in."""
    system = SYSTEMS["double_pendulum"]()
    items = effects(set, case, seed)
    put = parse_effects(items, system.dof)
    train = add_effects(generate(system, n_train, seed), put, system)
    test = clean_test = add_effects(generate(system, n_test, 1000 + seed), put, system)
    if noise:
        train, test = add_noise(train, "indirect", noise, seed), add_noise(clean_test, "indirect", noise, 1000 + seed)
    floor = float(np.mean((test.tau - clean_test.tau) ** 2))
    start = time.perf_counter()
    out = residual_loop(method, train, test, budget=Budget(seconds=budget, steps=steps), seed=seed, report=quiet)
    want = expected(put, system.dof, Sensor.exact(train).reference)
    found = reported(out.effects)
    return {
        "set": set, "case": case, "effects": items, "noise": noise, "method": method, "seed": seed,
        **score(want, found, reported(out.effects, "stderr")),
        "found": sorted(f"{n} j{'-'.join(map(str, j))}" for n, j in found),
        "findings": sorted(f"{e['kind']}: {e['name']} j{'-'.join(map(str, e['joints']))}" for e in out.effects
                           if (e["name"], tuple(e["joints"])) not in found),
        "equivalent": [" ≡ ".join([e["kept"], *e["equivalent"]]) for e in out.equivalent_laws or ()],
        "before": out.mse_before["test"], "after": out.mse_after["test"], "floor": floor, "rows": train.tau.size,
        "seconds": time.perf_counter() - start, "statistics_seconds": out.statistics_seconds,
    }


#: a run whose effects are worth less than this chi-squared on its training rows is beyond what the
#: data identify (:func:`worth`): the loop accepts a law only past a BIC drop of 10 and 5 standard errors
IDENTIFIABLE = 100.0


def worth(rows: list[dict]) -> None:
    """Give each run ``worth``: the chi-squared its effects are worth on its training
    rows, ``rows * before_0 / floor``, where ``before_0`` is the least test MSE that
    any method's declared model leaves on the same case, set and seed without noise
    (what the effects leave once a model has absorbed what it can), so that every
    method is judged on the same cases, and ``floor`` the run's noise; ``None``
    without a noise-free run, ``inf`` without noise."""
    clean: dict[tuple, float] = {}
    for r in rows:
        if r["noise"] == 0:
            key = (r.get("set", DEVELOPMENT), r["case"], r["seed"])
            clean[key] = min(clean.get(key, math.inf), r["before"])
    for r in rows:
        before = clean.get((r.get("set", DEVELOPMENT), r["case"], r["seed"]))
        r["worth"] = None if before is None else math.inf if not r["floor"] else r["rows"] * before / r["floor"]


def _error(worst: list[float]) -> str:
    """The median of the runs' worst parameter errors, in words where a whole number (N) differs."""
    if not worst:
        return "—"
    m = float(np.median(worst))
    return f"{m:.1%}" if math.isfinite(m) else "N differs"


def _percent(hits: int, of: int) -> str:
    return "—" if not of else f"{hits / of:.0%} ({hits}/{of})"


def _sum(rows: list[dict], key: str) -> int:
    return sum(r[key] for r in rows)


def _recall(rows: list[dict], key: str = "right") -> str:
    return _percent(_sum(rows, key), _sum(rows, "put_in"))


def _precision(rows: list[dict], key: str = "true_reported") -> str:
    return _percent(_sum(rows, key), _sum(rows, "reported"))


#: the summary's figures: heading, and the figure of a set's runs
FIGURES = (
    ("recall", _recall),
    (f"recall where the effects are worth χ² ≥ {IDENTIFIABLE:g}",
     lambda rows: _recall([r for r in rows if r.get("worth") is not None and r["worth"] >= IDENTIFIABLE])),
    (f"recall, parameters within 10 % or {CONSISTENT:g} standard errors", lambda rows: _recall(rows, "consistent")),
    ("precision", _precision),
    ("precision with parameters right", lambda rows: _precision(rows, "right")),
    ("runs with a spurious law", lambda rows: f"{sum(bool(r['spurious']) for r in rows)} of {len(rows)}"),
    ("runs naming laws equivalent on their data", lambda rows: f"{sum(bool(r.get('equivalent')) for r in rows)} of "
                                                               f"{len(rows)}"),
)


def summary(rows: list[dict], methods: list[str], noises: list[float], sets: list[str]) -> str:
    """Each figure per method and noise level, over every case and seed, a row per set (the evaluation set first)."""
    order = sorted(sets, key=lambda which: which != EVALUATION)
    lines = ["| method | noise | set | " + " | ".join(name for name, _ in FIGURES) + " |",
             "|---|---:|---|" + "---:|" * len(FIGURES)]
    for m in methods:
        for z in noises:
            for which in order:
                mine = [r for r in rows if r["method"] == m and r["noise"] == z and r.get("set", DEVELOPMENT) == which]
                if mine:
                    lines.append(f"| {m} | {z:g} | {which} | " + " | ".join(figure(mine) for _, figure in FIGURES) + " |")
    return "\n".join(lines)


def per_case(rows: list[dict], cases: list[str], methods: list[str], noises: list[float]) -> str:
    """Recall and precision per case, noise level and method, with the median worst parameter error."""
    lines = ["| effect | noise | method | χ² the effects are worth (median) | recall | precision "
             "| precision with parameters right | median worst parameter error | test MSE after ÷ noise floor |",
             "|---|---:|---|---:|---:|---:|---:|---:|---:|"]
    for c in cases:
        for z in noises:
            for m in methods:
                mine = [r for r in rows if r["case"] == c and r["noise"] == z and r["method"] == m]
                if not mine:
                    continue
                worst = [r["worst_error"] for r in mine if r["worst_error"] is not None]
                over = [r["after"] / r["floor"] for r in mine if r["floor"]]
                chi2 = [r["worth"] for r in mine if r.get("worth") is not None]
                chi2 = "—" if not chi2 or c == "clean" else f"{float(np.median(chi2)):.3g}"
                lines.append(f"| {c} | {z:g} | {m} | {chi2} | {_recall(mine)} | {_precision(mine)} "
                             f"| {_precision(mine, 'right')} | {_error(worst)} "
                             f"| {'—' if not over else f'{float(np.median(over)):.3g}'} |")
    return "\n".join(lines)


def confusion(rows: list[dict], cases: list[str], method: str) -> str:
    """What each law put in was reported as, and what was reported that was not
    put in, over every noise level and seed of ``method``."""
    lines = [f"| effect put in | reported as ({method}, every noise level and seed) | reported beside it, not put in |",
             "|---|---|---|"]
    for c in cases:
        mine = [r for r in rows if r["case"] == c and r["method"] == method]
        if not mine:
            continue
        seen, extra = {}, Counter(law for r in mine for law in r["spurious"])
        for r in mine:
            for law, was in r["as"].items():
                seen.setdefault(law, Counter())[was] += 1

        def counts(d):
            return ", ".join(f"{k} ×{v}" for k, v in sorted(d.items(), key=lambda kv: -kv[1]))

        what = "; ".join(f"**{law}**: {counts(was)}" for law, was in seen.items()) or "nothing put in"
        lines.append(f"| {c} | {what} | {counts(extra) or '—'} |")
    return "\n".join(lines)


@dataclass(frozen=True)
class Case(CaseJob):
    """One run in its own process (:func:`run_case`), killed at
    :func:`~bench.runner.job.fit_limit` of its budget."""

    set: str
    case: str
    noise: float
    method: str
    n_train: int
    n_test: int
    budget: float | None
    steps: int | None
    seed: int

    def run_limit(self) -> float:
        return fit_limit(Budget(seconds=self.budget, steps=self.steps))

    def compute(self) -> dict:
        return run_case(**self.payload())


#: the subcommand's one-line help


#: the loop's rules of acceptance, and the data each was chosen on: every one before the evaluation set existed
RULES = (
    (f"a term lowers the BIC by more than {MIN_BIC_DROP:g}",
     "Kass and Raftery's scale of evidence, before any case was run"),
    (f"its coefficient is at least {MIN_T:g} standard errors from zero", "the development set's cases"),
    (f"it lowers the held-out residual by at least {MIN_HELDOUT_GAIN:.0%}",
     "the development set's cases and the DFKI recordings"),
    (f"on independent samples, by {MIN_HELDOUT_CHI2:g} rows' worth of the residual where that is less",
     "the development set's Coulomb-plus-viscous case at 5 % noise, whose viscous part it otherwise missed"),
    (f"an admissible term stands in for a better one with an impossible coefficient where it removes "
     f"{AS_WELL:.0%} as much",
     "the development set's cases"),
    (f"an effect that claims beyond the data, or a law of the sensor or the drive, saves {BEYOND_GAIN:.0%} on a "
     "held-out trajectory", "the measured recordings (the DFKI robot's, the KUKA LWR4+'s) and the development set"),
    (f"on measured trajectories a round lowers the held-out error by {MIN_HELDOUT_GAIN:.0%}",
     "the KUKA LWR4+'s default split, after seeing its test trajectory's error: a choice informed by a test set"),
)


def add_arguments(parser) -> None:
    parser.add_argument("--noise", type=noise_level, nargs="+", default=[0.0, 0.01, 0.05, 0.1],
                        help="noise levels, fractions of each joint's torque std (default 0 0.01 0.05 0.1)")
    parser.add_argument("--sets", nargs="+", default=list(SETS), choices=list(SETS),
                        help=f"the sets of cases: {DEVELOPMENT} (fixed values, data seeds "
                             f"{', '.join(map(str, DEVELOPMENT_SEEDS))}; what tests and rules may use) and "
                             f"{EVALUATION} (values drawn from each case's ranges, data seeds of their own; held out "
                             f"from development) (default both)")
    parser.add_argument("--seeds", type=seed_list, default=list(DEVELOPMENT_SEEDS),
                        help=f"the development set's data seeds, comma-separated or a range a-b (default "
                             f"{','.join(map(str, DEVELOPMENT_SEEDS))})")
    parser.add_argument("--n-evaluation-seeds", type=positive_int, default=len(EVALUATION_SEEDS),
                        help=f"the first N of the evaluation set's {len(EVALUATION_SEEDS)} data seeds (default all)")
    parser.add_argument("--methods", nargs="+", default=["sysid", "sparse"], help="methods the loop fits (default sysid sparse)")
    parser.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES), help="effect cases (default: all)")
    parser.add_argument("--n-train", type=positive_int, default=3000, help="training samples (default 3000)")
    parser.add_argument("--n-test", type=positive_int, default=1500, help="test samples (default 1500)")
    parser.add_argument("--budget", type=positive, default=None,
                        help="seconds for each loop, its fit included (default 30); with --steps, a ceiling past which "
                             "a loop is killed (default: none)")
    parser.add_argument("--steps", type=positive_int, default=None,
                        help="bound each loop by N steps of its method's work instead of by time (--budget is then a "
                             "ceiling): the same command gives the same page on any machine")
    add_workers(parser, "runs")
    parser.add_argument("--out", type=Path, default=Path("results/residual/acceptance.md"),
                        help="the page to write (default results/residual/acceptance.md); every run goes to the "
                             "same name with .json; until the page is written, finished runs are kept in "
                             ".partial.jsonl, and the same command run again resumes from them")


def cases_table(rows: list[dict], cases: list[str], sets: list[str]) -> str:
    """Each case's effects in each set: the development set's values, the evaluation
    set's ranges and the values drawn for each of its seeds."""
    lines = ["| case | " + " | ".join(f"{which}" for which in sets) + " |", "|---|" + "---|" * len(sets)]
    for c in cases:
        cells = []
        for which in sets:
            drawn = {r["seed"]: r["effects"] for r in rows if r["case"] == c and r.get("set") == which}
            values = "; ".join(f"seed {seed}: `{' '.join(e) or 'none'}`" for seed, e in sorted(drawn.items()))
            cells.append(values if which == DEVELOPMENT else f"{EVALUATION_CASES[c].ranges}; {values}")
        lines.append(f"| {c} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(args) -> int:
    check_output(args.out)
    if args.budget is None and args.steps is None:
        args.budget = 30.0
    chosen = {DEVELOPMENT: args.seeds, EVALUATION: EVALUATION_SEEDS[:args.n_evaluation_seeds]}
    jobs = {f"{which} {c} noise={z:g} seed={s} {m}": Case(which, c, z, m, args.n_train, args.n_test, args.budget,
                                                         args.steps, s)
            for which in args.sets for c in args.cases for z in args.noise for s in chosen[which] for m in args.methods}

    def describe(r: dict) -> str:
        return (f"{r['right']}/{r['put_in']} right, {r['reported']} reported "
                f"({', '.join(r['found']) or 'nothing'}); test MSE {r['before']:.3g} -> {r['after']:.3g}")

    ledger = Ledger(args.out)
    rows = list(run_jobs(jobs, args.workers, describe, print_now, ledger, cluster=args.cluster).values())
    order = {c: i for i, c in enumerate(args.cases)}
    rows.sort(key=lambda r: (args.sets.index(r["set"]), order[r["case"]], r["noise"], r["seed"],
                             args.methods.index(r["method"])))
    worth(rows)
    prov = provenance()
    budget_words = (f"{args.budget:g} s for each loop, its method's fit included" if args.steps is None
                    else f"{args.steps} steps of its method's work for each loop's fit")
    runs = args.out.with_suffix(".json")
    main_set = EVALUATION if EVALUATION in args.sets else args.sets[0]
    shown = [r for r in rows if r["set"] == main_set]
    text = "\n".join([
        "# The residual loop on undeclared effects: recall, precision and confusion",
        "",
        f"Generated by `{args.invocation}` ({made_at(prov)}"
        f"); every run is in [{runs.name}]({runs.name}).",
        "",
        f"The double pendulum, {args.n_train} training and {args.n_test} test samples per run; noise on train and test "
        f"torques as a fraction of each joint's torque standard deviation; {budget_words}. The cases are in two sets "
        f"([bench/studies/acceptance_cases.py]({link(Path(__file__).with_name('acceptance_cases.py'), args.out)})):",
        "",
        f"- the **{DEVELOPMENT} set**: each case's effects at fixed values, data seeds "
        f"{', '.join(map(str, chosen[DEVELOPMENT]))} here. The tests and the loop's rules were made with these cases "
        "in view;",
        f"- the **{EVALUATION} set**: the same cases, each effect's values drawn for each data seed "
        f"({', '.join(map(str, chosen[EVALUATION]))} here) from the ranges the case states (the list below). No test "
        "reads it, no rule was chosen on it, and it did not exist when the rules were chosen.",
        "",
        "The figures a reader should take are the evaluation set's; the development set's stand beside them so that "
        "the gap shows.",
        "",
        f"**Recall** is the share of the laws put in that the loop reports as the right law on the right joints "
        f"with every parameter within {WITHIN:.0%} (a gain within {GAIN_WITHIN:.0%}; a periodic torque's N exactly); "
        "**precision** the share of the laws it reports that were put in, on their joints, whatever their parameters; "
        "**precision with parameters right** the share that were put in and have every parameter right as recall "
        "judges it. A finding (structural, beyond the data, not identified) is not a law; a simpler law the one put in "
        "contains (Coulomb friction for Coulomb plus viscous) counts as put in for precision, and recall counts it as "
        "missed. How much the data say about a case's effects is the chi-squared they are worth on the training rows: "
        "the training rows times the least test MSE any method's declared model leaves on the noise-free case, over "
        f"the noise's mean square (`worth` in the script), so that every method is judged on the same cases; the loop "
        f"needs about 25 for one law, and below {IDENTIFIABLE:g} no method can be expected to name it reliably. "
        "Where the data do not pin a parameter to 10 %, no method can be right by that rule: the column \"within "
        f"{CONSISTENT:g} standard errors\" also counts a law found on its joints whose parameters are each within 10 % "
        f"or within {CONSISTENT:g} of the standard errors the loop reports for them (N still exact). How each is "
        "scored: [bench/studies/acceptance_scoring.py](" + link(Path(__file__).with_name("acceptance_scoring.py"), args.out) + "). "
        "Where the loop could not tell laws apart on a run's data it names them as equivalent and keeps one by its rule "
        "(the fewest parameters, then the law declared first: [docs/residual_loop.md]("
        + link(Path(__file__).parents[2] / "docs" / "residual_loop.md", args.out) + "#laws-the-data-cannot-tell-apart)); "
        "the scores count the law it kept, and the last column counts the runs that named equivalents.",
        "",
        "## Over every case",
        "",
        summary(rows, args.methods, args.noise, args.sets),
        "",
        f"## Per case, {main_set} set",
        "",
        "The noise floor is the test set's mean squared noise: at \"after ÷ floor\" ≈ 1 everything but the noise "
        "is explained.",
        "",
        per_case(shown, args.cases, args.methods, args.noise),
        "",
        f"## Confusion: what each law put in was reported as, {main_set} set",
        "",
        *[block for m in args.methods for block in (confusion(shown, args.cases, m), "")],
        "## The cases and their seeds",
        "",
        cases_table(rows, args.cases, args.sets),
        "",
        "## The loop's rules and the data they were chosen on",
        "",
        "Each rule was chosen before the evaluation set existed, with these data in view:",
        "",
        *[f"- {rule}: {data}." for rule, data in RULES],
        "",
    ])
    write_json(runs, rows)
    atomic_write(args.out, lambda f: f.write(text))
    ledger.close()
    print(text)
    return 0
