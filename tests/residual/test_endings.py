"""What the loop says of the laws it reports and of why it stopped.

* Laws the data cannot tell apart are named together as equivalent on these
  data, and the one kept is chosen by the stated rule, not by round-off: an
  armature on a double pendulum's joints (what ``bench data --effects
  armature=0.6,0.25`` writes), which SysId's parametric form can take on
  either joint or as a tip payload; and a tip payload that explains a fitted
  expression's own missing coupling term on clean data.
* A loop that adds nothing says whether the residual held nothing
  significant or the budget ended it, and then what the undone round had
  found and the budget it would have needed.
"""

from __future__ import annotations

import dataclasses

import pytest
import sympy

from bench.core.budget import Budget

from bench.core.symbolic import coordinate_symbols
from bench.physics.models import ExpressionModel
from bench.residual import residual_loop
from bench.residual.report import markdown, summary_lines
from bench.residual.tracing import EQUIVALENCE_RULE
from bench.runner.records import read_record, residual_fields
from tests.commandline import cli
from tests.residual.test_budget import FRICTION, _budget_ends_at
from tests.residual.test_loop import SOLVED, SYSID, data_with, quiet

ARMATURE = "armature=0.6,0.25"


def _kept(effects: list[dict]) -> list[tuple[str, list[int]]]:
    """The laws the loop added (not its findings), with their joints."""
    return [(e["name"], e["joints"]) for e in effects if "finding" not in e]


def test_an_armature_either_joint_or_a_payload_explains_is_kept_by_the_rule_and_named_with_them(tmp_path):
    for part, n, seed in (("train", 1000, 0), ("test", 500, 1000)):
        made = cli("data", "--system", "double_pendulum", "--n", n, "--seed", seed, "--effects", ARMATURE,
                   "--out", tmp_path / f"{part}.csv")
        assert made.returncode == 0, made.stderr
    done = cli("residual", "--system", "double_pendulum", "--method", "sysid", "--train", tmp_path / "train.csv",
               "--test", tmp_path / "test.csv", "--steps", SYSID, "--json", tmp_path / "out.json",
               "--report", tmp_path / "out.md")
    assert done.returncode == 0, done.stderr
    out = residual_fields(read_record(tmp_path / "out.json"))
    # the data are fitted exactly by any one of them with SysId's four parameters: the first declared is kept
    assert _kept(out["effects"]) == [("armature", [1])]
    (entry,) = out["equivalent_laws"]
    assert entry["kept"] == "armature on joint 1" and entry["rule"] == EQUIVALENCE_RULE
    assert {"armature on joint 2", "tip_payload on joints 1-2"} <= set(entry["equivalent"])
    assert all(entry["parameters"][law] == 1 for law in ["armature on joint 1", *entry["equivalent"]])
    assert out["rounds"][1]["equivalent"] == [{k: v for k, v in entry.items() if k != "round"}]
    said = "Equivalent on these data (round 1): armature on joint 1 ≡ armature on joint 2 ≡ tip_payload on joints 1-2"
    assert said in (tmp_path / "out.md").read_text() and said in done.stdout
    assert "kept armature on joint 1 by the fewest parameters, then the law declared first" in done.stdout
    assert out["ending"]["reason"] == "nothing_significant"


def test_a_payload_that_explains_the_fits_own_missing_term_is_named_with_that_term():
    # clean data, and a fitted expression that lacks the pendulum's coupling term (as a symbolic fit may): a
    # tip payload's torque, with the expression's own coefficients refitted, supplies exactly that term
    train, test = data_with({}, n=1000)
    (q1, q2), (v1, v2) = coordinate_symbols(2)
    lacking = 6.0 * v1**2 + 0.5 * v2**2 + 50.0 * sympy.cos(q1) + 8.0 * sympy.cos(q2)
    out = residual_loop("mggp", train, test, budget=Budget(steps=SOLVED), fitted=ExpressionModel(lacking, 2), report=quiet)
    kept = _kept(out.effects)
    assert kept == [("tip_payload", [1, 2])]
    (entry,) = out.equivalent_laws
    assert entry["kept"] == "tip_payload on joints 1-2"
    assert "qd_1*qd_2*cos(q_1 - q_2) on joints 1-2" in entry["equivalent"]  # never the payload alone
    assert any(line.startswith("Equivalent on these data (round 1): tip_payload on joints 1-2 ≡ ")
               for line in summary_lines(out))


def test_a_loop_that_finds_nothing_says_so_with_what_the_model_leaves_in_numbers():
    train, test = data_with({}, n=1000)
    lines = []
    out = residual_loop("sparse", train, test, budget=Budget(steps=SOLVED), report=lines.append)
    assert out.ending["reason"] == "nothing_significant" and not out.equivalent_laws
    fitted = out.models[1].predict_torque(train)
    per_joint = ((fitted - train.tau) ** 2).sum(axis=0) / ((train.tau - train.tau.mean(axis=0)) ** 2).sum(axis=0)
    assert out.unexplained["per_joint"] == pytest.approx(per_joint.tolist(), rel=1e-9)
    assert out.unexplained["train"] < 0.01  # the clean double pendulum is all but explained
    assert summary_lines(out) == [
        "No effect added: no law passed every test (significance, held-out gain, physical sense) on a residual of "
        f"{out.unexplained['train']:.0%} of the training torques' variance (per joint "
        + ", ".join(f"{x:.0%}" for x in per_joint) + ")."]
    assert any(line.startswith("round 1: nothing significant left: no law passes every test, and the model "
                               "leaves ") for line in lines)


def test_a_loop_that_ends_with_most_of_the_variance_unexplained_says_so_first_in_numbers():
    train, test = data_with({}, n=1000)
    out = residual_loop("sparse", train, test, budget=Budget(steps=SOLVED), report=quiet)
    left = dataclasses.replace(out, unexplained={"train": 0.7, "per_joint": [0.47, 0.93]})
    lines = summary_lines(left)
    assert lines[0] == ("Most of the torque is unexplained: the final model leaves 70% of the training torques' "
                        "variance (per joint 47%, 93%); what it lacks is none of the laws the loop tried, or one "
                        "that failed a test (the rounds below say which).")
    assert "nothing significant" not in " ".join(lines)
    page = markdown(left).splitlines()
    assert page.index(f"**{lines[0][:-1]}**") < page.index("| torque MSE | train | test |")


def test_a_loop_its_budget_ends_in_round_1_names_what_the_round_had_found(monkeypatch):
    train, test = data_with(FRICTION, n=1000)
    _budget_ends_at(monkeypatch, "refitting jointly", 1)
    out = residual_loop("sysid", train, test, budget=Budget(steps=SYSID), report=quiet)
    assert _kept(out.effects) == []
    ending = out.ending
    assert ending["reason"] == "budget" and ending["round"] == 1 and "while refitting jointly" in ending["detail"]
    found = {f["law"] for f in ending["found"]}
    assert found and all("friction on joint" in law for law in found), found  # what was put in, and only that
    assert all(0 < f["heldout_gain"] <= 1 for f in ending["found"])
    assert ending["budget_needed_s"]["more_than"] >= 0 and "heldout_mse" not in ending  # stopped before scoring
    lines = summary_lines(out)
    assert lines[0].startswith("No effect added: the budget ended the loop, not the residual: the budget of")
    assert lines[1].startswith(f"Round 1 had found {len(found)} law(s) before it was undone: ")
    assert "held-out gain" in lines[1] and lines[2].startswith("A time budget of more than ")
    assert "nothing significant" not in " ".join(lines)
