"""The DFKI filter study writes its page and, beside it, the same numbers by cut-off."""

from __future__ import annotations

import json

from bench.studies import dfki_filter
from tests.commandline import cli


def test_the_page_and_its_json_give_the_same_numbers_with_the_command_that_made_them(tmp_path, monkeypatch):
    monkeypatch.setattr(dfki_filter, "CUTOFFS_HZ", (6.0,))  # the default cut-off alone: one row's work
    out = tmp_path / "filter.md"
    r = cli("study", "dfki-filter", "--out", out)
    assert r.returncode == 0, r.stderr
    written = json.loads(out.with_suffix(".json").read_text())
    assert written["command"].endswith(f"study dfki-filter --out {out}") and written["provenance"]["commit"]
    assert list(written["cutoffs"]) == ["6"] and written["default_cutoff_hz"] == 6.0
    row = written["cutoffs"]["6"]
    # friction and the rotor explain part of what the rigid body leaves
    assert 0 < row["lab_filtered"] < row["rigid_filtered"]
    page_row = next(line for line in out.read_text().splitlines() if line.startswith("| 6 (default) |"))
    assert f"| {row['lab_params_filtered']:.4g} |" in page_row and f"| {row['rigid_raw']:.4g} |" in page_row


def test_a_page_that_cannot_be_written_is_refused_before_any_fit(tmp_path):
    folder = tmp_path / "taken.json"
    folder.mkdir()  # where the numbers would go
    r = cli("study", "dfki-filter", "--out", tmp_path / "taken.md")
    assert r.returncode != 0 and len(r.stderr.strip().splitlines()) == 1 and "taken.json" in r.stderr
    assert not (tmp_path / "taken.md").exists()


def test_the_cut_off_chosen_on_training_trajectories_reads_no_test_data(monkeypatch):
    from systems.dfki_double_pendulum import DfkiDoublePendulum

    read = []
    load = DfkiDoublePendulum.load

    def watched(self, part, *args, **kwargs):
        read.append(part)
        return load(self, part, *args, **kwargs)

    monkeypatch.setattr(DfkiDoublePendulum, "load", watched)
    folds = dfki_filter.held_out(DfkiDoublePendulum(), dfki_filter.DFKI_FILTER)
    assert set(read) == {"train"} and len(folds) == 4 and all(v > 0 for v in folds)
