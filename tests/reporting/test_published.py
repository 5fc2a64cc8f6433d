"""The published tables are a pure function of their records: rebuilt from
the records of results/paper/double_pendulum_60s, they are the published text,
apart from the Machine and Commit lines (which describe the runs' machine and
code, not the tables) and the link to the reading guide (which depends on
where the tables are written)."""

from __future__ import annotations

import shutil
from pathlib import Path

from bench.reporting.tables import write_tables

PUBLISHED = Path(__file__).resolve().parents[2] / "results" / "paper" / "double_pendulum_60s"


def _comparable(text: str) -> list[str]:
    return [line for line in text.splitlines() if not line.startswith(("Machine: ", "Commit: ", "How to read these tables: "))]


def test_published_tables_rebuild_from_their_records(tmp_path):
    shutil.copytree(PUBLISHED / "records", tmp_path / "records")
    rebuilt = write_tables(tmp_path)
    published = (PUBLISHED / "tables.md").read_text()
    assert _comparable(rebuilt) == _comparable(published)
    # two tables of 12 rows: the header, the 8 group rows, Runs, Exact and Rollout
    assert sum(line.startswith("| ") for line in published.splitlines()) == 2 * 12
    assert sorted(p.name for p in tmp_path.glob("*.png")) == sorted(p.name for p in PUBLISHED.glob("*.png"))
