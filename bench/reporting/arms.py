"""The generated blocks of results/arms/README.md (:mod:`bench.reporting.pages`):
DeLaN on its characters, and beside the MLP and SyReNets on the Panda and the UR5, made from the
60 s matrices' records: the test MSE of the groups of seeds, the steps each
run did, its rollout, and its error on each part of the torque."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np

from bench.reporting.groups import group_stats, seed_statistic
from bench.reporting.pages import block, figure, indirect_records, learners as page_learners
from bench.runner.records import Record

#: the learners in the table's order, and their names there
LEARNERS = (("delan", "DeLaN"), ("mlp", "MLP"), ("syrenets", "SyReNets"))
#: the parts of the torque a record's ``details.forces`` holds, and their names in the table
PARTS = (("inertial", "inertial part"), ("coriolis", "Coriolis part"), ("gravity", "gravity part"))


def _rollouts(records: list[Record]) -> str:
    """How many of the runs' rollouts ended ok (with their median q RMSE), and why the others did not."""
    rollouts = [r.rollout for r in records if r.rollout]
    if not rollouts:
        return "not run"
    ok = [x for x in rollouts if x.get("status") == "ok"]
    text = f"{len(ok)} of {len(rollouts)} ok"
    if ok:
        text += f" (median q RMSE {float(np.median([x['q_rmse'] for x in ok])):.3g} rad)"
    others = Counter(x.get("status") for x in rollouts if x.get("status") != "ok")
    return text + "".join(f"; {n} {status}" for status, n in sorted(others.items()))


def _steps(records: list[Record]) -> str:
    steps = [r.steps for r in records if r.steps is not None]
    batch = {(r.hyperparameters or {}).get("batch_size") for r in records} - {None}
    text = f"{np.mean(steps):,.0f}" if steps else "—"
    return text + (f" (batches of {batch.pop()})" if len(batch) == 1 else "")


def table(root: Path, folder: str, system: str) -> str:
    """DeLaN, the MLP and SyReNets on ``system`` (those the folder has): one column each, from its records."""
    records = [r for r in indirect_records(root, folder) if r.system == system]
    present = {r.method for r in records}
    learners = page_learners(present, LEARNERS)
    by = {m: [r for r in records if r.method == m and r.status == "ok"] for m, _ in learners}
    rows = [("test MSE, All n (the mean over the seeds)", lambda rs: figure(group_stats(rs)["all"]["test"][0])),
            ("test MSE, Best (lowest training MSE)", lambda rs: figure(group_stats(rs)["best"]["test"][0])),
            ("test MSE, median seed", lambda rs: figure(seed_statistic(rs, "median"))),
            ("test MSE, worst seed", lambda rs: figure(seed_statistic(rs, "worst"))),
            ("steps in the budget (mean)", _steps),
            ("rollouts of 1 s", _rollouts)]
    for key, name in PARTS:
        rows.append((f"{name}'s MSE (mean)", lambda rs, k=key: figure(np.mean([r.details["forces"][f"{k}_mse"] for r in rs]))))
    lines = ["| | " + " | ".join(name for _, name in learners) + " |", "|---|" + "---:|" * len(learners)]
    for head, cell in rows:
        lines.append(f"| {head} | " + " | ".join(cell(by[m]) if by[m] else "—" for m, _ in learners) + " |")
    forces = [r.details["forces"] for rs in by.values() for r in rs if (r.details or {}).get("forces")]
    if forces:
        parts = ", ".join(f"{name} {np.mean([f[f'{key}_variance'] for f in forces]):.3g}" for key, name in PARTS)
        lines += ["", f"The true parts' variances (mean over the runs, each on its seed's {forces[0]['n']:,} test "
                      f"samples): {parts}. Runs ok: {', '.join(f'{name} {len(by[m])}' for m, name in learners)}."]
    return "\n".join(lines)


@block("arms.panda")
def panda(root: Path) -> str:
    return table(root, "arms/structure_60s", "panda")


@block("arms.characters")
def characters(root: Path) -> str:
    return table(root, "arms/delan_characters_60s", "delan_characters")


@block("arms.ur5")
def ur5(root: Path) -> str:
    return table(root, "arms/ur5_60s", "ur5")
