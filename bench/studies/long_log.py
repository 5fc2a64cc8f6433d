"""``python -m bench study long-log``: ``bench select`` at its default on a
long generated log, as a user with a long log of their own would run it.

The log is one case of the selection benchmark (:data:`CASES`, made by
:func:`bench.studies.selection_benchmark.make`), declared as a measured arm
of one's own: in the ``long`` layout, the Panda with a drive's laws the
rigid body lacks, :data:`~bench.studies.selection_benchmark.LONG` excitation
trajectories of :data:`~bench.studies.selection_benchmark.LONG_SECONDS` each
at :data:`~bench.studies.selection_benchmark.RATE_HZ` (70,080 samples), the
last one the test; in the ``seven`` layout, the KUKA with the same laws,
:data:`~bench.studies.selection_benchmark.SEVEN` training trajectories of
2,000 samples and a test, so that the loop's final fit holds out each of
seven trajectories in turn. ``bench select`` runs on it in a process of its
own, with nothing but ``--system`` and ``--out``, and ``--busy`` keeps cores
busy beside it; the page says whether every candidate finished, how many
rounds the loop ran on each fold and in its final fit, what was chosen, its
regret (its test MSE over the best candidate's) and how long the selection
took on this machine.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

from bench.core.arguments import nonnegative_int
from bench.core.errors import UserError
from bench.core.fileio import atomic_write, write_json
from bench.runner.provenance import provenance
from bench.runner.records import read_record, record_path
from bench.studies.selection_benchmark import LOGS, NOISE, RATE_HZ, Case, make, scores

#: the case whose log is made, by layout: the Panda's 12 trajectories of 5,840 samples (``long``) or the
#: KUKA's 7 training trajectories of 2,000 (``seven``: each held out in turn in the final fit), a drive's laws, seed 77
CASES = {"long": Case("panda", "long", "drive", 77), "seven": Case("kuka", "seven", "drive", 77)}
#: the arms' names on the page
ARM_NAMES = {"panda": "Panda", "kuka": "KUKA LWR4+"}
#: each layout's page, by default
PAGES = {"long": Path("results/selection/long_log.md"), "seven": Path("results/selection/seven_trajectories.md")}


def add_arguments(parser) -> None:
    parser.add_argument("--busy", type=nonnegative_int, default=0, metavar="N",
                        help="keep N cores busy beside the selection (N processes of `yes > /dev/null`), as on a "
                             "slower machine or one doing other work (default 0)")
    parser.add_argument("--layout", choices=sorted(CASES), default="long",
                        help="the log: long (the Panda, 12 trajectories, 70,080 samples; default) or seven (the KUKA, "
                             "7 training trajectories of 2,000 samples and a test)")
    parser.add_argument("--out", type=Path, default=None,
                        help="the page (default results/selection/long_log.md, or seven_trajectories.md for --layout "
                             "seven); select's own page and JSON go in the folder of its name beside it, the log in "
                             "its data/ (not kept in the repository)")


def summary(result: dict, runs: Path | None = None) -> dict:
    """What the page reports of ``bench select``'s ``select.json``: each candidate's status, steps (the loop's
    are its rounds), budget and seconds (its search and its final fit, from its record in ``runs``), the choice and
    its regret (:func:`~bench.studies.selection_benchmark.scores`)."""
    entries = result.get("candidates") or []
    status = {e["name"]: e.get("status") for e in entries}
    work = {e["name"]: {"folds": (e.get("work") or {}).get("fold_steps"), "final": (e.get("work") or {}).get("final_steps"),
                        "budget": e.get("budget"), "seconds": None if runs is None else _seconds(runs, e)}
            for e in entries}
    scored = scores(result)
    chosen = (result.get("chosen") or {}).get("name")
    regret = scored.get("rules", {}).get("lowest", {}).get("regret")
    over = next((e.get("test_over_standard") for e in entries if e["name"] == chosen), None)
    return {"status": status, "all_ok": bool(entries) and all(s == "ok" for s in status.values()), "work": work, "chosen": chosen, "best": scored.get("best"), "regret": regret,
            "chosen_over_standard": over}


def page(report: dict) -> str:
    s = report["summary"]
    ok = sum(v == "ok" for v in s["status"].values())
    lines = ["# bench select on a long log", "",
             f"Command: `{report['command']}`" + (f", at commit {report['commit']}" if report.get("commit") else ""),
             "",
             f"The log: the selection benchmark's case `{report['case']}` in its `{report.get('layout', 'long')}` "
             f"layout: the {report.get('arm', 'Panda')}'s URDF "
             f"with a drive's laws the rigid body lacks ({', '.join(report['effects'])}), torque noise "
             f"{report['noise']:g} of each joint's standard deviation; {report['trajectories']} excitation "
             f"trajectories (finite Fourier series) of {report['seconds']:g} s at {report['rate_hz']:g} Hz, "
             f"{report['samples']:,} samples, the last trajectory the test. The command above writes it again.", "",
             f"`{report['select']}` ran in {report['select_seconds'] / 60:.1f} min wall on {report['cpus']} cores"
             + (f", {report['busy']} of them kept busy beside it (`yes > /dev/null`)" if report.get("busy") else "")
             + "; "
             f"its page: [{report['select_page']}]({report['select_page']}).", "",
             "| candidate | status | steps: each fold fit → the final fit | its budget | seconds: the search and "
             "the final fit |", "|---|---|---|---|---|"]
    for name, status in s["status"].items():
        w = s["work"].get(name) or {}
        taken = w.get("seconds")
        lines.append(f"| {name} | {status} | {w.get('folds')} → {w.get('final')} | {w.get('budget') or '—'} | "
                     f"{'—' if taken is None else format(taken, 'g')} |")
    over = s["chosen_over_standard"]
    ratio = "" if over is None else f"{over:.3f}x the standard model on the test, "
    lines += ["", f"{ok} of {len(s['status'])} candidates finished. Chosen: **{s['chosen']}**, {ratio}"
              f"regret {s['regret']:.3f} (the best on the test: {s['best']}). The test trajectory was read only to "
              "score. A step of the loop is a round; `loop+gp`'s are its GP's, on the loop's final fit as its "
              "prior.", ""]
    return "\n".join(lines)


def _seconds(runs: Path, entry: dict) -> float | None:
    """A candidate's seconds: its search's and its final fit's (``None`` where it has no record or did not finish)."""
    path = record_path(runs, entry["run_id"])
    if entry.get("status") != "ok" or not path.exists():
        return None
    record = read_record(path)
    search = ((record.details or {}).get("tuning") or {}).get("search_seconds") or 0.0
    return round(search + (record.fit_seconds or 0.0), 1)


def _rows(csv: Path) -> int:
    """A recording's samples: its lines less the header."""
    with open(csv) as f:
        return sum(1 for _ in f) - 1


def main(args) -> int:
    layout = args.layout
    case, page_path = CASES[layout], args.out or PAGES[layout]
    folder = page_path.with_suffix("")
    declared = make(case, folder / "data")
    made = json.loads((folder / "data" / "case.json").read_text())
    out = folder / "select"
    command = [sys.executable, "-m", "bench", "select", "--system", f"measured:{declared}", "--out", str(out)]
    shown = f"python -m bench select --system measured:{declared} --out {out}"
    print(f"running {shown}", flush=True)
    busy = [subprocess.Popen(["yes"], stdout=subprocess.DEVNULL) for _ in range(args.busy)]
    try:
        start = time.perf_counter()
        finished = subprocess.run(command).returncode == 0
        seconds = time.perf_counter() - start
    finally:
        for p in busy:
            p.kill()
            p.wait()
    if not finished or not (out / "select.json").exists():
        raise UserError(f"{shown} failed; its output is above")
    result = json.loads((out / "select.json").read_text())
    samples = sum(_rows(p) for p in sorted((folder / "data").glob("rec*.csv")))
    report = {"command": args.invocation, "commit": provenance().get("commit"), "case": case.name,
              "layout": layout, "arm": ARM_NAMES.get(case.arm, case.arm),
              "effects": made["effects"], "noise": NOISE, "trajectories": LOGS[layout][0], "seconds": LOGS[layout][1],
              "rate_hz": RATE_HZ, "samples": samples, "select": shown, "select_seconds": round(seconds, 1),
              "cpus": os.cpu_count(), "busy": args.busy, "select_page": os.path.relpath(out / "select.md", page_path.parent),
              "summary": summary(result, out / "runs")}
    write_json(page_path.with_suffix(".json"), report)
    text = page(report)
    atomic_write(page_path, lambda f: f.write(text))
    print(text)
    print(f"wrote {page_path}")
    return 0
