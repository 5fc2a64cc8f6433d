"""``python -m bench study loop-speed``: a round of the residual loop on a long log, this tree against an
earlier commit, in one run.

The log is the long-log study's (:data:`bench.studies.long_log.CASES`, ``long``: the Panda with a drive's laws, 11
training trajectories and 64,240 training samples, made by
:func:`bench.studies.selection_benchmark.make`). Each tree's code runs in a process of its own, one BLAS
thread (the earlier commit exported by :func:`bench.studies.trees.export`), and runs the loop from SysId's
rigid body under a work budget, round 0 and round 1 only (``max_rounds=1``), as ``bench residual`` and the
loop candidates of ``bench select`` run it. The trees are timed in turn, ``--rounds`` times each, so that a
change in the machine's load falls on both. The page gives, for each, the samples the loop worked on,
round 0's seconds, round 1's (its trace, joint refit, pruning and held-out checks), the laws round 1
accepted and their ratio. Usage::

    python -m bench study loop-speed --against REV [--rounds 1] [--out results/residual/loop_speed.md]
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from bench.core.arguments import positive_int
from bench.core.errors import UserError
from bench.core.fileio import atomic_write, check_output, write_json
from bench.runner.provenance import machine, made_at, provenance
from bench.runner.threads import THREAD_VARS
from bench.studies import long_log
from bench.residual.limits import MAX_ROUNDS
from bench.studies.selection_benchmark import LONG, make
from bench.studies.trees import ROOT, export

#: run in the tree being timed: round 0's and round 1's seconds on the arm ``job["arm"]`` declares
WORKER = r"""
import json, sys
job = json.loads(sys.argv[1])
import bench
assert bench.__file__.startswith(job["tree"]), (bench.__file__, job["tree"])
from bench.core.budget import Budget
from bench.residual import residual_loop
from systems import get_system
from systems.measured_arm import register_measured
import bench.residual.loop as loop
if job.get("max_samples"):
    loop.MAX_SAMPLES = job["max_samples"]
train = get_system(register_measured("measured:" + job["arm"])).load("train")
out = residual_loop("sysid", train, None, budget=Budget(steps=1), seed=0, max_rounds=job["max_rounds"],
                    report=lambda line: None)
first, second = out.rounds[0], out.rounds[1]
laws = [{"name": e["name"], "joints": e.get("joints"),
         "parameters": {k: v["value"] for k, v in (e.get("parameters") or {}).items()}} for e in out.effects]
print(json.dumps({"samples": len(train), "thinned": getattr(out, "thinned", 1), "round0_s": first["seconds"],
                  "round1_s": second["seconds"] - first["seconds"], "statistics_s": out.statistics_seconds,
                  "accepted": second.get("accepted") or [], "stop": second.get("stop"), "rounds": len(out.rounds) - 1,
                  "laws": laws}))
"""

#: the most samples the loop works on (:data:`bench.residual.loop.MAX_SAMPLES`) that the page compares, in this tree
THINNING = (4096, 8192, 16384)


def add_arguments(parser) -> None:
    parser.add_argument("--against", required=True, help="the earlier commit (any git revision)")
    parser.add_argument("--rounds", type=positive_int, default=1, help="timings of each tree (default 1)")
    parser.add_argument("--out", type=Path, default=Path("results/residual/loop_speed.md"),
                        help="the page (default results/residual/loop_speed.md), its JSON beside it; the log goes "
                             "in a temporary folder")


def time_round(tree: Path, arm: Path, max_rounds: int = 1, max_samples: int | None = None) -> dict:
    """Round 0's and round 1's seconds, what round 1 accepted and the laws the loop ended with, on ``arm``, in
    a fresh process running ``tree``'s code with one BLAS thread, at most ``max_rounds`` rounds, the loop
    working on at most ``max_samples`` samples (default the tree's own)."""
    threads = {k: "1" for k in THREAD_VARS}
    env = {**os.environ, "PYTHONPATH": str(tree), **threads}
    job = {"tree": str(tree), "arm": str(arm), "max_rounds": max_rounds, "max_samples": max_samples}
    out = subprocess.run([sys.executable, "-c", WORKER, json.dumps(job)], cwd=tree, env=env,
                         capture_output=True, text=True)
    if out.returncode != 0:
        raise UserError(f"the loop in {tree} failed: {(out.stderr.strip().splitlines() or ['no output'])[-1]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def compare(against: str, rounds: int, folder: Path, report=print, with_thinning: bool = True) -> dict:
    """Both trees' :func:`time_round` on the long log (made in ``folder``), ``rounds`` times each in turn; with
    ``with_thinning``, this tree's loop run to its end on at most each of :data:`THINNING` samples."""
    arm = make(long_log.CASES["long"], folder / "log")
    with tempfile.TemporaryDirectory(prefix="loop-speed-") as tmp:
        old = export(against, Path(tmp))
        trees = {"before": Path(tmp), "after": ROOT}
        timings = {name: [] for name in trees}
        for k in range(rounds):
            for name, tree in trees.items():
                timings[name].append(time_round(tree, arm))
                report(f"round {k + 1}/{rounds}, {name}: round 1 took {timings[name][-1]['round1_s']:.1f} s")
        thinning = {}
        for most in THINNING if with_thinning else ():
            thinning[most] = time_round(ROOT, arm, max_rounds=MAX_ROUNDS, max_samples=most)
            report(f"this tree, at most {most} samples: {thinning[most]['rounds']} rounds, "
                   f"{len(thinning[most]['laws'])} laws")
    median = {name: statistics.median(t["round1_s"] for t in ts) for name, ts in timings.items()}
    return {"against": old, "timings": timings, "round1_s": median, "ratio": median["before"] / median["after"],
            "paired": statistics.median(b["round1_s"] / a["round1_s"]
                                        for b, a in zip(timings["before"], timings["after"])),
            "thinning": thinning}


def page(result: dict, invocation: str, prov: dict) -> str:
    lines = ["# A round of the residual loop on a long log, before and after", "",
             f"Generated by `{invocation}`: before = commit {result['against'][:10]}, after = {made_at(prov, 10)}. "
             f"The long-log study's log ({long_log.CASES['long'].name}: {LONG - 1} training trajectories, "
             f"{result['timings']['after'][0]['samples']:,} samples); the loop "
             f"from SysId's rigid body under a work budget, rounds 0 and 1, one BLAS thread, each tree in a process "
             f"of its own, timed in turn. Machine: {machine(prov)}; {prov.get('utc', '')[:10]}.", "",
             "| tree | samples the loop worked on | round 0 (s) | round 1 (s) | of it in the statistics (s) | "
             "laws round 1 accepted |", "|---|---:|---:|---:|---:|---|"]
    for name, timings in result["timings"].items():
        for t in timings:
            worked = t["samples"] // max(t["thinned"], 1)
            lines.append(f"| {name} | {worked:,} (one in {t['thinned']}) | {t['round0_s']:.1f} | {t['round1_s']:.1f} | "
                         f"{t['statistics_s']:.1f} | {len(t['accepted'])}: {', '.join(t['accepted'])} |")
    lines += ["", f"Round 1 before ÷ after: **{result['ratio']:.2f}x** (medians), {result['paired']:.2f}x (the median "
                  f"of each turn's paired ratio)."]
    if result.get("thinning"):
        lines += ["", "## The laws the loop finds on fewer samples", "",
                  "This tree's loop run to its end on the training data, working on at most each count of samples "
                  "(every k-th sample of each recording): the laws it ends with, and their parameters. Only the "
                  "training data are read.", "",
                  "| at most | one sample in | rounds | seconds, round 1 | laws | the laws and their parameters |",
                  "|---:|---:|---:|---:|---:|---|"]
        for most, t in sorted(result["thinning"].items(), key=lambda kv: int(kv[0])):
            laws = "; ".join(f"{law['name']} {law['joints']}: " + ", ".join(f"{k} {v:.4g}" for k, v in
                                                                            law["parameters"].items())
                             for law in sorted(t["laws"], key=lambda law: (law["name"], law["joints"] or [])))
            lines.append(f"| {int(most):,} | {t['thinned']} | {t['rounds']} | {t['round1_s']:.1f} | {len(t['laws'])} | "
                         f"{laws} |")
    return "\n".join(lines) + "\n"


def main(args) -> int:
    check_output(args.out)
    with tempfile.TemporaryDirectory(prefix="loop-speed-log-") as tmp:
        result = compare(args.against, args.rounds, Path(tmp))
    prov = provenance()
    write_json(args.out.with_suffix(".json"), {**result, "command": args.invocation, "provenance": prov})
    text = page(result, args.invocation, prov)
    atomic_write(args.out, lambda f: f.write(text))
    print(text)
    return 0
