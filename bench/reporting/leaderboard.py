"""A leaderboard: the tables of one run folder (every system, method and
experiment; :mod:`bench.reporting.tables`) with their convergence plots and
the methods' ranks across them, nothing else unless a commentary is given.

The project's own (``results/README.md``, from the records of
``results/leaderboard``) interleaves them with a commentary: a markdown file whose ``## `` headings name the table
sections they comment on (``## double_pendulum, direct``), plus an
``## Introduction`` that comes first; any other heading becomes a section of
its own after the tables, in the file's order.
Tables without a paragraph are listed on the console, so none goes
unexplained by accident. After the tables, :func:`rank_summary` gives each
method's mean rank across the sections and a Friedman test of whether the
ranks differ (:func:`bench.reporting.significance.friedman`). Usage::

    python -m bench leaderboard results/leaderboard --commentary results/commentary.md --out results/README.md
"""

from __future__ import annotations

import re
from pathlib import Path

from bench.core.errors import UserError
from bench.core.fileio import atomic_write, link
from bench.reporting.significance import ALPHA, by_seed, friedman, section_medians
from bench.reporting.tables import build_tables, read_for_tables, section_groups, write_plots


def read_commentary(path: Path) -> dict[str, str]:
    """``{heading: paragraph}`` of a commentary file."""
    if not path.is_file():
        raise UserError(f"{path}: no such commentary file")
    sections, key = {}, None
    for line in path.read_text().splitlines():
        m = re.match(r"^## (.+?)\s*$", line)
        if m:
            key = m.group(1)
            sections[key] = []
        elif key is not None:
            sections[key].append(line)
    return {k: "\n".join(v).strip() for k, v in sections.items()}


def build(run_dir: Path, commentary: dict[str, str], out: Path) -> tuple[str, list[str]]:
    """The leaderboard text and the table sections that have no commentary."""
    records = read_for_tables(run_dir)
    if not records:
        raise UserError(f"{run_dir}: no records found")
    plots = {k: link(Path(run_dir) / v, out) for k, v in write_plots(records, run_dir).items()}
    tables = build_tables(records, plots, out)
    body = tables.split("\n", 1)[1]  # drop the "# Results" title
    parts, missing, used = [], [], {"Introduction"}
    for chunk in re.split(r"(?m)^(?=## )", body):
        m = re.match(r"## (\S+), (\w+) experiment", chunk)
        if m:
            key = f"{m.group(1)}, {m.group(2)}"
            noisy = "noise" in chunk.splitlines()[0]
            lookup = key if not noisy else chunk.splitlines()[0][3:]
            text = commentary.get(lookup)
            used.add(lookup)
            head, _, rest = chunk.partition("\n")
            if text:
                chunk = f"{head}\n\n{text}\n{rest}"
            else:
                missing.append(key)
        parts.append(chunk)
    intro = commentary.get("Introduction", "")
    text = "# Leaderboard\n\n" + (intro + "\n\n" if intro else "") + "".join(parts).strip("\n") + "\n"
    summary = rank_summary(records)
    if summary:
        text += f"\n## Ranks across systems\n\n{summary}\n"
    for heading, paragraph in commentary.items():
        if heading not in used:
            text += f"\n## {heading}\n\n{paragraph}\n"
    return text, missing


def rank_summary(records) -> str:
    """Mean ranks across the sections (system, experiment, noise), each
    section ranking the methods by median test MSE over seeds, with a
    Friedman test; empty where fewer than two methods ran in two sections.
    Sections where fewer than two methods have results are left out."""
    medians = {f"{system}, {experiment}, noise {noise:g}": section_medians(
        {m: list(seeds.values()) for m, seeds in by_seed(recs).items()})
        for (system, experiment, noise), recs in section_groups(records).items()}
    # a section where no method could run (the direct experiment on measured data) ranks nothing
    out = friedman({k: v for k, v in medians.items() if len(v) >= 2})
    if out is None:
        return ""
    order = sorted(out.ranks, key=lambda m: (out.ranks[m], m))
    text = (f"Each of the {out.sections} sections ranks the methods by their median test MSE over seeds "
            f"(1 = best); the mean rank across them: " + ", ".join(f"{m} {out.ranks[m]:.2f}" for m in order) + ".")
    if out.p is not None:
        verdict = "differ" if out.p < ALPHA else "cannot be told apart"
        text += (f" Friedman test over the {len(order)} methods: χ² = {out.statistic:.2f}, p = {out.p:.2g}; "
                 f"at α = {ALPHA:g} the methods' ranks {verdict}. It says whether some methods rank differently, "
                 "not which.")
    if out.left_out:
        text += (f" Left out, without a result in every section: {', '.join(out.left_out)} "
                 "(a method's variants are its own runs, and are not ranked).")
    return text


def write_leaderboard(run_dir: Path, commentary: Path | None, out: Path) -> list[str]:
    """Write the leaderboard ``out`` from ``run_dir``'s records and the
    ``commentary`` file (``None``: none); returns the table sections without commentary."""
    text, missing = build(run_dir, {} if commentary is None else read_commentary(commentary), out)
    atomic_write(out, lambda f: f.write(text))
    return missing
