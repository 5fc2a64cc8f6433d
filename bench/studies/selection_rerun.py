"""``python -m bench study selection-rerun --candidates C1,C2 --out PAGE``: the
selection benchmark's page already at ``--out`` (``python -m bench study
selection``), with only these candidates run again.

Each case's run of ``bench select`` is redone with the named candidates only
(any of select's: one the page lacks is added),
at this commit, in ``cases_SET_rerun`` beside the page; the other candidates'
figures are those the page keeps (:data:`~bench.studies.selection_benchmark.KEPT_FIGURES`),
and every rule is scored again on the merged figures, except the ``stack``,
which needs every candidate's held-out predictions: a row run again has none.
The page keeps its command and commit, and says which candidates were run
again, by which command, at which commit. A change that touches only some
candidates' code is measured so without running the others again.
"""

from __future__ import annotations

import json

from pathlib import Path

from bench.core.arguments import add_workers, csv_list
from bench.core.errors import UserError
from bench.runner.ledger import Ledger
from bench.runner.progress import print_now
from bench.runner.provenance import provenance
from bench.runner.schedule import run_jobs
from bench.studies.selection_benchmark import SelectCase, cases, publish, scores, set_of, summary
from bench.tools.candidates import named_candidates
from bench.tools import select as selection


def merged(kept: dict, again: dict, order: list[str]) -> dict:
    """A row's scores from the figures ``kept`` on the page and those of the candidates run ``again``, which
    replace theirs; candidates in ``order`` (select's)."""
    if "error" in again:
        return {"error": f"run again: {again['error']}"}
    figures = {**kept.get("candidates", {}), **again["candidates"]}
    entries = [{"name": n, **f, "status": "ok" if f.get("validation_mse") is not None else "failed",
                "model": n if f.get("validation_mse") is not None else None}
               for n in order if (f := figures.get(n)) is not None]
    return scores({"candidates": entries})


def _said(s: dict) -> str:
    """A case's candidates run again, in one line: their validation and test MSEs (the rules wait for the merge)."""
    return s.get("error") or ", ".join(f"{n} validation {f['validation_mse']:.4g}, test {f['test_mse']:.4g}"
                                       if f.get("validation_mse") is not None and f.get("test_mse") is not None
                                       else f"{n} failed" for n, f in s["candidates"].items())



def add_arguments(parser) -> None:
    parser.add_argument("--candidates", type=csv_list, required=True,
                        help="the candidates to run again, any of select's "
                             f"({', '.join(c.name for c in selection.CANDIDATES)}); one the page lacks is added")
    add_workers(parser, "candidates")
    parser.add_argument("--out", type=Path, default=Path("results/selection/benchmark.md"),
                        help="the page made by python -m bench study selection (default "
                             "results/selection/benchmark.md); the cases run again go beside it")


def main(args) -> int:
    made = args.out.with_suffix(".json")
    if not made.exists():
        raise UserError(f"{made}: no page to run candidates again on; make it with python -m bench study selection")
    before = json.loads(made.read_text())
    again = named_candidates(args.candidates)
    order = [c.name for c in selection.CANDIDATES if c.name in before["candidates"] or c.name in again]  # a new one added
    by_name = {c.name: c for c in cases(set_of(before))}
    root = args.out.parent / f"cases_{before['set']}_rerun"
    runs = sorted({(t["case"], t.get("folds") or t["protocol"]) for t in before["table"] if "rules" in t["scores"]})
    jobs = {f"{name} {folds}": SelectCase(by_name[name].arm, by_name[name].layout, by_name[name].effects,
                                          by_name[name].seed, folds, before["steps"], again, args.workers,
                                          str(root / name))
            for name, folds in runs}
    ledger = Ledger(args.out)
    done = run_jobs(jobs, 1, _said, print_now, ledger, cluster=args.cluster)
    table = [dict(t, scores=merged(t["scores"], done[f"{t['case']} {t.get('folds') or t['protocol']}"], order))
             if "rules" in t["scores"] else t for t in before["table"]]
    reruns = before.get("reruns", []) + [{"candidates": list(again), "command": args.invocation,
                                          "commit": provenance().get("commit")}]
    publish(args.out, {**before, "candidates": order, "table": table, "summary": summary(table), "reruns": reruns})
    ledger.close()
    return 0
