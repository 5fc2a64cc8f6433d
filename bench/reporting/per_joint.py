"""``bench table --per-joint``: a run folder's test error per joint and per test trajectory.

Papers on real arms report the torque error per joint and per test
trajectory, often as nMSE (the MSE over the variance of the test torque, in
%), against the logged torque. Each run on a measured system records these
(:mod:`bench.evaluation.per_joint`); this page gives, per learner, their
median over its runs, against the logged (unfiltered) torque and against
the filtered torque the headline MSE is scored on, beside the filter's noise
floor: the MSE between the two torques, which no model of the filtered
torque can go below against the logged one.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import numpy as np

from bench.core.fileio import atomic_write
from bench.evaluation.per_joint import percent
from bench.reporting.tables import guide_line, label, read_for_tables, warn
from bench.runner.records import Record

#: the tables of one test trajectory: (title, key of a run's values, key of the noise floor's, in %)
TABLES = (
    ("nMSE per joint against the logged torque, unfiltered, % of its variance", "nmse_logged", "noise_floor_nmse", True),
    ("MSE per joint against the logged torque, unfiltered", "mse_logged", "noise_floor", False),
    ("nMSE per joint against the filtered torque (the headline's), % of its variance", "nmse", None, True),
    ("MSE per joint against the filtered torque (the headline's)", "mse", None, False),
)


def _split(record: Record) -> str:
    return (record.spec or {}).get("split") or "default"


def build_per_joint(records: list[Record], page: str | Path = "per_joint.md") -> str:
    """The page: per (system, split) and test trajectory, the tables of :data:`TABLES`."""
    groups: dict[tuple, dict[str, list[dict]]] = defaultdict(lambda: defaultdict(list))
    for r in records:
        entry = (r.details or {}).get("per_joint") if r.status == "ok" else None
        if entry:
            groups[(r.system, _split(r))][label(r)].append(entry["trajectories"])
    parts = ["# Test error per joint and per test trajectory", "", guide_line(page), ""]
    if not groups:
        return "\n".join(parts + ["No run here recorded its error per joint (runs on measured systems do)."]) + "\n"
    parts += ["Each cell is the median over a learner's runs (seeds); nMSE is the MSE over the variance, on that "
              "trajectory, of the torque it is scored against, in %.", ""]
    for (system, split), learners in sorted(groups.items()):
        trajectories = dict.fromkeys(t for runs in learners.values() for run in runs for t in run)
        for name in trajectories:
            runs = {m: [run[name] for run in rs if name in run] for m, rs in learners.items()}
            runs = {m: rs for m, rs in runs.items() if rs}
            first = next(iter(runs.values()))[0]
            dof = len(first["mse"])
            parts += [f"## {system}, split {split}: test trajectory {name} ({first['n']} samples)", ""]
            for title, key, floor_key, in_percent in TABLES:
                having = [r for rs in runs.values() for r in rs if key in r]
                if not having:
                    continue
                show = percent if in_percent else (lambda x: f"{x:.4g}")
                parts += [f"{title}:", "",
                          "| learner | runs | " + " | ".join(f"joint {j + 1}" for j in range(dof)) + " | mean |",
                          "|---|---:|" + "---:|" * (dof + 1)]
                floor = next((np.asarray(r[floor_key]) for r in having if floor_key and floor_key in r), None)
                if floor is not None:
                    parts.append("| the filter's noise floor | — | " + " | ".join(show(x) for x in floor)
                                 + f" | {show(floor.mean())} |")
                for method in sorted(runs):
                    values = [r[key] for r in runs[method] if key in r]
                    if not values:  # a learner whose records were written without this figure
                        parts.append(f"| {method} | 0 | " + " | ".join("—" for _ in range(dof)) + " | — |")
                        continue
                    cells = np.median(np.array(values, dtype=float), axis=0)
                    parts.append(f"| {method} | {len(values)} | " + " | ".join(show(x) for x in cells)
                                 + f" | {show(cells.mean())} |")
                parts.append("")
    return "\n".join(parts).rstrip() + "\n"


def write_per_joint(out_dir: str | Path, filename: str = "per_joint.md", report=warn) -> str:
    """Build the page from ``out_dir``'s records and write it there atomically."""
    records = read_for_tables(out_dir, report)
    if not records:
        raise FileNotFoundError(f"{out_dir}: no records found (expected {Path(out_dir) / 'records' / '*.json'})")
    page = Path(out_dir) / filename
    text = build_per_joint(records, page)
    atomic_write(page, lambda f: f.write(text))
    return text
