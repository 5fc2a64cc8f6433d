"""SyReNets' training step, this tree against an earlier commit, in one run.

Each commit's code runs in its own process (the earlier one exported with
``git archive`` into a temporary folder and put first on ``PYTHONPATH``), one
thread, on the same batch of the double pendulum. For each experiment
(direct, indirect) and configuration, the two are timed in turn,
``--rounds`` times each, so that a change in the machine's load falls on
both; the table gives each one's median steps per second, their ratio, and
the median of the rounds' paired ratios.

Configurations (:data:`CONFIGS`, which ``tests/benchmarks/test_syrenets_speed.py`` uses too):

* ``public``: SyReNets' configuration of that name (``--config public``, the
  authors' code), inputs ``(q, qd, qdd)``, a batch of 32 plus 16 replayed samples;
* ``default``: the suite's, inputs ``(q, qd)``, a batch of 32.

Both with the default one-probe contractive penalty, float64. With
``--compiled``, each configuration is timed once more with the later tree's
``compile=True`` (torch.compile of the training pass) against the earlier
tree as it is, or, with ``--both-compiled`` too, against the earlier tree's
``compile=True``; the compilation happens in the warm-up steps, which are not
timed, and the table gives how long those took. The steps run
inside the context that the tree's own ``Method.fit`` runs its loop in
(``methods.base.gc_frozen`` where the tree has it), so that what the loop
does around the step counts as well. Usage::

    python -m bench study syrenets-speed --against REV [--rounds 5] [--seconds 3] [--compiled [--both-compiled]] [--out results/syrenets/speed/syrenets_speed.md]
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from bench.core.experiment import EXPERIMENTS
from bench.core.arguments import positive, positive_int
from bench.core.errors import UserError
from bench.core.fileio import atomic_write, check_output
from bench.runner.provenance import machine, made_at, provenance
from bench.studies.trees import ROOT, export
from methods import METHODS

CONFIGS = {
    "public": {"hyperparameters": METHODS["syrenets"].configuration("public"), "batch": 48},
    "default": {"hyperparameters": {}, "batch": 32},
}

#: run in the tree being timed: steps per second of one configuration
WORKER = r"""
import json, sys, time
import torch
torch.set_num_threads(1)
job = json.loads(sys.argv[1])
import methods
assert methods.__file__.startswith(job["tree"]), (methods.__file__, job["tree"])
from bench.core.data import generate
from methods import METHODS
from systems import get_system
train = generate(get_system("double_pendulum"), 256, 0, cache=False)
m = METHODS["syrenets"](**job["hyperparameters"])
m.seed, m.dof = 0, train.dof
m._setup(train)
t = train.tensors()
batch = {k: v[:job["batch"]] for k, v in t.items()}
# the context the tree's own fit loop runs its steps in, where it has one
import contextlib, methods.base
loop_context = getattr(methods.base, "gc_frozen", contextlib.nullcontext)
with loop_context():
    start = time.perf_counter()
    for _ in range(5):
        m.train_step(batch, job["experiment"])
    warmup = time.perf_counter() - start
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < job["seconds"]:
        m.train_step(batch, job["experiment"])
        steps += 1
    rate = steps / (time.perf_counter() - start)
print(json.dumps({"steps_per_s": rate, "warmup_s": warmup}))
"""


def add_arguments(parser) -> None:
    parser.add_argument("--against", required=True, help="the earlier commit (any git revision)")
    parser.add_argument("--rounds", type=positive_int, default=5, help="timings of each tree per configuration (default 5)")
    parser.add_argument("--seconds", type=positive, default=3.0, help="seconds each timing runs (default 3)")
    parser.add_argument("--compiled", action="store_true",
                        help="also time each configuration with the later tree's compile=True")
    parser.add_argument("--both-compiled", action="store_true",
                        help="with --compiled: the earlier tree compiled too (it must have the option)")
    parser.add_argument("--out", type=Path, default=Path("results/syrenets/speed/syrenets_speed.md"),
                        help="the table to write (default results/syrenets/speed/syrenets_speed.md)")


def time_step(tree: Path, experiment: str, config: str, seconds: float, extra: dict | None = None) -> dict:
    """``{"steps_per_s", "warmup_s"}`` of one configuration (its hyperparameters
    updated with ``extra``), in a fresh process running ``tree``'s code."""
    job = {"tree": str(tree), "experiment": experiment, "seconds": seconds, **CONFIGS[config]}
    job["hyperparameters"] = {**job["hyperparameters"], **(extra or {})}
    env = {**os.environ, "PYTHONPATH": str(tree), "OMP_NUM_THREADS": "1"}
    out = subprocess.run([sys.executable, "-c", WORKER, json.dumps(job)], cwd=tree, env=env,
                         capture_output=True, text=True)
    if out.returncode != 0:
        raise UserError(f"timing {experiment}/{config} in {tree} failed: {out.stderr.strip().splitlines()[-1:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(args) -> int:
    if args.both_compiled and not args.compiled:
        raise UserError("--both-compiled: add --compiled, whose rows it changes")
    check_output(args.out)
    with tempfile.TemporaryDirectory(prefix="syrenets-speed-") as tmp:
        old_tree = Path(tmp)
        old = export(args.against, old_tree)
        trees = {"before": old_tree, "after": ROOT}
        rows, warmups = [], []
        variants = [(config, None) for config in CONFIGS]
        if args.compiled:
            variants += [(config, {"compile": True}) for config in CONFIGS]
        for experiment in EXPERIMENTS:
            for config, extra in variants:
                label = config + (", compiled" if extra else "")
                figures = {name: [] for name in trees}
                for k in range(args.rounds):
                    for name, tree in trees.items():
                        compiled = name == "after" or args.both_compiled
                        timing = time_step(tree, experiment, config, args.seconds, extra if compiled else None)
                        figures[name].append(timing["steps_per_s"])
                        if extra and compiled:
                            warmups.append(timing["warmup_s"])
                    print(f"{experiment} {label} round {k + 1}/{args.rounds}: "
                          f"before {figures['before'][-1]:.1f}, after {figures['after'][-1]:.1f} steps/s", flush=True)
                before, after = (statistics.median(figures[n]) for n in ("before", "after"))
                rows.append((experiment, label, before, after, figures))
    prov = provenance()
    lines = [
        "# SyReNets' training step, before and after",
        "",
        f"Generated by `{args.invocation}`: before = commit {old[:10]}, after = "
        f"{made_at(prov, 10)}. "
        f"One thread, float64, the double pendulum; each figure is the median of {args.rounds} timings of "
        f"{args.seconds:g} s, the two trees timed in turn. Machine: {machine(prov)}, "
        f"torch {prov.get('packages', {}).get('torch')}; {prov.get('utc', '')[:10]}.",
        "",
        "The paired ratio is the median over the rounds of each round's after ÷ before, the two timed one after",
        "the other: it follows a change in the machine's load less than the ratio of the medians does.",
        "",
        "| experiment | configuration | before (steps/s) | after (steps/s) | after ÷ before | paired ratio "
        "| timings before | timings after |",
        "|---|---|---:|---:|---:|---:|---|---|",
    ]
    for experiment, config, before, after, figures in rows:
        paired = statistics.median(a / b for a, b in zip(figures["after"], figures["before"]))
        lines.append(f"| {experiment} | {config} | {before:.1f} | {after:.1f} | {after / before:.2f}× | {paired:.2f}× | "
                     f"{', '.join(f'{v:.1f}' for v in figures['before'])} | {', '.join(f'{v:.1f}' for v in figures['after'])} |")
    if warmups:
        which = ("both trees ran with `compile=True`" if args.both_compiled
                 else "the after tree ran with `compile=True` and the before tree as it was")
        lines += ["", f"In the rows marked compiled, {which}. The compiled timings' five untimed warm-up steps, which "
                      f"include the compilation (inductor's on-disk cache "
                      f"as the earlier timings left it), took {statistics.median(warmups):.1f} s in the median "
                      f"({min(warmups):.1f}–{max(warmups):.1f} s)."]
    text = "\n".join(lines) + "\n"
    atomic_write(args.out, lambda f: f.write(text))
    print(text)
    return 0
