"""How every method's cost and error grow with the degrees of freedom.

The n-link rod pendulum for n = 1 … 7 (``systems.n_link_pendulum``) and the
two arms (the UR5, 6 joints; the Panda, 7), each method, both experiments,
at one budget per run and 5 seeds, through the harness like any matrix. For
each (method, experiment, system) the table gives the median over seeds of:

* the time per training step (or generation): the fit's time over its steps;
* the steps done in the budget;
* the peak memory the run took above what its process started with;
* the test MSE (``L`` directly, ``tau`` indirectly);

and a log–log plot draws time per step and test MSE against the degrees of
freedom. A method that cannot run at some size is in the table with its
status and reason. Usage::

    python -m bench scaling [--budget 5] [--seeds 5] [--out results/scaling]

The pendulums are registered as ``pendulum_<n>link`` by the plugin
:mod:`bench.experiments.scaling_systems`, which the study and its runs'
processes import, so that the rest of the suite does not list them.
"""

from __future__ import annotations

import statistics
from collections import defaultdict
from pathlib import Path

from bench.core.fileio import atomic_write, check_output
from bench.reporting.plots import line_plot
from bench.runner.matrix import run_matrix
from bench.runner.plugins import import_plugins
from bench.runner.provenance import provenance
from bench.runner.records import Record
from bench.runner.spec import SEEDS, build_specs
from methods import METHODS
from systems import SYSTEMS

#: the pendulums' sizes (as in the plugin)
LINKS = range(1, 8)
ARMS = ("ur5", "panda")
#: the plugin that registers the pendulums, in this process and in each run's
PLUGIN = "bench.experiments.scaling_systems"


def pendulum_name(n: int) -> str:
    return f"pendulum_{n}link"


def studied_systems() -> list[str]:
    return [pendulum_name(n) for n in LINKS] + list(ARMS)


def summarize(records: list[Record]) -> list[dict]:
    """One row per (method, experiment, system): medians over the ok seeds, or what became of the runs."""
    groups: dict[tuple, list[Record]] = defaultdict(list)
    for r in records:
        groups[(r.method, r.experiment, r.system)].append(r)
    rows = []
    for (method, experiment, system), rs in groups.items():
        ok = [r for r in rs if r.status == "ok"]
        row = {"method": method, "experiment": experiment, "system": system, "dof": SYSTEMS[system]().dof,
               "runs": len(rs), "ok": len(ok)}
        if ok:
            row.update(
                step_s=statistics.median(r.fit_seconds / max(r.steps, 1) for r in ok),
                steps=statistics.median(r.steps for r in ok),
                memory_mb=statistics.median(r.details["memory"]["peak_mb"] - r.details["memory"]["start_mb"] for r in ok),
                test_mse=statistics.median(r.test_mse for r in ok),
            )
        else:
            row["why"] = f"{rs[0].status}: {rs[0].error}"
        rows.append(row)
    order = {s: i for i, s in enumerate(studied_systems())}
    return sorted(rows, key=lambda r: (r["method"], r["experiment"], order.get(r["system"], 99)))


def table(rows: list[dict]) -> str:
    lines = ["| method | experiment | system | DoF | ok | time per step (s) | steps | peak memory (MB) | test MSE |",
             "|---|---|---|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        if r["ok"]:
            cells = f"{r['step_s']:.3g} | {r['steps']:.0f} | {r['memory_mb']:.0f} | {r['test_mse']:.3g}"
        else:
            cells = f"— | — | — | {r['why'][:160]}"
        lines.append(f"| {r['method']} | {r['experiment']} | {r['system']} | {r['dof']} | {r['ok']}/{r['runs']} | {cells} |")
    return "\n".join(lines)


def plots(rows: list[dict], out: Path) -> list[Path]:
    made = []
    for key, label in (("step_s", "time per step (s)"), ("test_mse", "test MSE")):
        for experiment in ("direct", "indirect"):
            series = defaultdict(list)
            for r in rows:
                if r["experiment"] == experiment and r["ok"] and r["system"].startswith("pendulum_"):
                    series[r["method"]].append((r["dof"], r[key]))
            arms = {r["method"]: (r["dof"], r[key]) for r in rows
                    if r["experiment"] == experiment and r["ok"] and r["system"] == "panda"}
            if series:
                path = out / f"scaling_{key}_{experiment}.png"
                made.append(line_plot(series, path, xlabel="degrees of freedom (n-link pendulum; ◆ the Panda)",
                                      ylabel=label, title=f"{label}, {experiment} experiment", markers=arms))
    return made


HELP = "measure how each method's time per step, memory and error grow with the degrees of freedom (results/scaling)"


def add_arguments(parser) -> None:
    parser.add_argument("--budget", type=float, default=5.0, help="seconds per run (default 5)")
    parser.add_argument("--seeds", type=int, default=5, help="the first N of the ten fixed seeds (default 5)")
    parser.add_argument("--methods", nargs="+", default=None, help="methods (default: every available one)")
    parser.add_argument("--workers", type=int, default=None, help="runs at a time (default: one per core)")
    parser.add_argument("--out", type=Path, default=Path("results/scaling"), help="output folder (default results/scaling)")


def main(args) -> int:
    check_output(args.out, folder=True)
    import_plugins([PLUGIN])
    methods = args.methods or [m for m in METHODS.names() if METHODS.entry(m).available]
    specs = build_specs(studied_systems(), methods, ["direct", "indirect"], SEEDS[: args.seeds], args.budget,
                        plugins=(PLUGIN,), rollout=False)
    records = run_matrix(specs, args.out, workers=args.workers)
    rows = summarize(records)
    images = plots(rows, args.out)
    prov = provenance()
    text = "\n".join([
        "# How cost and error grow with the degrees of freedom",
        "",
        f"Generated by `{args.invocation}` (commit {prov.get('commit', '?')[:10]}"
        f"{', dirty tree' if prov.get('dirty') else ''}, {prov.get('cpu')}). Protocol: "
        "[bench/experiments/scaling.py](../../bench/experiments/scaling.py). "
        f"{args.budget:g} s per run, {args.seeds} seeds, 32000 training and 10000 test samples, one thread per run; "
        "medians over the seeds that ended ok. Peak memory is what a run took above what its process started with "
        "(torch and the suite, shared with the fork server).",
        "",
        table(rows),
        "",
        *[f"![{p.stem}]({p.name})" for p in images],
        "",
    ])
    atomic_write(args.out / "README.md", lambda f: f.write(text))
    print(text)
    return 0
