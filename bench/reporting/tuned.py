"""The generated blocks of results/measured/README.md on choices made on the
training data (:mod:`bench.reporting.pages`): each learner tuned on its
training trajectory beside its defaults, how often validation's best learner
was the test's best, and what ``bench select`` chose on each split."""

from __future__ import annotations

import json
from collections import Counter, defaultdict
from pathlib import Path

from bench.reporting.measured import HYBRIDS, LEARNERS, MATRICES, SPLIT_NAMES, standard_model, times
from bench.reporting.pages import block, indirect_records, learners as page_learners
from bench.runner.records import Record

#: the learners tuned beside their defaults, in the page's order, with their names there
TUNED = LEARNERS + HYBRIDS + (("loop", "the residual loop's model from SysId"),
                              ("loop+gp", "the loop's model + GP"))
#: the select pages' folders, per split: the KUKA's, and the DFKI pendulum's (declared as an arm)
SELECT = ("measured/select_default", "measured/select_swapped")
SELECT_DFKI = ("measured/select_dfki_default", "measured/select_dfki_swapped")


def _all_n(records: list[Record]) -> float | None:
    tests = [r.test_mse for r in records if r.status == "ok" and r.test_mse is not None]
    return sum(tests) / len(tests) if tests else None


def _ranks(values: dict[str, float]) -> dict[str, int]:
    return {name: i + 1 for i, name in enumerate(sorted(values, key=values.get))}


@block("measured.kuka.tuned")
def tuned_beside_default(root: Path) -> str:
    """Each learner's All-n test MSE over the standard model's with its defaults
    and tuned on its training trajectory, its rank among the learners either
    way, and what the tuned runs chose most often."""
    lines = ["| learner | split | defaults: All n / standard | rank | tuned: All n / standard | rank | "
             "chosen most often (seeds) |", "|---|---|---:|---:|---:|---:|---|"]
    for (folder, _), split in zip(MATRICES, SPLIT_NAMES):
        records = indirect_records(root, folder, tuned=None)
        s = standard_model(records)
        if not s:
            continue
        rows = page_learners({r.method for r in records}, TUNED)
        default = {m: _all_n([r for r in records if r.method == m and not r.tuned]) for m, _ in rows}
        tuned = {m: _all_n([r for r in records if r.method == m and r.tuned]) for m, _ in rows}
        both = [m for m, _ in rows if default[m] is not None and tuned[m] is not None]
        rank_d, rank_t = _ranks({m: default[m] for m in both}), _ranks({m: tuned[m] for m in both})
        for method, label in rows:
            if tuned[method] is None:
                continue
            chosen = Counter(json.dumps((r.details.get("tuning") or {}).get("chosen", {}), sort_keys=True)
                             for r in records if r.method == method and r.tuned and r.status == "ok")
            top, count = chosen.most_common(1)[0] if chosen else ("{}", 0)
            words = ", ".join(f"{k}={v}" for k, v in sorted(json.loads(top).items())) or "nothing to search"
            d = "—" if default[method] is None else times(default[method] / s["test_mse"])
            lines.append(f"| {label} | {split} | {d} | {rank_d.get(method, '—')} | "
                         f"{times(tuned[method] / s['test_mse'])} | {rank_t.get(method, '—')} | {words} ({count}) |")
    return "\n".join(lines)


def validation_cases(root: Path) -> list[dict]:
    """Per seed and split, among the tuned learners that ran: the one with the
    lowest validation MSE (of its chosen combination) and the one with the lowest test MSE."""
    cases = []
    for (folder, _), split in zip(MATRICES, SPLIT_NAMES):
        by_seed = defaultdict(dict)
        for r in indirect_records(root, folder, tuned=True):
            validation = (r.details.get("tuning") or {}).get("validation_mse")
            if r.status == "ok" and validation is not None and r.test_mse is not None:
                by_seed[r.seed][r.method] = (validation, r.test_mse)
        for seed, learners in sorted(by_seed.items()):
            if len(learners) < 2:
                continue
            cases.append({"split": split, "seed": seed, "learners": len(learners),
                          "validation_best": min(learners, key=lambda m: learners[m][0]),
                          "test_best": min(learners, key=lambda m: learners[m][1])})
    return cases


@block("measured.kuka.validation")
def validation_against_test(root: Path) -> str:
    """How often, over the seed x split cases, the tuned learner validation put
    first was the one the test put first, and which each named."""
    cases = validation_cases(root)
    if not cases:
        return "No tuned runs yet."
    hits = sum(c["validation_best"] == c["test_best"] for c in cases)
    named = Counter((c["split"], c["validation_best"], c["test_best"]) for c in cases)
    lines = [f"Validation's best learner was the test's best in **{hits} of {len(cases)}** seed × split cases.", "",
             "| split | validation's best | test's best | cases |", "|---|---|---|---:|"]
    for (split, v, t), n in sorted(named.items()):
        lines.append(f"| {split} | {v} | {t} | {n} |")
    return "\n".join(lines)


@block("measured.kuka.select")
def selected(root: Path) -> str:
    """What ``bench select`` chose on each split of the KUKA, and every candidate's validation and test figures."""
    return select_table(root, SELECT)


@block("measured.dfki.select")
def selected_dfki(root: Path) -> str:
    """The same for the DFKI pendulum, declared as an arm."""
    return select_table(root, SELECT_DFKI)


def select_table(root: Path, folders: tuple[str, ...]) -> str:
    """Each split's ``select.json`` under ``root`` (``folders``, one a split): every candidate's validation and test
    MSE, its test MSE over the standard model's, and which was chosen; then the candidates' stack, where the page
    has one (:func:`bench.tools.select.stacked`), which is reported and never chosen."""
    lines = ["| split | candidate | validation MSE | test MSE | test / standard | chosen |", "|---|---|---:|---:|---:|---|"]
    for folder, split in zip(folders, SPLIT_NAMES):
        path = Path(root) / folder / "select.json"
        if not path.exists():
            continue
        result = json.loads(path.read_text())
        chosen = (result.get("chosen") or {}).get("name")
        for c in result["candidates"]:
            if c["validation_mse"] is None or c["test_mse"] is None:
                lines.append(f"| {split} | {c['name']} | {c['status']} | | | |")
                continue
            ratio = "—" if c.get("test_over_standard") is None else times(c["test_over_standard"])
            lines.append(f"| {split} | {c['name']} | {c['validation_mse']:.3g} | {c['test_mse']:.3g} | {ratio} | "
                         f"{'**chosen**' if c['name'] == chosen else ''} |")
        stack = result.get("stack") or {}
        if stack.get("validation_mse") is not None and stack.get("test_mse") is not None:
            ratio = "—" if stack.get("test_over_standard") is None else times(stack["test_over_standard"])
            lines.append(f"| {split} | the candidates' stack (nested validation) | {stack['validation_mse']:.3g} | "
                         f"{stack['test_mse']:.3g} | {ratio} | reported, not chosen |")
    return "\n".join(lines)
