"""An arm as it comes: one arm of a two-arm robot's URDF, its log at 100 Hz,
space-separated with CRLF line ends and without a time column, fitted by
``bench fit`` and ``bench residual`` from one declaration; and the refusals of
a chain that is not there."""

from __future__ import annotations

import gzip
import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pandas as pd
import numpy as np
import pytest
from bench.runner.records import read_record, residual_fields

from systems.urdf_arm import chain
from tests.commandline import cli

PANDA = Path(__file__).resolve().parents[2] / "systems" / "data" / "panda.urdf.gz"


def two_arms(path: Path) -> Path:
    """The Panda's URDF twice, ``left_`` and ``right_``, fixed to one base 1 m apart."""
    panda = ET.fromstring(gzip.open(PANDA).read())
    robot = ET.Element("robot", name="two_pandas")
    ET.SubElement(robot, "link", name="base")
    for side, y in (("left", 0.5), ("right", -0.5)):
        for element in panda:
            copy = ET.fromstring(ET.tostring(element))
            if copy.tag in ("link", "joint"):
                copy.set("name", f"{side}_{copy.get('name')}")
            for ref in copy.iter():
                if ref.tag in ("parent", "child"):
                    ref.set("link", f"{side}_{ref.get('link')}")
                if ref.tag == "mimic":
                    ref.set("joint", f"{side}_{ref.get('joint')}")
            robot.append(copy)
        mount = ET.SubElement(robot, "joint", name=f"{side}_mount", type="fixed")
        ET.SubElement(mount, "parent", link="base")
        ET.SubElement(mount, "child", link=f"{side}_panda_link0")
        ET.SubElement(mount, "origin", xyz=f"0 {y} 0", rpy="0 0 0")
    path.write_bytes(ET.tostring(robot))
    return path


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    """The two-arm URDF, three 4 s logs of its left arm as a logger writes them, and the arm's declaration."""
    folder = tmp_path_factory.mktemp("arm")
    urdf = two_arms(folder / "two_pandas.urdf")
    assert cli("robot-log", "--system", "panda", "--recordings", "3", "--seconds", "4", "--rate-hz", "100",
               "--effects", "viscous_friction=0.5,0.5,0.3,0.3,0.2,0.2,0.1", "--out", folder / "sim").returncode == 0
    names = []
    for k in range(3):
        frame = pd.read_csv(folder / "sim" / f"recording_{k}.csv").drop(columns=["time"])
        lines = [" ".join(frame.columns)] + [" ".join(f"{v:.17g}" for v in row) for row in frame.to_numpy()]
        (folder / f"log_{k}.txt").write_bytes(("\r\n".join(lines) + "\r\n").encode())
        names = list(frame.columns)
    columns = ",".join(f"{role}_{j}={c}" for j in range(1, 8) for role, c in
                       zip(("q", "qd", "tau"), [c for c in names if c.startswith(f"joint{j}_")]))
    body = "\n".join([
        f'urdf = "{urdf.name}"', 'root = "left_panda_link0"', 'tip = "left_panda_link7"', f'columns = "{columns}"',
        "rate_hz = 100", 'test = ["c"]', "[filter]", "cutoff_hz = 10.0", "[recordings]",
        *(f'r{k} = {{ file = "log_{k}.txt", trajectory = "{t}" }}' for k, t in enumerate("abc"))]) + "\n"
    declaration = folder / "left_arm.toml"
    declaration.write_text(body)
    return folder, declaration, body


@pytest.mark.long
def test_one_arm_of_a_two_arm_robot_is_fitted_and_traced_from_one_declaration(arm, tmp_path):
    folder, declaration, _ = arm
    r = cli("fit", "--system", f"measured:{declaration}", "--method", "sysid", "--experiment", "indirect",
            "--steps", "1", "--set", "feasible=false", "--set", "friction=true", "--json", tmp_path / "fit.json")
    assert r.returncode == 0, r.stderr
    record = json.loads((tmp_path / "fit.json").read_text())
    assert record["status"] == "ok" and record["test_mse"] < 1e-3 * record["details"]["constant_model"]["test_mse"]
    # the 100 Hz rows are kept as they are: 4 s less the 0.25 s trimmed from each end, 10 ms apart, nothing resampled
    assert "resampled" not in record["details"]["train_source"] and "interpolated" not in record["details"]["train_source"]
    assert record["details"]["n_train"] == 2 * (400 - 2 * 25)
    assert "  test trajectory c (350 samples), nMSE per joint against the logged torque, %: " in r.stdout
    r = cli("residual", "--system", f"measured:{declaration}", "--method", "sysid", "--steps", "1",
            "--json", tmp_path / "loop.json")
    assert r.returncode == 0, r.stderr
    loop = residual_fields(read_record(tmp_path / "loop.json"))
    assert loop["mse_after"]["test"] < loop["mse_before"]["test"]
    # per joint, before and after, against the logged torque beside the filter's noise floor
    before, after = (loop["per_joint"][k]["trajectories"]["c"] for k in ("before", "after"))
    assert len(after["nmse_logged"]) == 7 and np.mean(after["mse"]) == pytest.approx(loop["mse_after"]["test"], rel=1e-4)
    assert np.mean(after["nmse_logged"]) < np.mean(before["nmse_logged"])
    assert "test trajectory c (350 samples), nMSE per joint against the logged torque, %, before → after: 1: " in r.stdout
    assert {e["name"] for e in loop["effects"] if e["kind"] not in ("structural", "beyond_data", "not_identified")} \
        >= {"viscous_friction"}


@pytest.mark.parametrize("change, words", [
    (('tip = "left_panda_link7"', 'tip = "left_panda_link9"'), "no link 'left_panda_link9' (tip)"),
    (('root = "left_panda_link0"', 'root = "right_panda_link0"'), "do not form a chain"),
    (('tip = "left_panda_link7"', 'tip = "left_panda_link5"'), "has 5 joint(s)"),
])
def test_a_chain_that_is_not_there_is_refused_in_one_line_and_nothing_is_written(arm, tmp_path, change, words):
    folder, _, body = arm
    bad = folder / f"bad_{abs(hash(change)) % 1000}.toml"
    bad.write_text(body.replace(*change))
    out = tmp_path / "fit.json"
    r = cli("fit", "--system", f"measured:{bad}", "--method", "sysid", "--experiment", "indirect", "--steps", "1",
            "--json", out)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert str(bad) in r.stderr and words in r.stderr and not out.exists()


def test_the_joints_named_must_follow_one_another(arm):
    folder, _, _ = arm
    picked, locked = chain(folder / "two_pandas.urdf", joints=["left_panda_joint1", "left_panda_joint2"])
    assert picked == ["left_panda_joint1", "left_panda_joint2"] and "right_panda_joint1" in locked
    with pytest.raises(Exception, match="do not form a chain: left_panda_joint3 does not follow left_panda_joint1"):
        chain(folder / "two_pandas.urdf", joints=["left_panda_joint1", "left_panda_joint3"])
