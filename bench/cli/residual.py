"""``python -m bench residual``: fit, trace the torque residual to missing
effects, add them, refit, and report the error before and after."""

from __future__ import annotations

from pathlib import Path

from bench.cli.options import (add_ignore_limits, add_config, add_device, add_plugin, add_set, add_split, budget, check_names,
                               check_split, configurations, device, hyperparameters, load_plugins, number)
from bench.core.arguments import positive, positive_int, seed
from bench.core.fileio import check_output
from bench.core.budget import DEFAULT_BUDGET_S
from bench.residual.limits import FIT_SHARE, MAX_ROUNDS
from bench.runner.job import KILL_FACTOR


def add_arguments(res) -> None:
    res.add_argument("--system", required=True, help="the system whose declared model the method fits")
    res.add_argument("--method", required=True, help="a method that fits torques (indirect experiment)")
    res.add_argument("--train", type=Path, default=None, help="training CSV (default: a measured system's own split)")
    res.add_argument("--test", type=Path, default=None, help="test CSV (default: a measured system's own split)")
    res.add_argument("--budget", type=positive, default=None,
                     help=f"seconds for the fit and the rounds, where the method has no work of its own "
                          f"(default {DEFAULT_BUDGET_S:g}) or where given without --steps: the method's fit has {FIT_SHARE:.0%}% of "
                          f"it, no round starts that would end past it, a round still running at its end is undone, "
                          f"and the result keeps the rounds before it; the driven rollouts after the rounds are not "
                          f"charged to it. The loop's process is killed only at {KILL_FACTOR} x it (the rounds "
                          f"that finished are kept); bound by work, only a ceiling past which the loop is killed "
                          f"(default: none)")
    res.add_argument("--steps", type=positive_int, default=None,
                     help="bound the loop by work: the method's fit (and each cross-fit) does N steps of its work, "
                          "the polish all its starts, the trace until nothing is significant, and at most "
                          f"{MAX_ROUNDS} rounds; the same command then gives the same effects and numbers on any "
                          "machine. Default: the method's own work (1 for a fit that is one solve, as SysId's and "
                          "sparse regression's; a learner's its fixed steps), unless --budget is given; a method "
                          "without one (MGGP, SyReNets) is bound by --budget's seconds")
    add_split(res)
    res.add_argument("--seed", type=seed, default=0, help="the method's seed (default 0)")
    add_config(res)
    add_set(res)
    res.add_argument("--json", type=Path, default=None, help="write the result here (see the README for its keys)")
    res.add_argument("--report", type=Path, default=None, help="write a markdown report with residual plots here")
    add_ignore_limits(res)
    add_device(res)
    add_plugin(res)


def main(args) -> int:
    for path in (args.json, args.report):
        if path is not None:
            check_output(path)
    (name,), plugins = load_plugins(args, [args.system])  # a bad file: one line, nothing imported
    from bench.residual.job import ResidualJob, run_residual
    from bench.residual.report import summary_lines
    from systems import SYSTEMS

    check_names(args, [name])
    check_split(args.split, [name])
    system = SYSTEMS[name](split=args.split)  # the command's one build of it
    check_names(args, [name], [args.method], built={name: system})
    budget_s, steps = work(args)
    job = ResidualJob.of(
        name, args.method, budget_s=budget_s, steps=steps, seed=args.seed,
        train_path=None if args.train is None else str(args.train), test_path=None if args.test is None else str(args.test),
        profile=configurations(args, [args.method])[args.method],
        hyperparameters=hyperparameters(args.overrides, args.method, [args.method]),
        json_path=None if args.json is None else str(args.json), report_path=None if args.report is None else str(args.report),
        plugins=plugins, split=args.split, device=device(args.device, [args.method]), check_limits=not args.ignore_limits,
        command=args.invocation,
    )
    job.check(system)  # the method, its hyperparameters and the data given: one line, before the note below
    if args.json is None and args.report is None:
        print("note: neither --json nor --report given; the result is only printed")
    result = run_residual(job, checked=True)
    if result.stopped:
        print(f"stopped early: {result.stopped}")
    b, a = result.mse_before, result.mse_after
    print(f"torque MSE before: train {b['train']:.4g}, test {number(b['test'])}; after: train {a['train']:.4g}, test {number(a['test'])}")
    for e in result.effects:
        print("  " + effect_line(e))
    for line in summary_lines(result):
        print("  " + line)
    return 0


def work(args) -> tuple[float | None, int | None]:
    """``(budget_s, steps)``: those given; where neither is, the method's own work (:attr:`methods.base.Method.work`)
    with no ceiling, so that the loop's rounds are not decided by the machine's speed; a method without any gets
    the default seconds."""
    if args.steps is None and args.budget is None:
        from methods import METHODS

        own = METHODS[args.method].work
        if own is not None:
            return None, own
    return budget(args)[0], args.steps


def effect_line(entry: dict) -> str:
    """One effect of the loop's JSON as the console shows it: what, its kind and
    joints, then its parameters with their standard errors, or the finding, or
    its law; never an empty description."""
    what = entry.get("expression") or entry["name"]
    where = f"joint{'s' if len(entry['joints']) > 1 else ''} {'-'.join(map(str, entry['joints']))}"
    params = ", ".join(f"{k} = {p['value']:.6g} ± {p['stderr']:.2g}" for k, p in entry["parameters"].items())
    return f"{what} ({entry['kind']}) on {where}: {params or entry.get('finding') or entry.get('law') or 'no parameters'}"
