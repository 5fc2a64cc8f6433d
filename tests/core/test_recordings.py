"""Robot logs: naming their columns, and logs the filter cannot take."""

from __future__ import annotations

import numpy as np
import pytest

from bench.core.data import DataError
from bench.core.errors import ConfigError
from bench.core.recordings import ColumnMap, Recording, preprocess


def test_a_column_map_names_every_joints_columns():
    m = ColumnMap.parse("time=t, q_1=p1, qd_1=v1, tau_1=e1, q_2=p2, qd_2=v2, tau_2=e2")
    assert m == ColumnMap("t", ("p1", "p2"), ("v1", "v2"), ("e1", "e2")) and m.dof == 2


@pytest.mark.parametrize("text, message", [
    ("q_1=p,qd_1=v,tau_1=e", "name the time column"),
    ("time=t,q_1=p,qd_1=v,tau_1=e,q_3=x,qd_3=y,tau_3=z", "missing q_2, qd_2, tau_2"),
    ("time=t,q_1=p,qd_1=v,tau_1=e,acc_1=a", "unknown role"),
    ("time=t,time=s,q_1=p,qd_1=v,tau_1=e", "time is given twice"),
    ("time=t,q_1", "expected ROLE=COLUMN"),
])
def test_a_bad_column_map_is_refused_in_one_line(text, message):
    with pytest.raises(ConfigError, match=message):
        ColumnMap.parse(text)


def test_a_time_column_spanning_ages_is_refused_before_any_memory_is_taken():
    # found by the generated-input tests: one cell of 1e150 in the time column asked for a grid of 1e152 samples
    t = np.array([0.0, 1.0, 2.0, 1e150])
    rec = Recording(t, np.zeros((4, 1)), np.zeros((4, 1)), np.zeros((4, 1)))
    with pytest.raises(DataError, match="is the time column in seconds"):
        preprocess(rec)
