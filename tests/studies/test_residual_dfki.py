"""The DFKI residual measurement: its splits hold out whole recordings."""

from __future__ import annotations

import numpy as np
import pytest

from bench.studies.residual_dfki import run_case, split


def test_leaving_a_recording_out_trains_on_the_five_others_and_tests_on_it():
    train, test = split("03")
    assert test.recordings() == ["03"] and sorted(train.recordings()) == ["00", "01", "02", "04", "05"]
    assert not np.isin(train.recording, test.recording).any()
    suite_train, suite_test = split(None)
    assert sorted(suite_test.recordings()) == ["03", "05"]


@pytest.mark.long
def test_a_run_reports_before_after_and_its_time():
    row = run_case("sparse", "05", None, steps=1)
    assert row["held_out"] == "05" and row["after"] <= row["before"] and row["cut_short"] == 0
    assert 0 <= row["statistics_seconds"] <= row["seconds"]


def test_the_rows_holding_out_a_recording_the_cut_off_was_chosen_on_are_flagged_test_informed():
    from bench.studies.residual_dfki import informed_line

    line = informed_line(["00", "01", "02", "03", "04", "05"])
    assert "holding out 00, 01, 02, 04 rest on a choice" in line and "holding out 03, 05 do not" in line
    assert informed_line(["03", "05"]) == ""
