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

    python -m bench study scaling [--budget 5] [--seeds 5] [--out results/scaling]

The table covers every method recorded in the folder at the same budget and
seeds, so ``--methods delan`` adds a method's rows to a study already there
without running the others again.

The pendulums are registered as ``pendulum_<n>link`` by the plugin
:mod:`bench.studies.scaling_systems`, which the study and its runs'
processes import, so that the rest of the suite does not list them.
"""

from __future__ import annotations

import statistics
from collections import defaultdict
from pathlib import Path

from bench.core.experiment import EXPERIMENTS
from bench.core.arguments import positive, add_workers
from bench.core.fileio import atomic_write, check_output, link
from bench.reporting.plots import line_plot
from bench.runner.matrix import run_matrix
from bench.runner.plugins import import_plugins
from bench.runner.provenance import machine, made_at, provenance
from bench.runner.records import Record, read_records
from bench.runner.spec import SEEDS, build_specs, seed_count
from methods import METHODS
from bench.physics.terms import lagrangian_library_size as library_size
from systems import SYSTEMS

#: the pendulums' sizes (as in the plugin)
LINKS = range(1, 8)
ARMS = ("ur5", "panda")
#: the plugin that registers the pendulums, in this process and in each run's
PLUGIN = "bench.studies.scaling_systems"


def pendulum_name(n: int) -> str:
    return f"pendulum_{n}link"


def studied_systems() -> list[str]:
    return [pendulum_name(n) for n in LINKS] + list(ARMS)


def with_earlier(records: list[Record], folder: Path, budget: float, seeds: tuple[int, ...]) -> list[Record]:
    """``records`` and the records already in ``folder`` of the other runs of
    the study (other methods) at the same ``budget`` and ``seeds``."""
    mine = {r.run_id for r in records}
    studied = set(studied_systems())
    earlier = [r for r in read_records(folder, on_bad=lambda path, exc: None)
               if r.run_id not in mine and r.system in studied and r.budget_s == budget and r.seed in seeds]
    return records + earlier


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


def reason(why: str, limit: int = 120) -> str:
    """A run's status and the first clause of its error, cut at a word within ``limit`` characters."""
    status, _, error = why.partition(": ")
    for stop in ("; ", ". "):
        error = error.split(stop)[0]
    text = f"{status}: {error}" if error else status
    if len(text) > limit:
        text = text[:limit].rsplit(" ", 1)[0] + " …"
    return text.replace("|", "\\|")


def growth(rows: list[dict]) -> str:
    """Per (method, experiment), how time per step and memory grew over the pendulums that ran."""
    lines = ["| method | experiment | pendulums ok | time per step, largest / smallest | peak memory, largest / smallest |",
             "|---|---|---|---:|---:|"]
    by_key = defaultdict(list)
    for r in rows:
        if r["ok"] and r["system"].startswith("pendulum_"):
            by_key[(r["method"], r["experiment"])].append(r)
    for (method, experiment), rs in sorted(by_key.items()):
        small, large = min(rs, key=lambda r: r["dof"]), max(rs, key=lambda r: r["dof"])
        if large["dof"] == small["dof"]:
            continue
        memory = large["memory_mb"] / small["memory_mb"] if small["memory_mb"] > 0 else float("nan")
        lines.append(f"| {method} | {experiment} | {small['dof']}–{large['dof']} DoF | "
                     f"{large['step_s'] / small['step_s']:.2g}× | {memory:.2g}× |")
    return "\n".join(lines)


def sources() -> str:
    """Where each method's cost comes from, with the sparse library's sizes computed from its definition."""
    sizes = ", ".join(str(library_size(n, ("angle",) * n)) for n in LINKS)
    return " ".join([
        "Where the cost comes from. The direct experiment fits L itself; the indirect one trains through the",
        "Euler–Lagrange transform, whose mass matrix and Coriolis terms are second derivatives of L, n torque rows",
        "per sample. Sparse regression's library for n = 1 … {} joint angles holds {} terms, and the indirect".format(LINKS[-1], sizes),
        "design matrix holds the Euler–Lagrange transform of every term, so that method outgrows a small budget first.",
        "A SyReNets layer's terms are the pairwise sums and products of its inputs, quadratic in their number.",
        "SysId on the pendulums descends the gradient of the known model's parameters; on the arms it is one",
        "least-squares solve on Pinocchio's joint-torque regressor, one step. MGGP and Operon evaluate a population",
        "of a fixed size per generation; MGGP's indirect fitness takes the Euler–Lagrange transform of every gene of every individual.",
    ])


def table(rows: list[dict]) -> str:
    lines = ["| method | experiment | system | DoF | ok | time per step (s) | steps | peak memory (MB) | test MSE |",
             "|---|---|---|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        if r["ok"]:
            cells = f"{r['step_s']:.3g} | {r['steps']:.0f} | {r['memory_mb']:.0f} | {r['test_mse']:.3g}"
        else:
            cells = f"— | — | — | {reason(r['why'])}"
        lines.append(f"| {r['method']} | {r['experiment']} | {r['system']} | {r['dof']} | {r['ok']}/{r['runs']} | {cells} |")
    return "\n".join(lines)


def plots(rows: list[dict], out: Path) -> list[Path]:
    made = []
    for key, label in (("step_s", "time per step (s)"), ("test_mse", "test MSE")):
        for experiment in EXPERIMENTS:
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



def add_arguments(parser) -> None:
    parser.add_argument("--budget", type=positive, default=5.0, help="seconds per run (default 5)")
    parser.add_argument("--n-seeds", type=seed_count, default=5, help="the first N of the ten fixed seeds (default 5)")
    parser.add_argument("--methods", nargs="+", default=None, help="methods (default: every available one)")
    add_workers(parser, "runs", None)
    parser.add_argument("--out", type=Path, default=Path("results/scaling"), help="output folder (default results/scaling)")


def main(args) -> int:
    check_output(args.out, folder=True)
    import_plugins([PLUGIN])
    methods = args.methods or [m for m in METHODS.names() if METHODS.entry(m).available]
    specs = build_specs(studied_systems(), methods, ["direct", "indirect"], SEEDS[: args.n_seeds], args.budget,
                        plugins=(PLUGIN,), rollout=False)
    records = with_earlier(run_matrix(specs, args.out, workers=args.workers, cluster=args.cluster), args.out, args.budget,
                           tuple(SEEDS[: args.n_seeds]))
    rows = summarize(records)
    images = plots(rows, args.out)
    ran = [r.provenance for r in records if r.status not in ("unavailable", "not_applicable")] or [provenance()]
    commits = sorted({made_at(p, 10) for p in ran})
    cpus = sorted({machine(p) for p in ran})
    text = "\n".join([
        "# How cost and error grow with the degrees of freedom",
        "",
        f"Generated by `{args.invocation}` (runs at {'; '.join(commits)}, {'; '.join(cpus)}). Protocol: "
        f"[bench/studies/scaling.py]({link(__file__, args.out / 'README.md')}). "
        f"{args.budget:g} s per run, {args.n_seeds} seeds, 32000 training and 10000 test samples, one thread per run; "
        "medians over the seeds that ended ok. Peak memory is what a run took above what its process started with "
        "(torch and the suite, shared with the fork server).",
        "",
        table(rows),
        "",
        "How time per step and memory grew from the smallest to the largest pendulum that ran (ratios of the medians above):",
        "",
        growth(rows),
        "",
        sources(),
        "",
        *[f"![{p.stem}]({p.name})" for p in images],
        "",
    ])
    atomic_write(args.out / "README.md", lambda f: f.write(text))
    print(text)
    return 0
