"""Measure the residual loop on simulated data with known undeclared effects.

For each effect type (and clean data), each noise level and each method, the
double pendulum's torques get the effect (:func:`bench.core.effects.add_effects`)
and Gaussian noise on train and test torques (a fraction of each joint's
torque standard deviation); the loop (:func:`bench.residual.residual_loop`)
is run, each case in its own process through the runner, and the table says
whether it named exactly the right effects on the right joints, the worst
relative coefficient error, the test torque MSE before and after, and the
test set's noise floor (the mean square of the noise that was added), so that
"after ÷ floor" near 1 means that all but the noise was explained. Usage::

    python -m bench residual-acceptance [--noise 0 0.01 0.1] [--methods sysid sparse] [--out results/residual/acceptance.md]
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from bench.core.arguments import noise_level, positive, positive_int
from bench.core.data import add_noise, generate
from bench.core.effects import EFFECTS
from bench.core.laws import FAMILIES, Part, group
from bench.core.undeclared import GENERATOR_LAWS, add_effects, parse_effects
from bench.core.fileio import atomic_write, check_output, link
from bench.residual.loop import residual_loop
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
    "clean": [],
}


def expected(effects: dict, dof: int) -> dict[tuple, dict[str, float]]:
    """``{(name, joints from 1): {parameter: value}}`` of the effects added,
    as the loop's JSON names them: the parts on one joint as their laws
    (:func:`bench.core.laws.group`; Coulomb plus viscous friction is one law)."""
    out, on_joint = {}, {}
    for name, placed in effects.items():
        for joints, c in placed.items():
            if name in GENERATOR_LAWS:
                for part in GENERATOR_LAWS[name].parts(*c):
                    if part.coefficient:
                        on_joint.setdefault(joints[0], {})[part.name] = part
            elif len(joints) == 1 and name in FAMILIES:
                if c:
                    on_joint.setdefault(joints[0], {})[name] = Part(name, c)
            elif c:
                where = tuple(j + 1 for j in joints) or tuple(range(1, dof + 1))
                out[(name, where)] = {EFFECTS[name].parameter: c}
    for j, parts in on_joint.items():
        for law, members in group(parts):
            out[(law.name, (j + 1,))] = {k: v for k, (v, _) in law.parameters_of(members).items()}
    return out


def run_case(case: str, noise: float, method: str, n_train: int, n_test: int, budget: float | None,
             steps: int | None = None) -> dict:
    """One case: the loop on the effect ``case`` at ``noise``, with ``method``, within
    ``budget`` seconds or, with ``steps``, that work budget (:func:`bench.residual.residual_loop`)."""
    system = SYSTEMS["double_pendulum"]()
    effects = parse_effects(CASES[case], system.dof)
    train = add_effects(generate(system, n_train, 0), effects, system)
    test = clean_test = add_effects(generate(system, n_test, 1000), effects, system)
    if noise:
        train, test = add_noise(train, "indirect", noise, 0), add_noise(clean_test, "indirect", noise, 1)
    floor = float(np.mean((test.tau - clean_test.tau) ** 2))
    start = time.perf_counter()
    out = residual_loop(method, train, test, budget_s=budget, steps=steps, report=quiet)
    want = expected(effects, system.dof)
    found = {(e["name"], tuple(e["joints"])): {k: p["value"] for k, p in e["parameters"].items()}
             for e in out.effects if e["kind"] != "structural"}
    errors = [abs(found[k][p] - v) / abs(v) for k, params in want.items() if k in found
              for p, v in params.items() if p in found[k] and v]
    return {
        "case": case, "noise": noise, "method": method, "named_right": set(found) == set(want),
        "found": sorted(f"{n} j{'-'.join(map(str, j))}" for n, j in found)
        + sorted(f"structural: {e['name']} j{'-'.join(map(str, e['joints']))}" for e in out.effects if e["kind"] == "structural"),
        "worst_coef_error": max(errors) if errors else None,
        "before": out.mse_before["test"], "after": out.mse_after["test"], "floor": floor,
        "seconds": time.perf_counter() - start, "statistics_seconds": out.statistics_seconds,
    }


def table(rows: list[dict]) -> str:
    lines = [
        "| effect | noise | method | right effects, right joints | found | worst coefficient error | test MSE before "
        "| test MSE after | after ÷ before | noise floor | after ÷ floor | seconds | of which statistics |",
        "|---|---:|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        err = "—" if r["worst_coef_error"] is None else f"{r['worst_coef_error']:.2%}"
        floor = f"{r['floor']:.3g}" if r["floor"] else "0"
        over = f"{r['after'] / r['floor']:.3g}" if r["floor"] else "—"
        lines.append(
            f"| {r['case']} | {r['noise']:g} | {r['method']} | {'yes' if r['named_right'] else '**no**'} "
            f"| {', '.join(r['found']) or 'nothing'} | {err} | {r['before']:.3g} | {r['after']:.3g} "
            f"| {r['after'] / r['before']:.3g} | {floor} | {over} | {r['seconds']:.1f} | {r['statistics_seconds']:.1f} |"
        )
    return "\n".join(lines)


def run_payload(payload: dict, on_phase) -> dict:
    """One case in its own process (see :func:`run_case`)."""
    on_phase("run")
    return run_case(**payload)


#: the subcommand's one-line help
HELP = "measure the residual loop on data with known undeclared effects (results/residual/acceptance.md)"


def add_arguments(parser) -> None:
    parser.add_argument("--noise", type=noise_level, nargs="+", default=[0.0, 0.01, 0.1],
                        help="noise levels, fractions of each joint's torque std (default 0 0.01 0.1)")
    parser.add_argument("--methods", nargs="+", default=["sysid", "sparse"], help="methods the loop fits (default sysid sparse)")
    parser.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES), help="effect cases (default: all)")
    parser.add_argument("--n-train", type=positive_int, default=3000, help="training samples (default 3000)")
    parser.add_argument("--n-test", type=positive_int, default=1500, help="test samples (default 1500)")
    parser.add_argument("--budget", type=positive, default=None,
                        help="seconds for each loop, its fit included (default 30); with --steps, a ceiling past which "
                             "a loop is killed (default: none)")
    parser.add_argument("--steps", type=positive_int, default=None,
                        help="bound each loop by N steps of its method's work instead of by time (--budget is then a "
                             "ceiling): the same command gives the same effects on any machine")
    parser.add_argument("--workers", type=positive_int, default=2, help="cases at a time, one process each (default 2)")
    parser.add_argument("--out", type=Path, default=Path("results/residual/acceptance.md"),
                        help="the table to write (default results/residual/acceptance.md)")


def main(args) -> int:
    check_output(args.out)
    if args.budget is None and args.steps is None:
        args.budget = 30.0
    payloads = {f"{c} noise={z:g} {m}": {"case": c, "noise": z, "method": m, "n_train": args.n_train,
                                          "n_test": args.n_test, "budget": args.budget, "steps": args.steps}
                for c in args.cases for z in args.noise for m in args.methods}

    def describe(r: dict) -> str:
        return f"named right {r['named_right']}, test MSE {r['before']:.3g} -> {r['after']:.3g} (floor {r['floor']:.3g})"

    limit = KILL_FACTOR * args.budget if args.steps is None else (args.budget or math.inf)
    rows = list(run_jobs("bench.experiments.residual_acceptance:run_payload", payloads, limit, args.workers, describe,
                         print_now).values())
    order = {c: i for i, c in enumerate(args.cases)}
    rows.sort(key=lambda r: (order[r["case"]], r["noise"], args.methods.index(r["method"])))
    prov = provenance()
    budget_words = (f"{args.budget:g} s for each loop, its method's fit included" if args.steps is None
                    else f"{args.steps} steps of its method's work for each loop's fit")
    text = "\n".join([
        "# The residual loop on undeclared effects: acceptance figures",
        "",
        f"Generated by `{args.invocation}` (commit {prov.get('commit', '?')[:7]}"
        f"{', dirty tree' if prov.get('dirty') else ''}). Double pendulum, {args.n_train} training and {args.n_test} "
        f"test samples; each effect as `bench data --effects` takes it (the cases, and why the armature is on "
        f"joint 1 only, in "
        f"[bench/experiments/residual_acceptance.py]"
        f"({link(__file__, args.out)})); the worst coefficient error is over every parameter of "
        f"every effect found, and a structural finding is a finding, not an effect; noise on train and test torques as a fraction of each joint's "
        f"torque standard deviation; {budget_words}. The noise floor is the test set's "
        "mean squared noise: at \"after ÷ floor\" ≈ 1 everything but the noise is explained.",
        "",
        table(rows),
        "",
    ])
    atomic_write(args.out, lambda f: f.write(text))
    print(text)
    return 0
