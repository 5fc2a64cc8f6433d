"""The generated blocks of results/measured/README.md (:mod:`bench.reporting.pages`):
the KUKA LWR4+'s learners beside the standard model, the residual loop from
each fit, the laws it identified and those one trajectory cannot confirm, each
made from the matrices' records and the loops' JSON files."""

from __future__ import annotations

import re
from pathlib import Path

from bench.evaluation.driven import describe as describe_driven, pooled
from bench.reporting.groups import group_stats
from bench.reporting.pages import block, figure, indirect_records, learners as page_learners
from bench.runner.records import Record, read_record, residual_fields

#: the two splits' matrices, and how the page heads them
MATRICES = (("measured/kuka_60s", "train A, test B"), ("measured/kuka_swapped_60s", "train B, test A"))
#: the learners, in the page's order, and their names there
LEARNERS = (("sysid", "SysId (feasible, rigid body only)"), ("delan", "DeLaN"), ("syrenets", "SyReNets"),
            ("mlp", "MLP"), ("mggp", "MGGP"), ("sparse", "sparse regression"))
#: the hybrids (an identified rigid body plus a learned residual), in the page's order, and their names there
HYBRIDS = (("standard+gp", "standard model + GP"), ("feasible+gp", "feasible rigid body + GP"),
           ("standard+mlp", "standard model + MLP"), ("feasible+delan", "feasible rigid body + DeLaN"),
           ("standard+sparse_torque", "standard model + sparse torque terms"),
           ("feasible+sparse_torque", "feasible rigid body + sparse torque terms"),
           ("feasible+mggp", "feasible rigid body + MGGP"))
#: the driven rollouts' window lengths the page shows
WINDOWS = ("0.25", "1")
#: the loops' files (``LOOPS/{stem}_{split}.json``) and their names on the page
LOOPS_DIR = "measured/kuka_loop"
LOOPS = (("sysid", "SysId"), ("standard", "standard model"), ("delan", "DeLaN"), ("mlp", "MLP"))
SPLIT_NAMES = ("default", "swapped")
#: effect kinds that are findings, not laws
FINDINGS = ("structural", "beyond_data", "not_identified")


def times(x: float) -> str:
    """A ratio to the standard model: three figures, whole above 100."""
    return f"{x:.0f}×" if x >= 100 else f"{x:.3g}×"


def standard_model(records: list[Record]) -> dict | None:
    """The standard model's scores (``details.standard_model``) that the records carry, else ``None``."""
    return next((r.details["standard_model"] for r in records if (r.details or {}).get("standard_model")), None)


def _constant(records: list[Record]) -> dict | None:
    return next((r.details["constant_model"] for r in records if (r.details or {}).get("constant_model")), None)


def _driven(entries: list[dict], length: str) -> str:
    windows = [e["windows"][length] for e in entries if e and length in e.get("windows", {})]
    return describe_driven(*pooled(windows), figure) if windows else "—"


_STATUS_WORDS = {"timeout": "timed out", "failed": "failed", "unavailable": "unavailable",
                 "not_applicable": "not applicable"}


def _learner_cells(records: list[Record], standard: dict | None, constant: dict | None = None) -> list[str]:
    """A learner's cells on one split: All-n test MSE (‡ where above the constant's), ratio to the
    standard model, driven rollouts."""
    if not records:
        return ["not run", ""] + [""] * len(WINDOWS)
    ok = [r for r in records if r.status == "ok"]
    if not ok:
        status = max({r.status for r in records}, key=lambda s: sum(r.status == s for r in records))
        return [f"{len(records)} of {len(records)} runs {_STATUS_WORDS.get(status, status)}", ""] + [""] * len(WINDOWS)
    mean = group_stats(records)["all"]["test"][0]
    runs = "" if len(ok) == len(records) else f" ({len(ok)} of {len(records)} runs)"
    ratio = times(mean / standard['test_mse']) if standard and standard.get("test_mse") else "—"
    above = " ‡" if constant and constant.get("test_mse") is not None and mean > constant["test_mse"] else ""
    return [f"{figure(mean)}{above}{runs}", ratio] + [_driven([r.rollout for r in ok], w) for w in WINDOWS]


@block("measured.kuka.learners")
def learners(root: Path) -> str:
    """Every learner's All-n test MSE on each split, its ratio to the standard model,
    and its driven rollouts pooled over every seed's windows."""
    matrices = [indirect_records(root, folder) for folder, _ in MATRICES]
    head = "| |" + "".join(f" {title} | ratio |" + "".join(f" driven {w} s |" for w in WINDOWS)
                           for _, title in MATRICES)
    lines = [head, "|---|" + "---:|---:|" + "---|" * len(WINDOWS) + ("---:|---:|" + "---|" * len(WINDOWS)) * (len(MATRICES) - 1)]
    standard = [standard_model(records) for records in matrices]
    row = "| standard model |"
    for s in standard:
        row += (" — | | " + " | ".join([""] * len(WINDOWS)) + " |") if s is None else \
            (f" {figure(s['test_mse'])} | 1 | " + " | ".join(_driven([s.get("rollout")], w) for w in WINDOWS) + " |")
    lines.append(row)
    constant = [_constant(records) for records in matrices]
    if any(constant):
        row = "| constant (each joint's training-mean torque) |"
        for c, s in zip(constant, standard):
            row += (" — | |" if not c else f" {figure(c['test_mse'])} | "
                    + (times(c['test_mse'] / s['test_mse']) if s else "—") + " |") + " |" * len(WINDOWS)
        lines.append(row)
    for method, label in page_learners({r.method for records in matrices for r in records}, LEARNERS + HYBRIDS):
        cells = []
        for records, s, c in zip(matrices, standard, constant):
            cells += _learner_cells([r for r in records if r.method == method], s, c)
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    if any(constant):
        lines += ["", "‡: above the constant's test MSE."]
    return "\n".join(lines)


@block("measured.kuka.hybrids")
def hybrids(root: Path) -> str:
    """Each hybrid beside its prior on each split: its All-n test MSE over the
    standard model's, its worst seed's, over its prior's, how many seeds ended
    worse than their prior, on what share of the test samples (the median over
    seeds), and the share of its 0.25 s driven windows that stayed finite."""
    lines = ["| hybrid | split | All n / standard | worst seed / standard | All n / its prior | seeds worse than "
             "their prior | test samples worse than the prior (median over seeds) | driven 0.25 s windows finite |",
             "|---|---|---:|---:|---:|---:|---:|---:|"]
    matrices = [indirect_records(root, folder) for folder, _ in MATRICES]
    standard = [standard_model(records) for records in matrices]
    for method, label in HYBRIDS:
        for every, s, split in zip(matrices, standard, SPLIT_NAMES):
            records = [r for r in every if r.method == method and r.status == "ok"]
            if not records or not s:
                continue
            tests = [r.test_mse for r in records]
            priors = [r.details["references"]["prior"] for r in records]
            windows = [x for r in records for x in (r.rollout or {}).get("windows", {}).get(WINDOWS[0], {}).get("q_rmse", [])]
            finite = f"{sum(x is not None for x in windows) / len(windows):.0%}" if windows else "—"
            lines.append(f"| {label} | {split} | {times(sum(tests) / len(tests) / s['test_mse'])} "
                         f"| {times(max(tests) / s['test_mse'])} "
                         f"| {times(sum(tests) / sum(p['test_mse'] for p in priors))} "
                         f"| {sum(p['ratio'] > 1 for p in priors)} of {len(priors)} "
                         f"| {sorted(p['worse_share'] for p in priors)[len(priors) // 2]:.0%} | {finite} |")
    return "\n".join(lines)


def _size(records: list[Record]) -> str:
    """What a hybrid's residual learned, as its records say (the first that says)."""
    size = next(((r.details or {}).get("size") for r in records if (r.details or {}).get("size")), None)
    if size:
        return ", ".join(f"{v:,} {k}" for k, v in size.items())
    own = next(((r.details or {}).get("residual") for r in records if (r.details or {}).get("residual")), None)
    return ", ".join(f"{k} {v}" for k, v in own.items() if v is not None) if own else "—"


@block("measured.kuka.residuals")
def residuals(root: Path) -> str:
    """Symbolic against neural on what the rigid body lacks: the loop's laws from
    SysId beside each hybrid, on each split: test MSE, its ratio to the standard
    model, the driven rollouts and the size of what was learned."""
    lines = ["| what learns the residual | split | test MSE | / standard | " + " | ".join(f"driven {w} s" for w in WINDOWS)
             + " | what it learned |", "|---|---|---:|---:|" + "---|" * len(WINDOWS) + "---|"]
    for (folder, _), split in zip(MATRICES, SPLIT_NAMES):
        records = indirect_records(root, folder)
        s = standard_model(records)
        loop = _loop(root, "sysid", split)
        if loop is not None and s:
            laws = [e for e in loop["effects"] if e["kind"] not in FINDINGS]
            parameters = sum(len([p for p in e["parameters"].values() if p["value"] or p.get("stderr")]) for e in laws)
            lines.append(f"| the residual loop from SysId: named laws | {split} | {loop['mse_after']['test']:.3g} "
                         f"| {times(loop['mse_after']['test'] / s['test_mse'])} | "
                         + " | ".join(_driven([loop["rollout"]["after"]], w) for w in WINDOWS)
                         + f" | {len(laws)} laws, {parameters} parameters |")
        for method, label in HYBRIDS:
            mine = [r for r in records if r.method == method and r.status == "ok"]
            if not mine or not s:
                continue
            mean = sum(r.test_mse for r in mine) / len(mine)
            lines.append(f"| {label} (All {len(mine)}) | {split} | {mean:.3g} | {times(mean / s['test_mse'])} | "
                         + " | ".join(_driven([r.rollout for r in mine], w) for w in WINDOWS) + f" | {_size(mine)} |")
    return "\n".join(lines)


def _loop(root: Path, stem: str, split: str) -> dict | None:
    path = Path(root) / LOOPS_DIR / f"{stem}_{split}.json"
    return residual_fields(read_record(path), path) if path.is_file() else None


def holds_out(result: dict) -> str:
    """What the loop's held-out error holds out: the model and its effects where
    both are refitted without each held-out span; only the effects' coefficients
    for a kept fit, whose network saw every training row."""
    if result.get("heldout_holds_out"):
        return result["heldout_holds_out"].split(":")[0]
    return "the effects only" if result["rounds"][0].get("cross_fit") else "the model and its effects"


def _driven_pair(result: dict, length: str) -> str:
    rollout = result.get("rollout") or {}
    if not rollout:
        return "—"
    before, after = (_driven([rollout.get(k)], length) for k in ("before", "after"))
    return before if before == after and before.startswith("diverged") else f"{before} → {after}"


@block("measured.kuka.loops")
def loops(root: Path) -> str:
    """The residual loop from each fit on each split: test MSE before and after, the
    ratio to the standard model, the held-out error and what it holds out, the
    rounds kept, and the driven rollouts before and after."""
    standard = {split: standard_model(indirect_records(root, folder)) for split, (folder, _) in zip(SPLIT_NAMES, MATRICES)}
    lines = ["| loop from | split | test MSE before → after | after / standard | held out before → after "
             "(what it holds out) | rounds kept | " + " | ".join(f"driven {w} s before → after" for w in WINDOWS) + " |",
             "|---|---|---|---:|---|---:|" + "---|" * len(WINDOWS)]
    for stem, label in LOOPS:
        for split in SPLIT_NAMES:
            r = _loop(root, stem, split)
            if r is None:
                continue
            s = standard[split]
            ratio = times(r['mse_after']['test'] / s['test_mse']) if s else "—"
            kept = sum(1 for x in r["rounds"] if x["round"] > 0 and x.get("accepted") and not x.get("stop"))
            lines.append(f"| {label} | {split} | {r['mse_before']['test']:.4g} → {r['mse_after']['test']:.4g} | {ratio} "
                         f"| {figure(r['rounds'][0]['heldout_mse'])} → {figure(r['rounds'][-1]['heldout_mse'])} "
                         f"({holds_out(r)}) | {kept} | " + " | ".join(_driven_pair(r, w) for w in WINDOWS) + " |")
    return "\n".join(lines)


@block("measured.kuka.laws")
def laws(root: Path) -> str:
    """The laws the loop from SysId kept on each split: each law's parameters on
    each joint, default split / swapped split."""
    found: dict[tuple[str, str], dict[int, list[str]]] = {}
    results = [_loop(root, "sysid", split) for split in SPLIT_NAMES]
    for k, r in enumerate(results):
        for e in (r or {}).get("effects", []):
            if e["kind"] in FINDINGS or len(e["joints"]) != 1:
                continue
            for name, p in e["parameters"].items():
                if p["value"] == 0.0 and p.get("stderr", 0.0) == 0.0:  # a part the law's fit left out
                    continue
                cell = found.setdefault((e["name"], name), {}).setdefault(e["joints"][0], ["—"] * len(results))
                cell[k] = f"{p['value']:.3g} ± {p['stderr']:.1g}"
    dof = max([j for cells in found.values() for j in cells] + [0])
    lines = ["| law, parameter (default / swapped) | " + " | ".join(f"joint {j}" for j in range(1, dof + 1)) + " |",
             "|---|" + "---|" * dof]
    for (law, name), cells in sorted(found.items()):
        lines.append(f"| {law}, {name} | " + " | ".join(" / ".join(cells[j]) if j in cells else ""
                                                         for j in range(1, dof + 1)) + " |")
    return "\n".join(lines)


#: what a finding's text says the law is and what it fitted with
_FITTED = re.compile(r"^(?P<law>.*?) on (?:joints? [\d, -]+|every joint) fits the training data with (?P<what>.*?), but")


@block("measured.kuka.unconfirmed")
def unconfirmed(root: Path) -> str:
    """Per loop, the laws of the sensor and the drive and the periodic torques it
    fitted that held-out data did not confirm, with their fitted values."""
    lines = []
    for stem, label in LOOPS:
        for split in SPLIT_NAMES:
            r = _loop(root, stem, split)
            if r is None:
                continue
            entries = [e for e in r["effects"] if e["kind"] == "beyond_data"
                       and (e["name"] in ("torque_gain", "time_shift", "load_friction") or e["name"].startswith("periodic"))]
            parts = []
            for e in entries:
                m = _FITTED.search(e.get("finding", ""))
                joints = "every joint" if len(e["joints"]) > 1 else f"joint {e['joints'][0]}"
                parts.append(f"{m['law'] if m else e['name']} on {joints}" + (f", {m['what']}" if m else ""))
            lines.append(f"- {label}, {split} split: " + ("; ".join(parts) if parts else "none of these laws") + ".")
    return "\n".join(lines)
