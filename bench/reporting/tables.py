"""Tables in the paper's format, as a pure function of the records.

For each (system, experiment) there is one markdown table with one column per
method and the rows of Valle & Haddadin (2021), Tables 1 and 2:

* **Best**: the best seed;
* **k Best**: mean (± std) over the k best seeds;
* **All n**: mean (± std) over all seeds;
* **k Worse**: mean (± std) over the k worst seeds;

with ``n`` the table's seeds and ``k = ⌈n/2⌉`` (the paper's 10 seeds read
"5 Best", "All 10", "5 Worse"); below 4 seeds the k rows are left out
(:func:`bench.reporting.groups.group_label`),

each split into train and test MSE, in the experiment's own target (``L``
for direct, ``tau`` for indirect). The lowest mean of each row is bold; in
the All n rows (:data:`TESTED_GROUP`, the only seeds not chosen by training
MSE) so is every method whose seeds are not significantly different from
that method's (:func:`bench.reporting.significance.ties_with_best`), and a
method with too few seeds to test is marked †. Under each table, the methods'
mean rank across seeds (:func:`~bench.reporting.significance.seed_ranks`).

Definitions
-----------
* Seeds are ranked by their **training** MSE, so that picking the "best"
  seed uses no test information; the test row shows the test MSE of the same
  seeds. Ties break by seed number.
* Only runs with status ``ok`` enter the groups: "k Best" and "k Worse"
  take ``k`` of them (all of them, overlapping, where fewer than ``k`` are
  ok) and "All n" takes every one. The **Runs** row gives their number and
  what happened to the others (failed, timeout, unavailable, not applicable);
  below the table, each run that is not ok is named with its reason.
* std is the population standard deviation (``ddof = 0``).
* **Exact** counts the seeds whose expression is exactly the true Lagrangian
  up to the experiment's gauge (:mod:`bench.evaluation.recovery`); "—" for
  methods without an expression.
* Any run can be replayed with the work it did (``python -m bench rerun``).
* Above each table: the budget (seconds, or steps of each method's work),
  seeds and each method's named configuration, and the time spent compiling before the budget
  started where any run did; the data (the
  sampling ranges of generated data, or the files or recordings, and the
  noise on the training targets); the hyperparameters set beside each
  method's defaults; the machine and the commit.
* A run whose record file was corrupt, and which has not been redone, is
  counted in the Runs row as missing (:func:`bench.runner.records.missing_runs`).
"""

from __future__ import annotations

import math
import sys
from collections import Counter, defaultdict
from pathlib import Path
from typing import Callable

import numpy as np

from bench.core.experiment import EXPERIMENTS, Experiment
from bench.core.fileio import atomic_write, link
from bench.evaluation.driven import describe as describe_driven, pooled
from bench.evaluation.scores import MEASURED
from bench.reporting.groups import GROUPS, TESTED_GROUP, group_label, group_members, member_stats
from bench.reporting.header import header
from bench.reporting.plots import convergence_plot, plot_name
from bench.reporting.significance import by_seed, seed_ranks, ties_with_best
from bench.runner.provenance import PROJECT_ROOT
from bench.runner.records import Record, missing_runs, quarantine, read_records
from systems import SYSTEMS


def fmt(value: float) -> str:
    if value is None or not math.isfinite(value):
        return "nan"
    return f"{value:.2e}"


def _runs_cell(records: list[Record]) -> str:
    counts = Counter(r.status for r in records)
    if counts.get("unavailable") and len(counts) == 1:
        return "unavailable (see below)"
    if counts.get("not_applicable") and len(counts) == 1:
        return "not applicable (see below)"
    text = f"{counts.get('ok', 0)}/{len(records)} ok"
    others = [f"{v} {k.replace('_', ' ')}" for k, v in sorted(counts.items()) if k != "ok"]
    stages = Counter(stage for r in records if r.status == "ok" for stage in r.failed_stages)
    if stages:  # ok runs whose fit counts, and a later stage of which failed
        others.append("a stage after the fit failed: " + ", ".join(f"{s} in {n}" for s, n in sorted(stages.items())))
    return text + (f" ({', '.join(others)})" if others else "")


def _exact_cell(records: list[Record]) -> str:
    judged = [r for r in records if r.exact is not None]
    late = [r.details["exact_timed_out"] for r in records if r.details.get("exact_timed_out")]
    if not judged and not late:
        reasons = {r.details.get("exact_not_judged") for r in records if r.details.get("exact_not_judged")}
        if reasons == {MEASURED}:
            return "not applicable: measured data have no true L"
        if reasons:
            return "not judged: no closed-form Lagrangian"
        if any(r.details.get("exact_not_applicable") for r in records):
            return "not applicable: L is no function of q, q̇ alone"
        return "—"
    text = f"{sum(bool(r.exact) for r in judged)}/{len(records)} seeds exact"
    if late:
        text += f" ({len(late)} not judged: the check ran past {max(late):g} s)"
    return text


def _rollout_cell(records: list[Record]) -> str:
    """Median rollout error of q over the ``ok`` runs, and what became of the others."""
    rolled = [r.rollout for r in records if r.status == "ok" and r.rollout]
    if not rolled:
        return "—"
    errors = [x["q_rmse"] for x in rolled if x.get("status") == "ok" and x.get("q_rmse") is not None]
    counts = Counter(x.get("status") for x in rolled if x.get("status") != "ok")
    text = f"{fmt(float(np.median(errors)))} ({len(errors)}/{len(rolled)}" if errors else f"— (0/{len(rolled)}"
    others = "".join(f"; {v} {k.replace('_', ' ')}" for k, v in sorted(counts.items()))
    return text + others + ")"


def _driven_cell(records: list[Record], length: str) -> str:
    """The median q RMSE over every driven window of ``length`` s of the ``ok``
    runs, a diverged window counted as infinitely far, and how many diverged
    (:func:`~bench.evaluation.driven.pooled`): "diverged" where half or more did."""
    entries = [r.rollout["windows"][length] for r in records
               if r.status == "ok" and r.rollout and length in r.rollout.get("windows", {})]
    if not entries:
        return "—"
    return describe_driven(*pooled(entries), fmt)


def _standard(records: list[Record]) -> dict | None:
    """The standard model's figures (``details.standard_model``) the records carry, if any."""
    return next((r.details["standard_model"] for r in records if (r.details or {}).get("standard_model")), None)


def _constant(records: list[Record]) -> dict | None:
    """The constant model's figures (``details.constant_model``) the records carry, if any."""
    return next((r.details["constant_model"] for r in records if (r.details or {}).get("constant_model")), None)


def constant_line(records: list[Record]) -> str:
    """The constant model as a line above a measured system's table; empty where the records carry none."""
    c = _constant(records)
    if not c:
        return ""
    return (f"Constant model (each joint's training-mean torque, predicted everywhere): train MSE {fmt(c['train_mse'])}, "
            f"test MSE {fmt(c['test_mse']) if c.get('test_mse') is not None else '—'}. A learner whose "
            f"All n test MSE (the mean over its seeds) is above it is marked ‡.")


#: the joint columns of the standard model, in words (:func:`methods.sysid.joint_columns`)
JOINT_COLUMN_WORDS = {"b": "viscous friction", "F_c": "Coulomb friction", "I_a": "rotor inertia", "tau_0": "a torque offset"}


def standard_columns(standard: dict) -> str:
    """The joint columns of a record's standard model in words, the dropped ones named; a record that does not
    name them had Coulomb and viscous friction alone."""
    columns = list(standard.get("joint_columns", ("b", "F_c")))
    words = ["Coulomb and viscous friction"] if {"b", "F_c"} <= set(columns) else []
    words += [JOINT_COLUMN_WORDS.get(c, c) for c in columns if not (words and c in ("b", "F_c"))]
    text = ", ".join(words[:-1]) + " and " + words[-1] if len(words) > 1 else "".join(words)
    dropped = standard.get("dropped_joint_columns")
    return text + (f" (not identified apart from the rest: {', '.join(dropped)})" if dropped else "")


def standard_line(records: list[Record]) -> str:
    """The standard model as the line a measured arm's table reads against; empty where the records carry none."""
    s = _standard(records)
    if not s:
        return ""
    text = (f"Standard model (SysId's `{s['configuration']}` configuration: rigid-body base parameters plus "
            f"{standard_columns(s)} per joint, least squares, on the same samples): train MSE {fmt(s['train_mse'])}, test MSE "
            f"{fmt(s['test_mse']) if s.get('test_mse') is not None else '—'}")
    rollout = s.get("rollout") or {}
    for length, e in sorted(rollout.get("windows", {}).items(), key=lambda kv: float(kv[0])):
        text += f"; driven {length} s: q RMSE {describe_driven(*pooled([e]), fmt)}"
    if s.get("mass_matrix_positive_definite") is False:
        where = ("at the training states" if s.get("mass_matrix_states") is None else
                 f"indefinite at {s['mass_matrix_indefinite_states']:,} of its {s['mass_matrix_states']:,} training states")
        text += (f". Its mass matrix is not positive definite (smallest eigenvalue "
                 f"{s['mass_matrix_smallest_eigenvalue']:.3g}; {where}), so it has no forward dynamics there")
    return text + "."


def per_joint_line(records: list[Record]) -> str:
    """Where the runs recorded their test error per joint (runs on a measured system), where to find it."""
    if not any((r.details or {}).get("per_joint") for r in records):
        return ""
    return ("Per joint and per test trajectory (MSE and nMSE, against the logged and the filtered torque, beside the "
            "filter's noise floor): `per_joint.md`, written by `python -m bench table DIR --per-joint`.")


def build_table(records: list[Record]) -> str:
    """One markdown table for records of a single (system, experiment)."""
    if not records:
        return ""
    methods = sorted({r.method for r in records})
    by_method = defaultdict(list)
    for r in records:
        by_method[r.method].append(r)
    n_seeds = len({r.seed for r in records})
    members = {m: group_members(by_method[m], n_seeds) for m in methods}
    stats = {m: member_stats(members[m]) for m in methods}
    lines = ["| Group | Split | " + " | ".join(methods) + " |", "|---|---|" + "---|" * len(methods)]
    for group in GROUPS:
        if not any(group in members[m] for m in methods):
            continue
        for split in ("train", "test"):
            means = {m: stats[m].get(group, {}).get(split) for m in methods}
            samples = {m: members[m].get(group, {}).get(split) for m in methods}
            best, compared = ties_with_best({m: v for m, v in samples.items() if v is not None})
            tested_row = group == TESTED_GROUP
            constant = (_constant(records) or {}).get("test_mse") if split == "test" and tested_row else None
            cells = []
            for m in methods:
                v = means[m]
                if v is None:
                    cells.append("—")
                    continue
                text = fmt(v[0]) + ("" if v[1] is None else f" (± {fmt(v[1])})")
                if m == best or (tested_row and m in compared and compared[m].ties):
                    text = f"**{text}**"
                elif tested_row and m in compared and not compared[m].tested:
                    text += " †"
                if constant is not None and v[0] > constant:
                    text += " ‡"
                cells.append(text)
            label = group_label(group, n_seeds) if split == "train" else ""
            lines.append(f"| {label} | {split} | " + " | ".join(cells) + " |")
    lines.append("| Runs | | " + " | ".join(_runs_cell(by_method[m]) for m in methods) + " |")
    lines.append("| Exact | | " + " | ".join(_exact_cell(by_method[m]) for m in methods) + " |")
    driven = any((r.rollout or {}).get("kind") == "driven" for r in records)
    if driven:
        lengths = sorted({k for r in records for k in (r.rollout or {}).get("windows", {})}, key=float)
        for length in lengths:
            lines.append(f"| Driven {length} s | q RMSE | " + " | ".join(_driven_cell(by_method[m], length) for m in methods)
                         + " |")
    elif any(r.rollout for r in records):
        lines.append("| Rollout | q RMSE | " + " | ".join(_rollout_cell(by_method[m]) for m in methods) + " |")
    standard = _standard(records)
    if standard and standard.get("test_mse"):
        cells = []
        for m in methods:
            v = stats[m].get(TESTED_GROUP, {}).get("test")
            cells.append("—" if v is None else f"{v[0] / standard['test_mse']:.3g}×")
        lines.append(f"| {group_label(TESTED_GROUP, n_seeds)} / standard | test | " + " | ".join(cells) + " |")
    ranks, seeds = seed_ranks(by_seed(records))
    if ranks:
        order = sorted(ranks, key=lambda m: (ranks[m], m))
        lines += ["", f"Mean rank by test MSE over the {seeds} seed(s) every method completed (1 = best): "
                  + ", ".join(f"{m} {ranks[m]:.1f}" for m in order) + "."]
    notes = []
    for m in methods:
        statuses = {r.status for r in by_method[m]}
        if statuses in ({"unavailable"}, {"not_applicable"}):
            kind = "unavailable" if statuses == {"unavailable"} else "not applicable"
            notes.append(f"- **{m}** is {kind}: {by_method[m][0].error}")
            continue
        reasons: dict[tuple[str, str], list[int]] = defaultdict(list)  # every run that is not ok, with its reason
        for r in sorted(by_method[m], key=lambda r: r.seed):
            if r.status != "ok":
                reason = r.error_line or "no reason recorded"
                reasons[(r.status.replace("_", " "), reason)].append(r.seed)
        for (status, reason), seeds in reasons.items():
            which = f"seed {seeds[0]}" if len(seeds) == 1 else f"seeds {', '.join(map(str, seeds))}"
            notes.append(f"- **{m}**, {which}: {status}: {reason}")
    if notes:
        lines += [""] + notes
    return "\n".join(lines)


def label(record: Record) -> str:
    """The column a run's record goes to: its method, ``<method> tuned`` where the
    run chose its hyperparameters on its training data (beside the method's own)."""
    return str(record.name.with_tuned(record.tuned))


def expand_variants(records: list[Record]) -> list[Record]:
    """Each record under its column (:func:`label`), and one pseudo-record
    ``<method>@<variant>`` per variant a run reported (:mod:`bench.core.names`)."""
    out = []
    for r in records:
        column = r.name.with_tuned(r.tuned)
        r = r.replace(method=str(column)) if r.tuned else r
        out.append(r)
        for name, scores in (r.details or {}).get("variants", {}).items():
            blank = {"train_mse": None, "test_mse": None, "expression": None, "exact": None, "error": None,
                     "curve": [], "rollout": None}  # a variant has no training curve or rollout of its own
            fields = dict(scores)  # a stopped or inapplicable exact check goes to details, as execute puts a run's own
            details = {k: fields.pop(k) for k in list(fields) if k.startswith("exact_")}
            out.append(r.replace(**{**blank, "method": str(column.with_variant(name)), "status": "ok", **fields, "details": details}))
    return out


def section_groups(records: list[Record]) -> dict[tuple, list[Record]]:
    """Records by (system, experiment, noise), variants expanded."""
    groups = defaultdict(list)
    for r in expand_variants(records):
        groups[(r.system, r.experiment, r.noise or 0.0)].append(r)
    return groups


def build_tables(records: list[Record], plots: dict[tuple, str] | None = None, page: str | Path = "tables.md") -> str:
    """All tables, one section per (system, experiment, noise level), as one
    markdown document.

    A method's variants (such as a refined equation) get columns of their own,
    named ``<method>@<variant>``. ``plots`` maps a section's key to an image
    file (relative to the document) embedded under its table; ``page`` is
    where the document will be written, for its link to :data:`GUIDE`.
    """
    plots = plots or {}
    groups = section_groups(records)
    order = {e: k for k, e in enumerate(EXPERIMENTS)}
    parts = ["# Results", "", guide_line(page), ""]
    for (system, experiment, noise) in sorted(groups, key=lambda k: (k[0], order.get(k[1], 9), k[1], k[2])):
        recs = groups[(system, experiment, noise)]
        target = Experiment.of(experiment).symbol
        noisy = f", training targets with {noise * 100:g} % noise (test targets clean)" if noise else ""
        parts += [f"## {system}, {experiment} experiment (MSE of {target}){noisy}", ""]
        parts += [line + "  " for line in header(recs)]
        reference = _reference(system)
        if reference:
            parts += ["", f"Reference: {reference}"]
        for line in (standard_line(recs), constant_line(recs), per_joint_line(recs)):
            if line:
                parts += ["", line]
        parts += ["", build_table(recs), ""]
        if (system, experiment, noise) in plots:
            parts += [f"![convergence: {system}, {experiment}]({plots[(system, experiment, noise)]})", ""]
    return "\n".join(parts).rstrip() + "\n"


def _reference(system: str) -> str:
    """The system's published reference figure, if it declares one."""
    try:
        return SYSTEMS[system].reference
    except KeyError:
        return ""


#: the page that says how to read a table: its header, rows, marks and columns
GUIDE = PROJECT_ROOT / "docs" / "reading_tables.md"


def guide_line(page: str | Path) -> str:
    """The tables' opening line: a link to :data:`GUIDE` from the page at ``page``."""
    return f"How to read these tables: [{GUIDE.name}]({link(GUIDE, page)})."


def write_plots(records: list[Record], out_dir: str | Path) -> dict[tuple, str]:
    """Convergence plots (:mod:`bench.reporting.plots`) next to the tables, by section key."""
    made = {}
    for (system, experiment, noise), recs in section_groups(records).items():
        name = plot_name(system, experiment, noise)
        title = f"{system}, {experiment}" + (f", {noise * 100:g} % noise" if noise else "")
        if convergence_plot(recs, Path(out_dir) / name, title):
            made[(system, experiment, noise)] = name
    return made


def warn(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def read_for_tables(out_dir: str | Path, report: Callable[[str], None] = warn) -> list[Record]:
    """``out_dir``'s valid records, and stand-ins for the runs whose record
    is corrupt: such a file is reported in one line and moved to
    ``records/corrupt/`` (:func:`bench.runner.records.quarantine`), so that
    the matrix's resume redoes its run."""
    def bad(path, error):
        report(f"warning: {error}; moved to {quarantine(path)}, and counted as missing")

    records = read_records(out_dir, on_bad=bad)
    return records + missing_runs(out_dir, records)


def write_tables(out_dir: str | Path, filename: str = "tables.md", plots: bool = True,
                 report: Callable[[str], None] = warn) -> str:
    """Build the tables (and, with ``plots``, the convergence plots) from
    ``out_dir``'s records and write them into ``out_dir`` atomically."""
    records = read_for_tables(out_dir, report)
    if not records:
        raise FileNotFoundError(f"{out_dir}: no records found (expected {Path(out_dir) / 'records' / '*.json'})")
    page = Path(out_dir) / filename
    text = build_tables(records, write_plots(records, out_dir) if plots else None, page)
    atomic_write(Path(out_dir) / filename, lambda f: f.write(text))
    return text
