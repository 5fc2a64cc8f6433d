"""Without Pinocchio (a bare GPU machine, a user who has not installed
``pin``) the suite starts: the arms from URDF files are listed as
unavailable with the reason, and asking for one gives that reason in one line."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
#: the command line with Pinocchio taken away
WITHOUT = """
import importlib.abc, runpy, sys
class Missing(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name.split(".")[0] == "pinocchio":
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
sys.meta_path.insert(0, Missing())
sys.argv = ["bench", *sys.argv[1:]]
runpy.run_module("bench", run_name="__main__")
"""


def bench(*args):
    return subprocess.run([sys.executable, "-c", WITHOUT, *args], cwd=ROOT, capture_output=True, text=True, timeout=300)


def test_the_suite_starts_without_pinocchio_and_says_which_systems_need_it(tmp_path):
    listed = bench("list")
    assert listed.returncode == 0, listed.stderr
    assert "double_pendulum" in listed.stdout and "dfki_double_pendulum" in listed.stdout
    (line,) = [x for x in listed.stdout.splitlines() if "panda" in x]
    assert "unavailable" in line and "pip install pin" in line
    # a measured arm's file is read first (a bad one is refused before the systems are imported), then needs the
    # arms' engine
    refused = bench("list", "--plugin", f"measured:{ROOT / 'systems' / 'data' / 'kuka_lwr4.toml'}")
    assert refused.returncode == 2 and "Pinocchio" in refused.stderr and len(refused.stderr.strip().splitlines()) == 1
