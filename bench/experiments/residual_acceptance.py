"""The residual loop's benchmark of undeclared effects: recall, precision and
confusion, per effect and noise level, over several data seeds and methods.

For each case (an effect, a chosen pair of effects, or clean data), each
noise level, each data seed and each method, the double pendulum's torques
get the effects (:func:`bench.core.undeclared.add_effects`) and Gaussian
noise on train and test torques (a fraction of each joint's torque standard
deviation); the loop (:func:`bench.residual.residual_loop`) runs, each case in
its own process through the runner, under a work budget, and its report is
scored (:mod:`bench.experiments.acceptance_scoring`):

* **recall**: of the laws put in, the share found as the right law on the
  right joints with every parameter within 10 %;
* **precision**: of the laws reported, the share that were put in (a
  structural or other finding is not a law);
* **confusion**: what each law put in was reported as.

The page gives them per method and noise level over every case, per case,
and the confusion per method; a JSON file beside it holds every run. Usage::

    python -m bench study residual-acceptance [--noise 0 0.01 0.05 0.1] [--seeds 0 1 2] [--methods sysid sparse] \\
        --steps 2000 [--out results/residual/acceptance.md]
"""

from __future__ import annotations

import math
import time
from collections import Counter
from pathlib import Path

import numpy as np

from bench.core.arguments import noise_level, positive, positive_int, seed_list
from bench.core.data import add_noise, generate
from bench.core.undeclared import add_effects, parse_effects
from bench.core.fileio import atomic_write, check_output, link, write_json
from bench.experiments.acceptance_scoring import CONSISTENT, GAIN_WITHIN, WITHIN, expected, reported, score
from bench.residual.loop import residual_loop
from bench.residual.sensors import Sensor
from bench.runner.isolation import run_jobs
from bench.runner.matrix import KILL_FACTOR
from bench.runner.progress import print_now, quiet
from bench.runner.provenance import provenance
from systems import SYSTEMS

#: the undeclared effects, one case each, as ``bench data --effects`` takes them
CASES = {
    "viscous_friction": ["viscous_friction=0.8,0.5"],
    "coulomb_friction": ["coulomb_friction=1.5,0.7"],
    # on one joint: with armatures on both joints the double pendulum's SysId form is not identifiable
    # from torques (six unknowns m1, m2, l1, l2, Ia1, Ia2 map to five coefficients of L)
    "armature": ["armature=0.3,0"],
    "spring": ["spring=2.0,1.0"],
    "offset": ["offset=0.5,-0.3"],
    "elbow_spring": ["coupled_spring=1-2:3.0"],
    "elbow_damper": ["coupled_damper=1-2:0.6"],
    "stribeck": ["stribeck_friction=1:1.0,2.0,0.5,0.3"],
    "coulomb_viscous": ["viscous_friction=0.8,0.5", "coulomb_friction=1.5,0.7"],
    # a low-pass filter's rounding of Coulomb friction, at a velocity well below the data's
    "smooth_coulomb": ["smooth_coulomb=1:1.5,0.02,0;2:0.7,0.02,0"],
    "offset_spring": ["offset_spring=2:2.0,0.3"],
    "tip_payload": ["tip_payload=0.5"],
    "gravity_tilt": ["gravity_tilt=0.05"],
    # a torque sensor that reads 4 % low on joint 2
    "torque_gain": ["torque_gain=1,0.96"],
    # cogging, or a drive's ripple: six periods a revolution of joint 1
    "periodic_torque": ["periodic_torque=1:0.3,6,0.5"],
    # a gear whose Coulomb level grows with its load: 10 % of joint 1's torque
    "load_friction": ["load_friction=0.1,0"],
    # chosen pairs: a sensor's gain and offset on one joint; a gain beside friction; ripple beside a spring;
    # a load-dependent Coulomb level beside a constant one
    "gain_offset": ["torque_gain=1,1.05", "offset=0,0.2"],
    "gain_viscous": ["torque_gain=1,0.96", "viscous_friction=0.8,0.5"],
    "periodic_spring": ["periodic_torque=1:0.3,6,0.5", "spring=0,1.0"],
    "load_coulomb": ["load_friction=0.1,0", "coulomb_friction=0.5,0"],
    "clean": [],
}


def run_case(case: str, noise: float, method: str, n_train: int, n_test: int, budget: float | None,
             steps: int | None = None, seed: int = 0) -> dict:
    """One run: the loop on ``case`` at ``noise`` with ``method``, on the data of
    ``seed`` (training samples from ``seed``, test samples from ``1000 + seed``,
    the noise from their own streams of them), within ``budget`` seconds or,
    with ``steps``, that work budget; scored against what was put in."""
    system = SYSTEMS["double_pendulum"]()
    effects = parse_effects(CASES[case], system.dof)
    train = add_effects(generate(system, n_train, seed), effects, system)
    test = clean_test = add_effects(generate(system, n_test, 1000 + seed), effects, system)
    if noise:
        train, test = add_noise(train, "indirect", noise, seed), add_noise(clean_test, "indirect", noise, 1000 + seed)
    floor = float(np.mean((test.tau - clean_test.tau) ** 2))
    start = time.perf_counter()
    out = residual_loop(method, train, test, budget_s=budget, steps=steps, seed=seed, report=quiet)
    want = expected(effects, system.dof, Sensor.exact(train).reference)
    found = reported(out.effects)
    return {
        "case": case, "noise": noise, "method": method, "seed": seed, **score(want, found, reported(out.effects, "stderr")),
        "found": sorted(f"{n} j{'-'.join(map(str, j))}" for n, j in found),
        "findings": sorted(f"{e['kind']}: {e['name']} j{'-'.join(map(str, e['joints']))}" for e in out.effects
                           if (e["name"], tuple(e["joints"])) not in found),
        "before": out.mse_before["test"], "after": out.mse_after["test"], "floor": floor, "rows": train.tau.size,
        "seconds": time.perf_counter() - start, "statistics_seconds": out.statistics_seconds,
    }


#: a run whose effects are worth less than this chi-squared on its training rows is beyond what the
#: data identify (:func:`worth`): the loop accepts a law only past a BIC drop of 10 and 5 standard errors
IDENTIFIABLE = 100.0


def worth(rows: list[dict]) -> None:
    """Give each run ``worth``: the chi-squared its effects are worth on its training
    rows, ``rows * before_0 / floor``, where ``before_0`` is the test MSE its
    method's declared model leaves on the same case and seed without noise (what
    the effects leave once the model has absorbed what it can) and ``floor`` the
    run's noise; ``None`` without a noise-free run, ``inf`` without noise."""
    clean = {(r["case"], r["seed"], r["method"]): r["before"] for r in rows if r["noise"] == 0}
    for r in rows:
        before = clean.get((r["case"], r["seed"], r["method"]))
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


def _precision(rows: list[dict]) -> str:
    return _percent(_sum(rows, "true_reported"), _sum(rows, "reported"))


def summary(rows: list[dict], methods: list[str], noises: list[float]) -> str:
    """Recall and precision per method and noise level, over every case and seed."""
    lines = [f"| method | noise | recall | recall where the effects are worth χ² ≥ {IDENTIFIABLE:g} "
             f"| recall, parameters within 10 % or {CONSISTENT:g} standard errors | precision "
             f"| runs with a spurious law | runs |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for m in methods:
        for z in noises:
            mine = [r for r in rows if r["method"] == m and r["noise"] == z]
            seen = [r for r in mine if r.get("worth") is not None and r["worth"] >= IDENTIFIABLE]
            lines.append(f"| {m} | {z:g} | {_recall(mine)} | {_recall(seen)} | {_recall(mine, 'consistent')} "
                         f"| {_precision(mine)} "
                         f"| {sum(bool(r['spurious']) for r in mine)} | {len(mine)} |")
    return "\n".join(lines)


def per_case(rows: list[dict], cases: list[str], methods: list[str], noises: list[float]) -> str:
    """Recall and precision per case, noise level and method, with the median worst parameter error."""
    lines = ["| effect | noise | method | χ² the effects are worth (median) | recall | precision "
             "| median worst parameter error | test MSE after ÷ noise floor |",
             "|---|---:|---|---:|---:|---:|---:|---:|"]
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
                lines.append(f"| {c} | {z:g} | {m} | {chi2} | {_recall(mine)} | {_precision(mine)} | {_error(worst)} "
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


def run_payload(payload: dict, on_phase) -> dict:
    """One run in its own process (see :func:`run_case`)."""
    on_phase("run")
    return run_case(**payload)


#: the subcommand's one-line help
HELP = "the residual loop's benchmark of undeclared effects: recall, precision, confusion (results/residual/acceptance.md)"


def add_arguments(parser) -> None:
    parser.add_argument("--noise", type=noise_level, nargs="+", default=[0.0, 0.01, 0.05, 0.1],
                        help="noise levels, fractions of each joint's torque std (default 0 0.01 0.05 0.1)")
    parser.add_argument("--seeds", type=seed_list, default=[0, 1, 2],
                        help="data seeds, comma-separated or a range a-b (default 0,1,2)")
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
    parser.add_argument("--workers", type=positive_int, default=2, help="runs at a time, one process each (default 2)")
    parser.add_argument("--out", type=Path, default=Path("results/residual/acceptance.md"),
                        help="the page to write (default results/residual/acceptance.md); every run goes to the "
                             "same name with .json")


def main(args) -> int:
    check_output(args.out)
    if args.budget is None and args.steps is None:
        args.budget = 30.0
    payloads = {f"{c} noise={z:g} seed={s} {m}": {"case": c, "noise": z, "method": m, "n_train": args.n_train,
                                                  "n_test": args.n_test, "budget": args.budget, "steps": args.steps,
                                                  "seed": s}
                for c in args.cases for z in args.noise for s in args.seeds for m in args.methods}

    def describe(r: dict) -> str:
        return (f"{r['right']}/{r['put_in']} right, {r['reported']} reported "
                f"({', '.join(r['found']) or 'nothing'}); test MSE {r['before']:.3g} -> {r['after']:.3g}")

    limit = KILL_FACTOR * args.budget if args.steps is None else (args.budget or math.inf)
    rows = list(run_jobs("bench.experiments.residual_acceptance:run_payload", payloads, limit, args.workers, describe,
                         print_now).values())
    order = {c: i for i, c in enumerate(args.cases)}
    rows.sort(key=lambda r: (order[r["case"]], r["noise"], r["seed"], args.methods.index(r["method"])))
    worth(rows)
    prov = provenance()
    budget_words = (f"{args.budget:g} s for each loop, its method's fit included" if args.steps is None
                    else f"{args.steps} steps of its method's work for each loop's fit")
    runs = args.out.with_suffix(".json")
    text = "\n".join([
        "# The residual loop on undeclared effects: recall, precision and confusion",
        "",
        f"Generated by `{args.invocation}` (commit {prov.get('commit', '?')[:7]}"
        f"{', dirty tree' if prov.get('dirty') else ''}); every run is in [{runs.name}]({runs.name}).",
        "",
        f"The double pendulum, {args.n_train} training and {args.n_test} test samples per run, data seeds "
        f"{', '.join(map(str, args.seeds))}; each case's effects as `bench data --effects` takes them (the cases in "
        f"[bench/experiments/residual_acceptance.py]({link(__file__, args.out)})); noise on train and test torques "
        f"as a fraction of each joint's torque standard deviation; {budget_words}.",
        "",
        f"**Recall** is the share of the laws put in that the loop reports as the right law on the right joints "
        f"with every parameter within {WITHIN:.0%} (a gain within {GAIN_WITHIN:.0%}; a periodic torque's N exactly); "
        "**precision** the share of the laws it reports that were put in, on their joints; a finding (structural, "
        "beyond the data, not identified) is not a law; a simpler law the one put in contains (Coulomb friction for "
        "Coulomb plus viscous) counts as put in, and recall counts it as missed. How much the data say about a "
        "case's effects is the chi-squared they are worth on the training rows: the training rows times the test "
        "MSE the method's declared model leaves on the noise-free case, over the noise's mean square "
        f"(`worth` in the script); the loop needs about 25 for one law, and below {IDENTIFIABLE:g} no method can be "
        "expected to name it reliably. Where the data do not pin a parameter to 10 %, no method can be right by "
        f"that rule: the column \"within {CONSISTENT:g} standard errors\" also counts a law found on its joints whose "
        f"parameters are each within 10 % or within {CONSISTENT:g} of the standard errors the loop reports for them "
        "(N still exact). How each is scored: "
        "[bench/experiments/acceptance_scoring.py](" + link(Path(__file__).with_name("acceptance_scoring.py"), args.out) + ").",
        "",
        "## Over every case",
        "",
        summary(rows, args.methods, args.noise),
        "",
        "## Per case",
        "",
        "The noise floor is the test set's mean squared noise: at \"after ÷ floor\" ≈ 1 everything but the noise "
        "is explained.",
        "",
        per_case(rows, args.cases, args.methods, args.noise),
        "",
        "## Confusion: what each law put in was reported as",
        "",
        *[block for m in args.methods for block in (confusion(rows, args.cases, m), "")],
    ])
    write_json(runs, rows)
    atomic_write(args.out, lambda f: f.write(text))
    print(text)
    return 0
