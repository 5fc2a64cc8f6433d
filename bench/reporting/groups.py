"""The groups of seeds a table's rows are made of (Valle & Haddadin, 2021,
Tables 1 and 2): the best seed, the best and the worse half, and all of them,
ranked by training MSE (:func:`group_members`), and each row's label for
the table's number of seeds (:func:`group_label`); and the median or worst
seed's own MSE (:func:`seed_statistic`)."""

from __future__ import annotations

import math

import numpy as np

from bench.runner.records import Record

#: the groups of seeds, in the table's order; each row's label is :func:`group_label`'s
GROUPS = ("best", "best half", "all", "worse half")
#: the rows whose methods are compared for significance: the only group whose
#: seeds are not chosen by their own training MSE
TESTED_GROUP = "all"
#: the fewest seeds whose halves are rows of their own
HALVES_FROM = 4
#: what a figure may give besides a group of seeds: the median seed's MSE, and the worst seed's (the highest)
SEED_STATISTICS = ("median", "worst")


def half(n: int) -> int:
    """``k`` of "k Best" and "k Worse" for ``n`` seeds: ⌈n/2⌉."""
    return math.ceil(n / 2)


def group_label(group: str, n: int) -> str:
    """A group's row label in a table of ``n`` seeds: "Best", "k Best", "All n", "k Worse"."""
    return {"best": "Best", "best half": f"{half(n)} Best", "all": f"All {n}", "worse half": f"{half(n)} Worse"}[group]


def group_members(records: list[Record], n_seeds: int | None = None) -> dict[str, dict[str, list[float]]]:
    """``{group: {split: values}}``: each group's seeds' MSE, over ``ok`` records
    (a split without test data is absent), for a table of ``n_seeds`` seeds
    (by default the records' own); no halves below :data:`HALVES_FROM` seeds."""
    ok = sorted((r for r in records if r.status == "ok"), key=lambda r: (r.train_mse, r.seed))
    n = len(ok)
    if n == 0:
        return {}
    seeds = n_seeds if n_seeds is not None else len({r.seed for r in records})
    k = min(half(seeds), n)
    members = {"best": ok[:1], "all": ok}
    if seeds >= HALVES_FROM:
        members |= {"best half": ok[:k], "worse half": ok[n - k:]}
    out = {}
    for group, runs in members.items():
        out[group] = {}
        for split in ("train", "test"):
            vals = [getattr(r, f"{split}_mse") for r in runs]
            if not any(v is None for v in vals):
                out[group][split] = [float(v) for v in vals]
    return out


def group_stats(records: list[Record]) -> dict[str, dict[str, tuple[float, float | None]]]:
    """``{group: {"train": (mean, std), "test": (mean, std)}}`` over ``ok`` records.

    ``std`` is ``None`` for the single-run "best" group; a split without test
    data is absent.
    """
    return member_stats(group_members(records))


def member_stats(members: dict[str, dict[str, list[float]]]) -> dict[str, dict[str, tuple[float, float | None]]]:
    """:func:`group_stats` from :func:`group_members`' values."""
    return {group: {split: (float(np.mean(vals)), None if group == "best" else float(np.std(vals)))
                    for split, vals in splits.items()}
            for group, splits in members.items()}


def seed_statistic(records: list[Record], statistic: str, split: str = "test") -> float | None:
    """The median or the worst (highest) of the ``ok`` seeds' own MSEs on ``split``
    (:data:`SEED_STATISTICS`); ``None`` where no seed has one."""
    values = [v for v in (getattr(r, f"{split}_mse") for r in records if r.status == "ok") if v is not None]
    if not values:
        return None
    return float(np.median(values)) if statistic == "median" else float(max(values))
