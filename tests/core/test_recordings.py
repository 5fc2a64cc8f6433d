"""Robot logs: naming their columns, and logs the filter cannot take."""

from __future__ import annotations

import numpy as np
import pytest

from bench.core.data import DataError
from bench.core.errors import ConfigError
from bench.core.recordings import ColumnMap, FilterSpec, Recording, preprocess


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


def test_the_filtered_velocity_sign_keeps_viscous_friction_unbiased():
    # Coulomb friction's jump, low-passed with the torque, is rounded over the filter's span: a line
    # through sign(qd) and qd then fits a steeper viscous slope; the same low-pass on sign(qd) does not
    dt, F_c, b = 0.002, 0.5, 0.2
    t = np.arange(0.0, 20.0, dt)
    qd = 0.4 * np.sin(2 * np.pi * 0.7 * t) + 0.3 * np.sin(2 * np.pi * 1.9 * t + 1.0)
    q = np.cumsum(qd) * dt
    rec = Recording(t, q[:, None], qd[:, None], (F_c * np.sign(qd) + b * qd)[:, None])
    s = preprocess(rec, FilterSpec(dt=dt, cutoff_hz=20.0))

    def fit(sign):
        return np.linalg.lstsq(np.c_[sign[:, 0], s["qd"][:, 0]], s["tau"][:, 0], rcond=None)[0]

    assert abs(fit(np.sign(s["qd"]))[1] / b - 1) > 0.05  # the bias the filtered sign removes
    np.testing.assert_allclose(fit(s["sign_qd"]), [F_c, b], rtol=2e-3)
