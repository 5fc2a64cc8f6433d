"""What validation could see against what the model will be asked: on one
periodic trajectory the folds score samples next to what they were fitted on,
and a faster trajectory lies beyond them; trajectories far apart are their own
target; a target log's torques are never read."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bench.core.csv_format import write_csv
from bench.core.data import Dataset
from bench.core.folds import folds
from bench.evaluation.domain import domain, sentences
from bench.tools.select import applicability
from systems import SYSTEMS
from bench.core.scoring import opened
from tests.commandline import cli


def _joined(parts: list[Dataset]) -> Dataset:
    """Recordings one after another, as a measured arm's training data hold them."""
    cat = {k: np.concatenate([getattr(p, k) for p in parts]) for k in ("q", "qd", "qdd", "tau", "recording",
                                                                      "trajectory", "time")}
    return Dataset(cat["q"], cat["qd"], cat["qdd"], cat["tau"], recording=cat["recording"],
                   trajectory=cat["trajectory"], time=cat["time"])


def _trajectory(name: str, speed: float, amplitude: float, seconds: float = 60.0, rate: float = 100.0,
                repeats: int = 1) -> Dataset:
    """A periodic excitation of two joints at ``speed`` rad/s, recorded ``repeats`` times."""
    t = np.arange(0, seconds, 1 / rate)
    q = amplitude * np.stack([np.sin(speed * t), np.sin(0.5 * speed * t + 1)], axis=1)
    qd = amplitude * np.stack([speed * np.cos(speed * t), 0.5 * speed * np.cos(0.5 * speed * t + 1)], axis=1)
    parts = []
    for k in range(repeats):
        n = len(t)
        parts.append(Dataset(q, qd, np.zeros_like(q), np.cos(q), recording=np.full(n, f"{name}{k}"),
                             trajectory=np.full(n, name), time=t))
    return _joined(parts)


def test_on_one_periodic_trajectory_a_faster_one_lies_beyond_what_validation_reached():
    train = _trajectory("A", 1.0, 1.0, repeats=2)
    faster = _trajectory("B", 2.0, 1.3)
    report = domain(train, folds(train), faster, "a faster trajectory")
    assert report["reach"]["median"] < 0.05  # a period later the trajectory revisits its own states
    assert report["target"]["median_distance"] > 10 * report["reach"]["median"]
    assert report["validated_at_target"] is False
    assert "**not** validated at the target's distance" in sentences(report)
    alone = domain(train, folds(train))  # one trajectory and no target: nothing to compare with, and it says so
    assert alone["target"] is None and alone["validated_at_target"] is None
    assert "nothing says how far the next trajectory will lie" in sentences(alone)
    assert applicability(train, faster, None)["test_beyond_reach"] is True


def test_several_trajectories_are_their_own_target():
    train = _joined([_trajectory("slow", 0.5, 0.6), _trajectory("mid", 1.0, 1.0), _trajectory("fast", 2.0, 1.4)])
    report = domain(train, folds(train))
    assert report["target"]["what"] == "the spread between the training trajectories"
    assert len(report["target"]["per_trajectory"]) == 3
    # leaving a whole trajectory out, the folds reach exactly as far as the trajectories lie from each other
    assert report["validated_at_target"] is True
    assert report["reach"]["median"] == report["target"]["median_distance"]


@pytest.mark.long
def test_select_reads_the_target_logs_states_and_never_its_torques(tmp_path):
    test = opened(SYSTEMS["kuka_lwr4"]().load("test"))
    write_csv(test, tmp_path / "target.csv")
    lines = (tmp_path / "target.csv").read_text().splitlines()
    header = lines[0].split(",")
    taus = [i for i, c in enumerate(header) if c.startswith("tau_")]
    garbled = [lines[0]] + [",".join("not a torque" if i in taus else v for i, v in enumerate(line.split(",")))
                            for line in lines[1:]]
    (tmp_path / "target.csv").write_text("\n".join(garbled) + "\n")
    out = tmp_path / "sel"
    r = cli("select", "--system", "kuka_lwr4", "--candidates", "standard,feasible", "--steps", "1", "--no-rollout",
            "--target-states", tmp_path / "target.csv", "--out", out)
    assert r.returncode == 0, r.stderr
    report = json.loads((out / "select.json").read_text())["domain"]
    # the target here is the test trajectory's states, so the two distances are one
    assert report["target"]["median_distance"] == report["test_median_distance"] > 1.0
    assert report["validated_at_target"] is False and report["test_beyond_reach"] is True
    assert "not validated at the target's distance" in r.stdout
    assert "**not** validated at the target's distance" in (out / "select.md").read_text()
