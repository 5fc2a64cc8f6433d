"""A law of the joint declared by a plugin file alone (tests/plugins/quadratic_drag.py, the example of
docs/extending.md) goes into generated data through ``bench data --plugin`` and is found by the residual loop,
through ``bench residual --plugin``, with its value, as a built-in law is."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from bench.core.data import generate
from bench.physics.effects import EFFECTS, Effect
from bench.physics.laws import FAMILIES, LAWS
from bench.runner.records import read_record, residual_fields
from systems import get_system
from tests.commandline import cli

PLUGIN = Path(__file__).parents[1] / "plugins" / "quadratic_drag.py"


@pytest.fixture
def drag():
    """The plugin imported as ``--plugin`` imports it, and its law taken out again after the test."""
    spec = importlib.util.spec_from_file_location("quadratic_drag_plugin", PLUGIN)
    module = importlib.util.module_from_spec(spec)
    sys.modules["quadratic_drag_plugin"] = module
    spec.loader.exec_module(module)
    yield
    LAWS.remove("quadratic_drag")
    sys.modules.pop("quadratic_drag_plugin", None)


def dragged(data, c):
    return data.replace(tau=data.tau + np.asarray(c) * data.qd * np.abs(data.qd))


def test_a_declared_law_of_the_joint_is_an_effect_a_law_and_a_family(drag):
    assert "quadratic_drag" in EFFECTS and LAWS.arm["quadratic_drag"].family == FAMILIES["quadratic_drag"] == "drag"
    LAWS.declare(EFFECTS["quadratic_drag"], "drag")  # the same declaration again (a plugin imported twice) is kept
    with pytest.raises(ValueError, match="a name of its own"):
        LAWS.declare(Effect("quadratic_drag", lambda q, qd: qd[0] ** 4, "D", "c", "other"), "drag")
    with pytest.raises(ValueError, match="one effect on one joint"):
        LAWS.declare(Effect("pair_drag", lambda q, qd: qd[0] * qd[1], "D", "c", "c", arity=2), "drag")


def test_the_law_is_gone_once_removed():
    assert "quadratic_drag" not in EFFECTS and "quadratic_drag" not in FAMILIES and "quadratic_drag" not in LAWS.arm


def test_a_plugins_law_of_the_joint_reaches_generated_data_and_the_loop(drag, tmp_path):
    s = get_system("double_pendulum")
    clean = generate(s, 64, 0)
    r = cli("data", "--system", "double_pendulum", "--n", "64", "--seed", "0", "--plugin", PLUGIN,
            "--effects", "quadratic_drag=0.3,0", "--out", tmp_path / "d.csv")
    assert r.returncode == 0, r.stderr
    from bench.core.csv_format import read_csv
    np.testing.assert_allclose(read_csv(tmp_path / "d.csv").tau, dragged(clean, [0.3, 0.0]).tau, rtol=1e-9, atol=1e-12)
    bad = cli("data", "--system", "double_pendulum", "--n", "64", "--seed", "0", "--plugin", PLUGIN,
              "--effects", "quadratic_drag=-0.3,0", "--out", tmp_path / "e.csv")
    assert bad.returncode == 2 and "quadratic_drag" in bad.stderr and not (tmp_path / "e.csv").exists()
    for name, n, seed in (("train", 2000, 0), ("test", 800, 1000)):
        made = cli("data", "--system", "double_pendulum", "--n", str(n), "--seed", str(seed), "--plugin", PLUGIN,
                   "--effects", "quadratic_drag=0.3,0", "--out", tmp_path / f"{name}.csv")
        assert made.returncode == 0, made.stderr
    loop = cli("residual", "--system", "double_pendulum", "--method", "sysid", "--train", tmp_path / "train.csv",
               "--test", tmp_path / "test.csv", "--steps", "1000", "--plugin", PLUGIN, "--json", tmp_path / "loop.json")
    assert loop.returncode == 0, loop.stderr
    result = residual_fields(read_record(tmp_path / "loop.json"))
    found = {(e["name"], tuple(e["joints"])): e for e in result["effects"]
             if e["kind"] not in ("structural", "beyond_data", "not_identified")}
    assert list(found) == [("quadratic_drag", (1,))]
    assert found[("quadratic_drag", (1,))]["parameters"]["c"]["value"] == pytest.approx(0.3, rel=1e-3)


def test_the_guides_example_is_the_plugin_file():
    guide = (Path(__file__).parents[2] / "docs" / "extending.md").read_text()
    declaration = PLUGIN.read_text()[PLUGIN.read_text().index("LAWS.declare("):].strip()
    assert declaration in guide
