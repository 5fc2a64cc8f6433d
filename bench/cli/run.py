"""``python -m bench run``: a matrix of systems x methods x experiments x
noise levels x seeds, each run isolated and budgeted, then its tables."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

from bench.cli.parser import UsageError
from bench.cli.options import (add_budget, add_ignore_limits, add_config, add_tune, add_device, add_plugin, add_set, add_split, budget,
    check_names, check_split, configurations, device, hyperparameters, load_plugins, resampled)
from bench.core.arguments import add_workers, csv_list, noise_level, positive, positive_int, seed_list
from bench.core.fileio import check_output
from bench.runner.spec import N_TEST, N_TRAIN, SEEDS, build_specs, seed_count


def add_arguments(r) -> None:
    r.add_argument("--systems", type=csv_list, default=["double_pendulum"],
                   help="comma-separated, or 'all'; urdf:PATH for any arm's URDF, measured:PATH for a measured arm's "
                        "file (default: double_pendulum)")
    r.add_argument("--methods", type=csv_list, default=None, help="comma-separated (default: every registered method; one that applies to none of "
                        "the systems is recorded as not applicable, with one line saying why, where one named here "
                        "is refused)")
    r.add_argument("--experiments", type=csv_list, default=["direct", "indirect"], help="direct,indirect (default: both)")
    seeds = r.add_mutually_exclusive_group()
    seeds.add_argument("--seeds", type=seed_list, default=None, help="explicit seeds, e.g. 0,1,2 or 0-9")
    seeds.add_argument("--n-seeds", type=seed_count, default=10, help="the first N of the ten fixed seeds (default 10)")
    add_budget(r, "per run")
    add_split(r)
    r.add_argument("--out", type=Path, required=True, help="output folder: records/, logs/, tables.md")
    add_workers(r, "runs", None)
    r.add_argument("--threads", type=positive_int, default=1, help="torch/BLAS threads per run (default 1)")
    add_device(r)
    r.add_argument("--stack-seeds", action="store_true",
                   help="train the seeds of each SyReNets, MLP or DeLaN run (or a plain TorchLagrangianMethod "
                        "plugin's) as one stacked model in one process: each seed's record is what its fit alone "
                        "gives, to rounding; fast on a GPU (--device cuda), no faster on a CPU; SysId and SyReNets' "
                        "compiled configuration train alone")
    add_tune(r)
    add_config(r, "each method in the run that offers it")
    add_set(r, "every method in the run")
    r.add_argument("--n-train", type=positive_int, default=N_TRAIN, help=f"training samples (default {N_TRAIN})")
    r.add_argument("--n-test", type=positive_int, default=N_TEST, help=f"test samples (default {N_TEST})")
    r.add_argument("--domain-half-width", type=positive, default=None,
                   help="sample angles, velocities and accelerations from U(-w, w) (default: the system's own domain, "
                        "pi/2 for the paper; linear coordinates keep their ranges)")
    r.add_argument("--noise", type=noise_level, nargs="+", default=[0.0], metavar="LEVEL",
                   help="Gaussian noise on the training targets as a fraction of their std; several levels "
                        "add a dimension to the matrix, e.g. --noise 0 0.01 0.1 (default 0)")
    r.add_argument("--no-rollout", action="store_true",
                   help="skip the rollout error of simulated systems (integrating each model's dynamics for 1 s)")
    add_ignore_limits(r, "run on a measured system whose recordings' positions")
    add_plugin(r)
    r.add_argument("--no-resume", action="store_true", help="rerun runs that already have a record")
    r.add_argument("--retry-failed", action="store_true",
                   help="also redo runs whose record says failed or timeout (by default a resume keeps them, and "
                        "redoes only runs whose record was made by other code or another configuration)")


def main(args) -> int:
    check_output(args.out, folder=True)
    systems, plugins = load_plugins(args, _all_systems() if args.systems == ["all"] else args.systems,
                                    args.methods or [])  # a bad file: one line, nothing imported
    from bench.reporting.tables import write_tables
    from bench.runner import matrix
    from bench.runner.run import given_data, log_path, make_system, method_config, raised
    from methods import METHODS

    methods = args.methods or METHODS.names()
    skipped = check_names(args, systems, methods, args.experiments, named=args.methods is not None)
    for reason in dict.fromkeys(skipped.values()):  # every registered method: one line each that cannot apply
        print(f"not applicable, recorded as such: {reason}")
    check_split(args.split, systems)
    seeds = args.seeds if args.seeds is not None else list(SEEDS[: args.n_seeds])
    budget_s, steps = budget(args)
    chosen = configurations(args, methods)
    where = device(args.device, methods)
    specs = build_specs(
        systems, methods, args.experiments, seeds, budget_s, noises=args.noise, steps=steps,
        n_train=args.n_train, n_test=args.n_test,
        domain_half_width=args.domain_half_width,
        plugins=plugins,
        threads=args.threads,
        rollout=not args.no_rollout,
        split=args.split,
        device=where,
        tune=args.tune,
    )
    specs = [dataclasses.replace(s, profile=chosen[s.method],
                                 hyperparameters=hyperparameters(args.overrides, s.method, methods)) for s in specs]
    for spec in specs:  # fail fast on a bad override, before any process starts
        if spec.method in METHODS and METHODS.entry(spec.method).available:
            METHODS[spec.method](**method_config(spec))
    for spec in {(s.system, s.split): s for s in specs}.values():  # a measured arm's log in degrees, say: one
        given = given_data(make_system(spec), None, None, check_limits=not args.ignore_limits)  # line, before any run
        for line in resampled(given):
            print(f"{spec.system}: {line}")
    if args.stack_seeds and args.tune:
        raise UsageError("--stack-seeds trains the seeds as one model; --tune searches each seed's hyperparameters "
                         "on its own: give one of them")
    if args.stack_seeds and args.cluster:
        raise UsageError("--stack-seeds runs the stacked seeds on the local pool; with --cluster each run is a task of its own")
    records = matrix.run_matrix(specs, args.out, workers=args.workers, resume=not args.no_resume,
                                cluster=args.cluster, retry_failed=args.retry_failed, stack=args.stack_seeds)
    text = write_tables(args.out)
    print(f"tables written to {args.out / 'tables.md'}")
    print(text)
    errors = [r for r in records if raised(r)]
    for r in errors:  # what a script or CI must see: the runs whose code raised, one line each
        print(f"error: {r.system} {r.method} {r.experiment} seed={r.seed}: {r.error_line or 'no message'} "
              f"(log: {log_path(args.out, r.run_id)})", file=sys.stderr)
    return 1 if errors else 0


def _all_systems() -> list[str]:
    """``--systems all``: every registered system (the registry imports them all)."""
    from systems import SYSTEMS

    return SYSTEMS.names()
