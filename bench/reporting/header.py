"""The lines above each section's table: how its runs were made (the budget,
the seeds and the methods' configurations, compiling before the budget, the
data, the hyperparameters set beside each method's own, what tuned runs
chose, the machine and the commit), from the records alone."""

from __future__ import annotations

import math
from collections import Counter, defaultdict

import numpy as np

from bench.runner.provenance import machine
from bench.runner.records import MISSING, Record
from systems import SYSTEMS


def _angle(value: float) -> str:
    for name, angle in (("π/2", math.pi / 2), ("π", math.pi)):
        if math.isclose(abs(value), angle, rel_tol=1e-9):
            return f"{'−' if value < 0 else ''}{name}"
    return f"{value:g}".replace("-", "−")


def _uniform(pairs) -> str:
    """``U(a, b)``, or one per coordinate joined by ×."""
    if len(pairs) == 2 and all(isinstance(v, (int, float)) for v in pairs):
        pairs = [pairs]
    if all(list(p) == list(pairs[0]) for p in pairs):
        pairs = pairs[:1]  # the same range for every coordinate
    return " × ".join(f"U({_angle(lo)}, {_angle(hi)})" for lo, hi in pairs)


def _data(records: list[Record]) -> str:
    """What the section's runs learned from: sampling ranges or files, sizes, noise."""
    described = [r for r in records if r.details.get("train_source")] or records
    sources = set()
    for r in described:
        if r.spec.get("train_path"):
            sources.add(f"the files {r.spec['train_path']} (test: {r.spec.get('test_path') or 'none'})")
        elif not _simulated(r.system) and r.spec.get("split") not in (None, "default"):
            sources.add(f"the system's recordings, its split {r.spec['split']} ({r.details.get('train_source', '?')}; "
                        f"test: {r.details.get('test_source', '?')})")
        elif not _simulated(r.system):
            sources.add("the system's recordings, its published train and test split"
                        + (f" ({r.details['train_source']}; test: {r.details.get('test_source')})"
                           if r.details.get("train_source") else ""))
        elif "domain" in r.details:
            d = r.details["domain"]
            ranges = {k: _uniform(d[k]) for k in ("q", "qd", "qdd")}
            text = (f"q, q̇, q̈ ~ {ranges['q']}" if len(set(ranges.values())) == 1 else
                    f"q ~ {ranges['q']}, q̇ ~ {ranges['qd']}, q̈ ~ {ranges['qdd']}")
            sources.add(f"{r.details.get('n_train')} training and {r.details.get('n_test')} test samples, {text}")
        else:
            w = r.spec.get("domain_half_width")
            sources.add("samples from the system's own domain" if not w else f"samples with angles, q̇ and q̈ ~ U(−{_angle(w)}, {_angle(w)})")
    noises = sorted({r.noise or 0.0 for r in records})
    noise = ", ".join("none" if z == 0 else f"{z * 100:g} % of each target column's std on the training targets" for z in noises)
    return f"Data: {'; '.join(sorted(sources))}; noise: {noise}."


def _simulated(system: str) -> bool:
    try:
        return bool(SYSTEMS[system].simulated)
    except KeyError:  # a system registered by a plugin that is not loaded
        return True


def _overrides(records: list[Record]) -> str:
    """The hyperparameters the runs set beside each method's defaults (or its smoke configuration)."""
    by_method = defaultdict(dict)
    for r in records:
        for key, value in (r.spec.get("hyperparameters") or {}).items():
            by_method[str(r.name.run)][key] = value
    if not by_method:
        return "Hyperparameters: each method's own (none set)."
    parts = [f"{m}: {', '.join(f'{k}={v!r}' for k, v in sorted(kv.items()))}" for m, kv in sorted(by_method.items())]
    return f"Hyperparameters set beside each method's own: {'; '.join(parts)}."


def _tuning(records: list[Record]) -> list[str]:
    """For tuned runs: the protocol, and what each tuned method chose over its seeds."""
    tuned = [r for r in records if r.tuned and (r.details or {}).get("tuning")]
    if not tuned:
        return []
    by_method = defaultdict(Counter)
    folds = set()
    for r in tuned:
        t = r.details["tuning"]
        by_method[r.method][", ".join(f"{k}={v!r}" for k, v in sorted(t.get("chosen", {}).items())) or "defaults"] += 1
        if "folds" in t:
            folds.add(t["folds"]["description"])
    chose = "; ".join(f"{m}: " + ", ".join(f"{c} ({n})" for c, n in sorted(counts.items(), key=lambda kv: -kv[1]))
                      for m, counts in sorted(by_method.items()))
    return [f"Tuned: the columns marked *tuned* are {tuned[0].details['tuning']['protocol']} (validation folds: "
            f"{'; '.join(sorted(folds)) or 'none'}), within each run's budget; chosen (seeds): {chose}."]


def _configurations(records: list[Record]) -> str:
    """The methods' named configurations: ``default`` where every run used its
    method's defaults, else the named ones by method (``default; syrenets: best-300s``)."""
    by_method = defaultdict(set)
    for r in records:
        by_method[str(r.name.run)].add(r.spec.get("profile", "default"))
    names = {n for v in by_method.values() for n in v}
    if len(names) == 1:
        return names.pop()
    others = sorted(m for m, v in by_method.items() if v == {"default"})
    named = [f"{m}: {', '.join(sorted(v))}" for m, v in sorted(by_method.items()) if v != {"default"}]
    return "; ".join((["default"] if others else []) + named)


def header(records: list[Record]) -> list[str]:
    """The lines above a section's table (see :mod:`bench.reporting.tables`): the budget, seeds and
    configurations, compiling, the data, the hyperparameters set, tuning, the machine and the commit."""
    records = [r for r in records if r.status != MISSING]
    if not records:
        return ["Every run of this section is missing its record (see the Runs row)."]
    budgets = sorted({r.describe_budget() for r in records}, key=lambda b: (len(b), b))
    kinds = {r.budget_kind for r in records}
    seeds = sorted({r.seed for r in records})
    prov = [r.provenance for r in records]
    cpus = sorted({machine(p) for p in prov})
    ran = [r.provenance for r in records if r.status not in ("unavailable", "not_applicable")]
    threads = sorted({str(p["threads"].get("torch_intra_op", "?")) for p in ran})
    per_run = f"{', '.join(threads)} thread(s) per run" if ran else "no run ran"
    commits = sorted({f"{p['commit'][:10]}{' (dirty)' if p.get('dirty') else ''}" for p in prov})
    torch_versions = sorted({str(p["packages"].get("torch")) for p in prov})
    dates = sorted(p["utc"][:10] for p in prov)
    profiles = _configurations(records)
    what = "of wall-clock per run" if kinds == {"seconds"} else \
        "of each method's work per run (gradient steps, generations or solves)" if kinds == {"steps"} else "per run"
    lines = [
        f"Budget: {', '.join(budgets)} {what}; "
        f"{len(seeds)} seed(s) ({', '.join(map(str, seeds))}); configuration: {profiles}."
        + _preparation(records),
        _data(records),
        _overrides(records),
        *_tuning(records),
        f"Machine: {'; '.join(cpus)}; {per_run}; torch {', '.join(torch_versions)}.",
        f"Commit: {', '.join(commits)}; run {dates[0]}{'' if dates[0] == dates[-1] else ' to ' + dates[-1]}.",
    ]
    return lines


def _preparation(records: list[Record]) -> str:
    """Compiling before each run's budget started, or, in records made before
    it did, inside the budget; and whether the runs can be replayed."""
    text = ""
    before = [r.details["prepare_seconds"] for r in records if r.details.get("prepare_seconds")]
    inside = [r.details["compile_seconds"] for r in records
              if r.details.get("compile_seconds") and "prepare_seconds" not in r.details]
    if before:
        text += (f" Before its budget started, each of {len(before)} run(s) compiled its training step (not counted in "
                 f"the budget): median {float(np.median(before)):.3g} s, at most {max(before):.3g} s.")
    if inside:
        text += (f" {len(inside)} run(s) compiled their training step inside the budget, which it shortened: "
                 f"median {float(np.median(inside)):.3g} s, at most {max(inside):.3g} s.")
    ran = [r for r in records if r.status == "ok"]
    old = [r for r in ran if r.replay is None and r.budget_kind == "seconds"]
    if old:
        text += (f" {'These' if len(old) == len(ran) else f'{len(old)} of these'} records predate records of the "
                 f"work a run did: their runs cannot be replayed.")
    return text
