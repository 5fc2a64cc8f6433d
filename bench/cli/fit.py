"""``python -m bench fit``: one run, isolated like a matrix's, on the user's
CSV data or on generated data, summarised in one line."""

from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path

from bench.cli.parser import UsageError
from bench.cli.options import (add_ignore_limits, add_budget, add_config, add_tune, add_device, add_plugin, add_set, add_split, budget,
    check_names, check_split, configurations, device, hyperparameters, load_plugins, resampled)
from bench.core.arguments import positive, positive_int, seed
from bench.core.fileio import atomic_write, check_output
from bench.evaluation.per_joint import per_joint_lines
from bench.runner.records import Record, record_path
from bench.runner.spec import N_TEST, N_TRAIN, RunSpec


def add_arguments(f) -> None:
    f.add_argument("--system", required=True, help="the data's system")
    f.add_argument("--method", required=True, help="the method to fit")
    f.add_argument("--experiment", required=True, choices=["direct", "indirect"],
                   help="learn from samples of L (direct) or from torques (indirect)")
    f.add_argument("--train", type=Path, default=None, help="training CSV (default: generated)")
    f.add_argument("--test", type=Path, default=None, help="test CSV (default: generated when --train is not given)")
    f.add_argument("--seed", type=seed, default=0, help="the run's seed (default 0)")
    add_budget(f, "for the fit")
    add_split(f)
    f.add_argument("--json", type=Path, default=None, help="write the run's record here")
    f.add_argument("--save", type=Path, default=None, metavar="FILE",
                   help="write the fitted model to FILE, a model file that python -m bench predict reads (numbers "
                        "and expressions only, no code); it is checked to give the fitted model's torques back first")
    add_tune(f, "the run")
    add_config(f)
    add_set(f)
    f.add_argument("--n-train", type=positive_int, default=N_TRAIN, help=f"generated training samples (default {N_TRAIN})")
    f.add_argument("--n-test", type=positive_int, default=N_TEST, help=f"generated test samples (default {N_TEST})")
    f.add_argument("--domain-half-width", type=positive, default=None,
                   help="sample angles, velocities and accelerations from U(-w, w) (default: the system's own domain)")
    add_ignore_limits(f)
    add_device(f)
    add_plugin(f)


def main(args) -> int:
    for path in (args.json, args.save):
        if path:
            check_output(path)
    (name,), plugins = load_plugins(args, [args.system], [args.method])  # a bad file: one line, nothing imported
    from bench.runner.run import given_data, make_system, method_config, preflight
    from methods import METHODS

    check_names(args, [name], [args.method], [args.experiment])
    check_split(args.split, [name])
    if args.test and not args.train:
        raise UsageError("--test needs --train (generated training data comes with generated test data)")
    spec = RunSpec(
        system=name, method=args.method, experiment=args.experiment, seed=args.seed,
        budget_s=budget(args)[0], steps=args.steps, profile=configurations(args, [args.method])[args.method],
        hyperparameters=hyperparameters(args.overrides, args.method, [args.method]),
        n_train=args.n_train, n_test=args.n_test,
        train_path=str(args.train) if args.train else None, test_path=str(args.test) if args.test else None,
        domain_half_width=args.domain_half_width, plugins=plugins, split=args.split,
        device=device(args.device, [args.method]),
        tune=args.tune, save=str(args.save.resolve()) if args.save else None,
    )
    if METHODS.entry(args.method).available:
        METHODS[args.method](**method_config(spec))  # bad hyperparameters: exit 2 now
    system = make_system(spec)  # once in this process; the run's own process builds its own
    runs = preflight(spec, system) is None  # else its record says why not (the run's job writes it)
    given = given_data(system, spec.train_path, spec.test_path, check_limits=not args.ignore_limits) \
        if runs else None
    for part in given or ():
        if part is not None:
            part.check_target(args.experiment)  # bad files: exit 2 now, before the run's process starts
    for line in resampled(given):
        print(line)
    if runs:
        print(starting_line(spec), flush=True)
    record, log = run_in_scratch(spec, checked=runs, data=given, copy_to=args.json)
    print(summary_line(record, log))
    for line in variant_lines(record) + per_joint_summary(record):
        print(line)
    if args.save and record.status == "ok":
        if "save" in record.failed_stages:
            print(f"error: {args.save}: not written: {record.failed_stages['save'].splitlines()[0]}", file=sys.stderr)
            return 1
        print(f"model written to {args.save}")
    return 0 if record.status in ("ok", "unavailable", "not_applicable") else 1


def run_in_scratch(spec: RunSpec, checked: bool = False, data: tuple | None = None,
                   copy_to: Path | None = None) -> tuple[Record, Path | None]:
    """One run in its own process (threads pinned, killed like any run of a
    matrix), in a scratch folder; returns its record and, where something
    failed, the log that holds the traceback (the folder is then kept).
    ``checked``: the caller made the run job's checks, which are not repeated;
    ``data``: the ``(train, test)`` pair the caller read, handed to the run's
    process so that it does not read the files again; ``copy_to``: where the
    record's file, as the run wrote it, is copied (``--json``)."""
    from bench.runner import run

    work = Path(tempfile.mkdtemp(prefix="bench-fit-"))
    record = run.run_one(spec, work, checked=checked, data=data)
    if copy_to is not None:
        content = record_path(work, spec.run_id).read_bytes()
        atomic_write(copy_to, lambda f: f.write(content), binary=True)
    if record.status in ("failed", "timeout") or record.failed_stages:
        return record, run.log_path(work, spec.run_id)
    shutil.rmtree(work, ignore_errors=True)
    return record, None


def starting_line(spec: RunSpec) -> str:
    """What the run is about to do and for how long, printed before its process starts: the summary comes
    when it ends."""
    tuned = ", its hyperparameters searched first" if spec.tune else ""
    return (f"{spec.system} {spec.method} {spec.experiment} seed={spec.seed}: fitting within {spec.budget.describe()}"
            f"{tuned}, then scoring")


def variant_lines(record: Record) -> list[str]:
    """One line per variant the method derived from its fit (:meth:`methods.base.Method.variants`: SyReNets'
    pruned and refined equations), scored on the same data, and whether its equation is the system's true
    Lagrangian where that is judged (``exact``); or why it has no score."""
    lines = []
    for name, entry in ((record.details or {}).get("variants") or {}).items() if record.status == "ok" else ():
        head = f"  {record.method}@{name}: "
        if entry.get("status") != "ok":
            lines.append(head + f"{entry.get('status')} ({entry.get('error') or 'no reason given'})")
            continue
        test = entry.get("test_mse")
        exact = {True: " | the true Lagrangian recovered", False: " | not the true Lagrangian"}.get(entry.get("exact"), "")
        lines.append(head + f"train MSE {entry['train_mse']:.4g} | test MSE "
                     + ("n/a (no test data)" if test is None else f"{test:.4g}") + exact)
    return lines


def per_joint_summary(record: Record) -> list[str]:
    """One line per test trajectory of a run on a measured system: each joint's
    nMSE against the logged torque (else the scored one), with the filter's noise floor."""
    entry = (record.details or {}).get("per_joint") if record.status == "ok" else None
    return [f"  {line}" for line in per_joint_lines(entry)] if entry else []


def summary_line(record: Record, log: Path | None = None) -> str:
    head = f"{record.system} {record.method} {record.experiment} seed={record.seed}: {record.status}"
    where = f"; traceback in {log}" if log else ""
    if record.status != "ok":
        return f"{head} ({record.error}{where})"
    test = record.test_mse
    failed = f" | failed after the fit: {', '.join(record.failed_stages)}{where}" if record.failed_stages else ""
    tuning = (record.details or {}).get("tuning")
    if tuning:
        chosen = ", ".join(f"{k}={v!r}" for k, v in sorted(tuning.get("chosen", {}).items())) or "its defaults"
        searched = f" after a search of {tuning['search_seconds']:.1f} s" if "search_seconds" in tuning else ""
        failed = f" | tuned: chose {chosen}{searched}" + failed
    return (
        f"{head} | train MSE {record.train_mse:.4g} | test MSE {'n/a (no test data)' if test is None else f'{test:.4g}'}"
        f" | {record.steps} steps in {record.fit_seconds:.1f} s ({record.stop_reason}){failed}"
    )
