"""The SyReNets step timing of two commits in one run."""

from __future__ import annotations

import argparse

import pytest

from bench.core.errors import UserError
from bench.studies import syrenets_speed


def test_an_unknown_revision_is_one_clear_error(tmp_path):
    with pytest.raises(UserError, match="--against no-such-rev: not a commit"):
        syrenets_speed.export("no-such-rev", tmp_path)
    assert list(tmp_path.iterdir()) == []


def test_both_compiled_without_compiled_is_one_clear_error(tmp_path):
    args = argparse.Namespace(against="HEAD", rounds=1, seconds=0.2, compiled=False, both_compiled=True,
                              out=tmp_path / "speed.md", invocation="python -m bench study syrenets-speed --both-compiled")
    with pytest.raises(UserError, match="--both-compiled: add --compiled"):
        syrenets_speed.main(args)
    assert not (tmp_path / "speed.md").exists()


@pytest.mark.slow
def test_both_trees_are_timed_in_turn_and_the_table_gives_their_ratio(tmp_path):
    out = tmp_path / "speed.md"
    args = argparse.Namespace(against="HEAD", rounds=1, seconds=0.2, compiled=False, both_compiled=False, out=out,
                              invocation="python -m bench study syrenets-speed")
    assert syrenets_speed.main(args) == 0
    rows = [line for line in out.read_text().splitlines() if line.startswith("| direct") or line.startswith("| indirect")]
    assert len(rows) == 4
    for row in rows:
        cells = [c.strip() for c in row.strip("|").split("|")]
        before, after, ratio = float(cells[2]), float(cells[3]), float(cells[4].rstrip("×"))
        assert before > 0 and after > 0 and ratio == pytest.approx(after / before, rel=0.03)
        # one round: the paired ratio is that round's ratio
        assert float(cells[5].rstrip("×")) == pytest.approx(float(cells[7]) / float(cells[6]), rel=0.03)
