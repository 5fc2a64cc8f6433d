"""The suite's one command line: ``python -m bench COMMAND``.

A thin layer over the library: every command calls functions that are also
usable from Python. Bad input ends with a one-line ``error:`` message on
stderr and exit code 2; nothing is half-written. Every option has a help
text (``python -m bench COMMAND --help``).

Commands: ``list``, ``run``, ``table``, ``data``, ``fit``, ``residual``,
``convert``, ``rerun``, ``leaderboard``, and the measurement scripts of
:mod:`bench.experiments`: ``adaptation``, ``residual-acceptance``,
``overhead``, ``dfki-filter``.
"""

from __future__ import annotations

import argparse
import ast
import shlex
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

from bench.core.arguments import noise_level, nonnegative, positive, positive_int, seed
from bench.core.data import Dataset, add_noise, check_experiment, generate, write_csv
from bench.core.effects import EFFECTS
from bench.core.undeclared import GENERATOR_LAWS, add_effects, parse_effects
from bench.core.errors import UserError
from bench.core.fileio import check_output, write_json
from bench.core.recordings import DEFAULT_FILTER, ColumnMap, FilterSpec, preprocess, read_recording
from bench.experiments import (adaptation, dfki_filter, overhead, residual_acceptance, residual_dfki, robot_log, scaling,
                               syrenets_profile, syrenets_speed)
from bench.reporting.leaderboard import write_leaderboard
from bench.reporting.tables import write_tables
from bench.residual.job import ResidualJob, run_residual
from bench.residual.loop import FIT_SHARE, MAX_ROUNDS
from bench.runner import matrix
from bench.runner.execute import given_data, make_system, method_config, preflight
from bench.runner.isolation import CallFailed
from bench.runner.plugins import import_plugins, system_plugins
from bench.runner.records import Record, read_record
from bench.runner.replay import RELATIVE_TOLERANCE, compare, replay_spec
from bench.runner.spec import N_TEST, N_TRAIN, SEEDS, RunSpec, build_specs, seed_count
from methods import METHODS
from systems import SYSTEMS
from systems.dfki_double_pendulum import read_raw

EXIT_USAGE = 2


class UsageError(UserError):
    """A bad command line; reported in one line with exit code 2."""


def _csv_list(text: str) -> list[str]:
    items = [t.strip() for t in text.split(",") if t.strip()]
    if not items:
        raise argparse.ArgumentTypeError("expected a comma-separated list")
    return items


def _seed_list(text: str) -> list[int]:
    out = []
    for part in _csv_list(text):
        lo, dash, hi = part.partition("-")
        if dash and lo:
            first, last = seed(lo), seed(hi)
            if last < first:
                raise argparse.ArgumentTypeError(f"the seed range {part} is empty (write it low-high)")
            out += list(range(first, last + 1))
        else:
            out.append(seed(part))
    if len(set(out)) != len(out):
        raise argparse.ArgumentTypeError(f"a seed is given twice in {text}")
    return out


def _assignment(text: str) -> tuple[str, object]:
    if "=" not in text:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text!r}")
    key, raw = text.split("=", 1)
    try:
        value = ast.literal_eval(raw)
    except (ValueError, SyntaxError):
        value = raw
    return key.strip(), value


class _Parser(argparse.ArgumentParser):
    """Argument errors in one line (``--help`` still shows the usage)."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


_SET_HELP = "hyperparameter override, e.g. hidden=64 (repeatable)"
_STEPS_HELP = ("bound each run by N steps of its method's work (gradient steps, GP generations, solves) instead of by "
               "time: the run is then a pure function of its seed and gives the same numbers on any machine")
#: seconds per run where neither --budget nor --steps is given
DEFAULT_BUDGET_S = 60.0
_PLUGIN_HELP = "a .py file or module that registers extra methods or systems (repeatable)"


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog="python -m bench",
        description="Benchmark suite for learning Lagrangians of physical systems, symbolically and neurally.",
    )
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=_Parser)

    sub.add_parser("list", help="list systems and methods, with availability")

    r = sub.add_parser("run", help="run a matrix of systems x methods x experiments x seeds and write tables")
    r.add_argument("--systems", type=_csv_list, default=["double_pendulum"],
                   help="comma-separated, or 'all'; urdf:PATH for any arm's URDF (default: double_pendulum)")
    r.add_argument("--methods", type=_csv_list, default=None, help="comma-separated (default: all registered)")
    r.add_argument("--experiments", type=_csv_list, default=["direct", "indirect"], help="direct,indirect (default: both)")
    seeds = r.add_mutually_exclusive_group()
    seeds.add_argument("--seeds", type=_seed_list, default=None, help="explicit seeds, e.g. 0,1,2 or 0-9")
    seeds.add_argument("--n-seeds", type=seed_count, default=10, help="the first N of the ten fixed seeds (default 10)")
    r.add_argument("--budget", type=positive, default=None,
                   help="wall-clock seconds per run (default 60); with --steps, a ceiling past which a run is killed "
                        "and recorded as timeout (default: none)")
    r.add_argument("--steps", type=positive_int, default=None, help=_STEPS_HELP)
    r.add_argument("--out", type=Path, required=True, help="output folder: records/, logs/, tables.md")
    r.add_argument("--workers", type=positive_int, default=None, help="runs at a time (default: one per core)")
    r.add_argument("--threads", type=positive_int, default=1, help="torch/BLAS threads per run (default 1)")
    r.add_argument("--smoke", action="store_true", help="use each method's tiny smoke configuration")
    r.add_argument("--set", dest="overrides", type=_assignment, action="append", default=[], metavar="NAME=VALUE",
                   help="hyperparameter override for every method in the run (repeatable)")
    r.add_argument("--n-train", type=positive_int, default=N_TRAIN, help=f"training samples (default {N_TRAIN})")
    r.add_argument("--n-test", type=positive_int, default=N_TEST, help=f"test samples (default {N_TEST})")
    r.add_argument("--domain-half-width", type=positive, default=None,
                   help="sample angles, velocities and accelerations from U(-w, w) (default: the system's own domain, "
                        "pi/2 for the paper; linear coordinates keep their ranges)")
    r.add_argument("--noise", type=noise_level, nargs="+", default=[0.0], metavar="LEVEL",
                   help="Gaussian noise on the training targets as a fraction of their std; several levels "
                        "add a dimension to the matrix, e.g. --noise 0 0.01 0.1 (default 0)")
    r.add_argument("--cluster", default=None, metavar="local|ADDRESS",
                   help="run on Dask distributed: 'local' starts a LocalCluster of --workers processes; "
                        "tcp://host:8786 uses a running scheduler (needs the 'dask' extra)")
    r.add_argument("--no-rollout", action="store_true",
                   help="skip the rollout error of simulated systems (integrating each model's dynamics for 1 s)")
    r.add_argument("--plugin", action="append", default=[], help=_PLUGIN_HELP)
    r.add_argument("--no-resume", action="store_true", help="rerun runs that already have a record")
    r.add_argument("--retry-failed", action="store_true",
                   help="also redo runs whose record says failed or timeout (by default a resume keeps them, and "
                        "redoes only runs whose record was made by other code or another configuration)")

    t = sub.add_parser("table", help="write DIR/tables.md from DIR's records and print it")
    t.add_argument("dir", type=Path, help="a run folder (with records/) or a folder of records")

    d = sub.add_parser("data", help="generate data in the suite's CSV format")
    d.add_argument("--system", required=True, help="a simulated system")
    d.add_argument("--n", type=positive_int, required=True, help="number of samples")
    d.add_argument("--seed", type=seed, required=True, help="the generator's seed (the same seed gives the same data)")
    d.add_argument("--out", type=Path, required=True, help="CSV file to write")
    d.add_argument("--domain-half-width", type=positive, default=None,
                   help="sample angles, velocities and accelerations from U(-w, w) (default: the system's own domain)")
    d.add_argument("--effects", nargs="+", default=[], metavar="NAME=c1,...,cn",
                   help="add effects the system does not declare: one coefficient per joint for "
                        f"{', '.join(n for n, e in EFFECTS.items() if e.arity == 1 and e.shaped is None)} "
                        "(e.g. viscous_friction=0.8,0.5); "
                        f"i-j:c items for {', '.join(n for n, e in EFFECTS.items() if e.arity == 2)} on the "
                        "difference of coordinates i and j (e.g. coupled_spring=1-2:3.0); "
                        + "; ".join(f"j:{','.join(law.parameters)} items for {name}" for name, law in GENERATOR_LAWS.items())
                        + ", ';'-separated (e.g. stribeck_friction=1:1.0,2.0,0.5,0.3); "
                        "one number for a planar chain's tip_payload (its mass) or gravity_tilt (radians)")
    d.add_argument("--noise", type=noise_level, default=0.0,
                   help="Gaussian noise on tau as a fraction of each joint's torque std (default 0)")

    res = sub.add_parser("residual", help="fit, trace the torque residual to missing effects, add them, refit; "
                                          "report the error before and after")
    res.add_argument("--system", required=True, help="the system whose declared model the method fits")
    res.add_argument("--method", required=True, help="a method that fits torques (indirect experiment)")
    res.add_argument("--train", type=Path, default=None, help="training CSV (default: a measured system's own split)")
    res.add_argument("--test", type=Path, default=None, help="test CSV (default: a measured system's own split)")
    res.add_argument("--budget", type=positive, default=None,
                     help=f"seconds for the whole loop (default 60): the method's fit has {FIT_SHARE:.0%}% of it, no "
                          f"round starts that would end past it, and the loop's process is killed at "
                          f"{matrix.KILL_FACTOR} x it; with --steps, only a ceiling past which the loop is killed "
                          f"(default: none)")
    res.add_argument("--steps", type=positive_int, default=None,
                     help="bound the loop by work instead of time: the method's fit (and each cross-fit) does N steps "
                          "of its work, the polish all its starts, the trace until nothing is significant, and at most "
                          f"{MAX_ROUNDS} rounds; the same command then gives the same effects and numbers on any machine")
    res.add_argument("--seed", type=seed, default=0, help="the method's seed (default 0)")
    res.add_argument("--set", dest="overrides", type=_assignment, action="append", default=[], metavar="NAME=VALUE",
                     help=_SET_HELP)
    res.add_argument("--json", type=Path, default=None, help="write the result here (see the README for its keys)")
    res.add_argument("--report", type=Path, default=None, help="write a markdown report with residual plots here")
    res.add_argument("--plugin", action="append", default=[], help=_PLUGIN_HELP)

    cv = sub.add_parser("convert", help="turn a robot's log into the suite's CSV format: resample, low-pass, differentiate")
    layout = cv.add_mutually_exclusive_group(required=True)
    layout.add_argument("--format", choices=["dfki"], help="a DFKI double pendulum recording, in either of the lab's layouts")
    layout.add_argument("--columns", metavar="time=T,q_1=C,qd_1=C,tau_1=C,...",
                        help="any log: which columns hold the time (s) and each joint's q, qd and tau")
    cv.add_argument("raw", type=Path, nargs="+",
                    help="the log(s) (CSV, may be gzipped); each is one recording, named in the output's "
                         "trajectory column by its file name")
    cv.add_argument("--out", type=Path, required=True, help="CSV file to write")
    cv.add_argument("--dt", type=positive, default=DEFAULT_FILTER.dt,
                    help=f"the uniform time step the log is resampled to, s (default {DEFAULT_FILTER.dt:g})")
    cv.add_argument("--cutoff-hz", type=positive, default=DEFAULT_FILTER.cutoff_hz,
                    help=f"the zero-phase Butterworth low-pass's cut-off on q, qd and tau, Hz "
                         f"(default {DEFAULT_FILTER.cutoff_hz:g}, measured for the DFKI robot)")
    cv.add_argument("--order", type=positive_int, default=DEFAULT_FILTER.order,
                    help=f"the low-pass's order (default {DEFAULT_FILTER.order})")
    cv.add_argument("--trim", type=nonnegative, default=DEFAULT_FILTER.trim_s,
                    help=f"seconds cut from each end, the filter's start-up (default {DEFAULT_FILTER.trim_s:g})")
    cv.add_argument("--decimate", type=positive_int, default=DEFAULT_FILTER.decimate,
                    help=f"keep every N-th sample (default {DEFAULT_FILTER.decimate})")

    f = sub.add_parser("fit", help="one run on your own CSV data or on generated data; prints a one-line summary")
    f.add_argument("--system", required=True, help="the data's system")
    f.add_argument("--method", required=True, help="the method to fit")
    f.add_argument("--experiment", required=True, choices=["direct", "indirect"],
                   help="learn from samples of L (direct) or from torques (indirect)")
    f.add_argument("--train", type=Path, default=None, help="training CSV (default: generated)")
    f.add_argument("--test", type=Path, default=None, help="test CSV (default: generated when --train is not given)")
    f.add_argument("--seed", type=seed, default=0, help="the run's seed (default 0)")
    f.add_argument("--budget", type=positive, default=None,
                   help="wall-clock seconds for the fit (default 60); with --steps, a ceiling past which the run is "
                        "killed and recorded as timeout (default: none)")
    f.add_argument("--steps", type=positive_int, default=None, help=_STEPS_HELP)
    f.add_argument("--json", type=Path, default=None, help="write the run's record here")
    f.add_argument("--smoke", action="store_true", help="use the method's tiny smoke configuration")
    f.add_argument("--set", dest="overrides", type=_assignment, action="append", default=[], metavar="NAME=VALUE",
                   help=_SET_HELP)
    f.add_argument("--n-train", type=positive_int, default=N_TRAIN, help=f"generated training samples (default {N_TRAIN})")
    f.add_argument("--n-test", type=positive_int, default=N_TEST, help=f"generated test samples (default {N_TEST})")
    f.add_argument("--domain-half-width", type=positive, default=None,
                   help="sample angles, velocities and accelerations from U(-w, w) (default: the system's own domain)")
    f.add_argument("--plugin", action="append", default=[], help=_PLUGIN_HELP)

    rr = sub.add_parser("rerun", help="replay a recorded run with the work it did and compare its train and test MSE")
    rr.add_argument("record", type=Path, help="a run's record (OUT/records/<run id>.json, or a fit's --json)")
    rr.add_argument("--budget", type=positive, default=None,
                    help="a ceiling in seconds past which the replay is killed (default: none; a slower machine "
                         "takes longer than the recorded budget to do the same work)")
    rr.add_argument("--json", type=Path, default=None, help="write the replay's record here")

    lb = sub.add_parser("leaderboard", help="write the leaderboard from a run folder's records and a commentary")
    lb.add_argument("run_dir", type=Path, help="the run folder (default results/leaderboard)", nargs="?",
                    default=Path("results/leaderboard"))
    lb.add_argument("--commentary", type=Path, default=Path("results/commentary.md"),
                    help="markdown with a '## system, experiment' paragraph per table (default results/commentary.md)")
    lb.add_argument("--out", type=Path, default=Path("results/README.md"), help="the leaderboard (default results/README.md)")

    for name, module in EXPERIMENTS.items():
        e = sub.add_parser(name, help=module.HELP)
        module.add_arguments(e)
    return p


#: the measurement scripts, by subcommand
EXPERIMENTS = {
    "adaptation": adaptation,
    "residual-acceptance": residual_acceptance,
    "residual-dfki": residual_dfki,
    "robot-log": robot_log,
    "overhead": overhead,
    "dfki-filter": dfki_filter,
    "scaling": scaling,
    "syrenets-speed": syrenets_speed,
    "syrenets-profile": syrenets_profile,
}


# -- commands ------------------------------------------------------------------------

def cmd_list(args) -> int:
    print("Systems:")
    for entry in SYSTEMS.entries():
        sys_obj = entry.obj()
        kind = "simulated" if sys_obj.simulated else "measured"
        print(f"  {entry.name:<20} dof={sys_obj.dof}  {kind:<9}  coordinates={','.join(sys_obj.coordinates)}  tags={','.join(sorted(entry.tags))}")
    print("Methods:")
    for entry in METHODS.entries():
        reason = entry.unavailable_reason()
        state = "available" if reason is None else f"unavailable: {reason}"
        exps = ",".join(entry.obj.experiments)
        print(f"  {entry.name:<20} {state}  experiments={exps}  tags={','.join(sorted(entry.tags))}")
    return 0


def _plugin_paths(plugins: list[str]) -> tuple[str, ...]:
    """Plugin files as absolute paths (runs import them in their own processes); module names as given."""
    return tuple(str(Path(p).resolve()) if p.endswith(".py") else p for p in plugins)


def _check_names(systems=(), methods=(), experiments=()) -> None:
    for name in systems:
        SYSTEMS.entry(name)
    for name in methods:
        METHODS.entry(name)
    for name in experiments:
        check_experiment(name)


def _budget(args) -> tuple[float | None, int | None]:
    """``(budget_s, steps)`` from ``--budget`` and ``--steps``: seconds
    (default :data:`DEFAULT_BUDGET_S`), or steps with an optional ceiling."""
    if args.steps is None:
        return (args.budget if args.budget is not None else DEFAULT_BUDGET_S), None
    return args.budget, args.steps


def cmd_run(args) -> int:
    check_output(args.out, folder=True)
    import_plugins(args.plugin)
    methods = args.methods or METHODS.names()
    if args.systems == ["all"]:
        args.systems = SYSTEMS.names()
    args.systems, arms = system_plugins(args.systems)
    _check_names(args.systems, methods, args.experiments)
    seeds = args.seeds if args.seeds is not None else list(SEEDS[: args.n_seeds])
    budget_s, steps = _budget(args)
    specs = build_specs(
        args.systems, methods, args.experiments, seeds, budget_s, noises=args.noise, steps=steps,
        profile="smoke" if args.smoke else "default",
        hyperparameters=dict(args.overrides),
        n_train=args.n_train, n_test=args.n_test,
        domain_half_width=args.domain_half_width,
        plugins=_plugin_paths(args.plugin) + arms,
        threads=args.threads,
        rollout=not args.no_rollout,
    )
    for spec in specs:  # fail fast on a bad override, before any process starts
        if spec.method in METHODS and METHODS.entry(spec.method).available:
            METHODS[spec.method](**method_config(spec))
    matrix.run_matrix(specs, args.out, workers=args.workers, resume=not args.no_resume, cluster=args.cluster,
                      retry_failed=args.retry_failed)
    text = write_tables(args.out)
    print(f"tables written to {args.out / 'tables.md'}")
    print(text)
    return 0


def cmd_table(args) -> int:
    try:
        text = write_tables(args.dir)
    except FileNotFoundError as exc:
        raise UsageError(str(exc)) from None
    print(text)
    return 0


def cmd_data(args) -> int:
    check_output(args.out)
    (args.system,), _ = system_plugins([args.system])
    cls = SYSTEMS[args.system]
    system = cls()
    if not system.simulated:
        raise UsageError(f"{args.system} is measured; its data come with the suite (python -m bench residual --system {args.system} ...)")
    if args.domain_half_width:
        system = cls(domain=system.scaled_domain(args.domain_half_width))
    effects = parse_effects(args.effects, system.dof) if args.effects else {}
    data = generate(system, args.n, args.seed)
    if effects:
        data = add_effects(data, effects, system)
    if args.noise:
        data = add_noise(data, "indirect", args.noise, args.seed)
    write_csv(data, args.out)
    extra = "".join([f", undeclared {', '.join(args.effects)}" if effects else "",
                     f", {args.noise:g} x std noise on tau" if args.noise else ""])
    print(f"wrote {len(data)} samples of {args.system} (seed {args.seed}{extra}) to {args.out}")
    return 0


def cmd_residual(args) -> int:
    for path in (args.json, args.report):
        if path is not None:
            check_output(path)
    import_plugins(args.plugin)
    (args.system,), arms = system_plugins([args.system])
    _check_names([args.system], [args.method], [])
    system = SYSTEMS[args.system]()
    entry = METHODS.entry(args.method)
    if not entry.available:
        raise UsageError(f"method {args.method} is unavailable: {entry.unavailable_reason()}")
    reason = entry.obj.not_applicable_reason("indirect")
    if reason:
        raise UsageError(f"method {args.method} cannot run the loop, which fits torques: {reason}")
    METHODS[args.method](**dict(args.overrides))  # bad hyperparameters: exit 2 now
    if not args.train and system.simulated:
        raise UsageError(f"{args.system} is simulated: give --train (and --test) CSV files, e.g. from python -m bench data")
    if args.json is None and args.report is None:
        print("note: neither --json nor --report given; the result is only printed")
    job = ResidualJob(
        system=args.system, method=args.method,
        train_path=None if args.train is None else str(args.train), test_path=None if args.test is None else str(args.test),
        budget_s=_budget(args)[0], steps=args.steps, seed=args.seed, hyperparameters=dict(args.overrides),
        json_path=None if args.json is None else str(args.json), report_path=None if args.report is None else str(args.report),
        plugins=_plugin_paths(args.plugin) + arms,
    )
    result = run_residual(job)
    b, a = result.mse_before, result.mse_after
    print(f"torque MSE before: train {b['train']:.4g}, test {_maybe(b['test'])}; after: train {a['train']:.4g}, test {_maybe(a['test'])}")
    for e in result.effects:
        what = e.get("expression") or e["name"]
        where = f"joint{'s' if len(e['joints']) > 1 else ''} {'-'.join(map(str, e['joints']))}"
        params = ", ".join(f"{k} = {p['value']:.6g} ± {p['stderr']:.2g}" for k, p in e["parameters"].items())
        print(f"  {what} ({e['kind']}) on {where}: {params}")
    if not result.effects:
        print("  no effect added: nothing significant in the residual")
    return 0


def _maybe(x, spec: str = ".4g") -> str:
    return "n/a" if x is None else format(x, spec)


def cmd_convert(args) -> int:
    check_output(args.out)
    spec = FilterSpec(dt=args.dt, cutoff_hz=args.cutoff_hz, order=args.order, trim_s=args.trim, decimate=args.decimate)
    names = [recording_name(p) for p in args.raw]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise UsageError(f"two logs would be the same recording {repeated[0]!r}: give files with distinct names")
    # one column map for every log, so they share their joints; each is read and checked before anything is written
    columns = ColumnMap.parse(args.columns) if args.columns else None
    system = None if columns else "dfki_double_pendulum"
    parts = [preprocess(read_recording(path, columns) if columns else read_raw(path), spec) for path in args.raw]
    arrays = {k: np.concatenate([p[k] for p in parts]) for k in ("q", "qd", "qdd", "tau")}
    labels = np.concatenate([np.full(len(p["q"]), n) for n, p in zip(names, parts)])
    source = ", ".join(map(str, args.raw))
    write_csv(Dataset(arrays["q"], arrays["qd"], arrays["qdd"], arrays["tau"], None, system, source, recording=labels), args.out)
    print(f"wrote {len(labels)} samples of {arrays['q'].shape[1]} joint(s) from {len(parts)} recording(s) to {args.out} "
          f"({spec.describe()})")
    return 0


def recording_name(path: Path) -> str:
    """A log's recording name: its file name without the .csv and compression suffixes."""
    name = path.name
    for suffix in (".gz", ".bz2", ".xz", ".zip", ".csv"):
        name = name.removesuffix(suffix)
    return name or path.name


def cmd_fit(args) -> int:
    if args.json:
        check_output(args.json)
    import_plugins(args.plugin)
    (args.system,), arms = system_plugins([args.system])
    _check_names([args.system], [args.method], [args.experiment])
    if args.test and not args.train:
        raise UsageError("--test needs --train (generated training data comes with generated test data)")
    spec = RunSpec(
        system=args.system, method=args.method, experiment=args.experiment, seed=args.seed,
        budget_s=_budget(args)[0], steps=args.steps, profile="smoke" if args.smoke else "default",
        hyperparameters=dict(args.overrides), n_train=args.n_train, n_test=args.n_test,
        train_path=str(args.train) if args.train else None, test_path=str(args.test) if args.test else None,
        domain_half_width=args.domain_half_width, plugins=_plugin_paths(args.plugin) + arms,
    )
    if METHODS.entry(args.method).available:
        METHODS[args.method](**method_config(spec))  # bad hyperparameters: exit 2 now
    given = given_data(make_system(spec), spec.train_path, spec.test_path) if preflight(spec) is None else None
    for part in given or ():
        if part is not None:
            part.target(args.experiment)  # bad files: exit 2 now, before the run's process starts
    record, log = run_one(spec)
    if args.json:
        write_json(args.json, record.to_json())
    print(summary_line(record, log))
    return 0 if record.status in ("ok", "unavailable", "not_applicable") else 1


def run_one(spec: RunSpec) -> tuple[Record, Path | None]:
    """One run in its own process (threads pinned, killed like any run of a
    matrix), in a scratch folder; returns its record and, where something
    failed, the log that holds the traceback (the folder is then kept)."""
    work = Path(tempfile.mkdtemp(prefix="bench-fit-"))
    record = matrix.run_isolated(spec, work)
    if record.status in ("failed", "timeout") or record.failed_stages:
        return record, matrix.log_path(work, spec.run_id)
    shutil.rmtree(work, ignore_errors=True)
    return record, None


def summary_line(record: Record, log: Path | None = None) -> str:
    head = f"{record.system} {record.method} {record.experiment} seed={record.seed}: {record.status}"
    where = f"; traceback in {log}" if log else ""
    if record.status != "ok":
        return f"{head} ({record.error}{where})"
    test = record.test_mse
    failed = f" | failed after the fit: {', '.join(record.failed_stages)}{where}" if record.failed_stages else ""
    return (
        f"{head} | train MSE {record.train_mse:.4g} | test MSE {'n/a (no test data)' if test is None else f'{test:.4g}'}"
        f" | {record.steps} steps in {record.fit_seconds:.1f} s ({record.stop_reason}){failed}"
    )


def cmd_rerun(args) -> int:
    if args.json:
        check_output(args.json)
    recorded = read_record(args.record)
    spec = replay_spec(recorded, str(args.record), ceiling_s=args.budget)
    import_plugins(spec.plugins)
    print(f"replaying {recorded.run_id}: {spec.budget.describe()} (recorded under {recorded.describe_budget()}, "
          f"stopped by {recorded.stop_reason})", flush=True)
    replayed, log = run_one(spec)
    if args.json:
        write_json(args.json, replayed.to_json())
    if replayed.status != "ok":
        print(summary_line(replayed, log))
        return 1
    rows = compare(recorded, replayed)
    print(f"{'':10} {'recorded':>24} {'replayed':>24} {'relative difference':>20}")
    for name, a, b, diff in rows:
        print(f"{name:10} {_maybe(a, '.17g'):>24} {_maybe(b, '.17g'):>24} {diff:>20.3g}")
    same = all(diff <= RELATIVE_TOLERANCE for *_, diff in rows)
    print(f"{'the same' if same else 'DIFFERENT'} up to a relative {RELATIVE_TOLERANCE:g} "
          f"({replayed.steps} steps; recorded {recorded.steps})")
    return 0 if same else 1


def cmd_leaderboard(args) -> int:
    check_output(args.out)
    missing = write_leaderboard(args.run_dir, args.commentary, args.out)
    for key in missing:
        print(f"no commentary for the table '{key}' (add '## {key}' to {args.commentary})")
    print(f"wrote {args.out}")
    return 0


COMMANDS = {"list": cmd_list, "run": cmd_run, "table": cmd_table, "data": cmd_data, "fit": cmd_fit,
            "residual": cmd_residual, "convert": cmd_convert, "rerun": cmd_rerun, "leaderboard": cmd_leaderboard,
            **{name: module.main for name, module in EXPERIMENTS.items()}}


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(argv)
    args.invocation = "python -m bench " + shlex.join(argv)
    try:
        return COMMANDS[args.command](args)
    except (UserError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except CallFailed as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted; finished runs keep their records, rerun the same command to resume", file=sys.stderr)
        return 130
