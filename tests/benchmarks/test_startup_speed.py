"""The command line's start-up: ``python -m bench --help``, ``select --help``, ``bench list``, a
refused model file and a refused measured-arm file, each a fresh process, beside
``python -c pass`` in the same run. Run with ``make benchmark``; the table after
it gives each one's seconds more than ``python -c pass``."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.benchmark

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("startup")
    (folder / "model.npz").write_bytes(b"not a model file")
    (folder / "log.csv").write_text("q_1,qd_1,qdd_1\n0,0,0\n")
    (folder / "arm.toml").write_text('urdf = "arm.urdf"\n[recordings\n')
    return folder


def _run(*argv: str, code: int):
    def call():
        r = subprocess.run([sys.executable, *argv], cwd=ROOT, capture_output=True, text=True)
        assert r.returncode == code, r.stderr[-500:]
    return call


@pytest.mark.parametrize("name,argv,code", [
    ("python -c pass", ("-c", "pass"), 0),
    ("bench --help", ("-m", "bench", "--help"), 0),
    ("bench select --help", ("-m", "bench", "select", "--help"), 0),
    ("bench list", ("-m", "bench", "list"), 0),
])
def test_startup(benchmark, name, argv, code):
    benchmark.group = "startup"
    benchmark.extra_info["startup"] = name
    benchmark.pedantic(_run(*argv, code=code), rounds=3, iterations=1)


def test_startup_refused_model_file(benchmark, files):
    benchmark.group = "startup"
    benchmark.extra_info["startup"] = "a refused model file (bench predict)"
    benchmark.pedantic(_run("-m", "bench", "predict", "--model", str(files / "model.npz"), "--log",
                            str(files / "log.csv"), "--out", str(files / "out.csv"), code=2), rounds=3, iterations=1)


@pytest.mark.parametrize("command", [
    ("fit", "--system", "{arm}", "--method", "sysid", "--experiment", "indirect"),
    ("run", "--systems", "{arm}", "--methods", "sysid", "--out", "{folder}/ran"),
    ("residual", "--system", "{arm}", "--method", "sysid"),
])
def test_startup_refused_measured_arm_file(benchmark, files, command):
    benchmark.group = "startup"
    benchmark.extra_info["startup"] = f"a refused measured-arm file (bench {command[0]})"
    argv = [w.format(arm=f"measured:{files / 'arm.toml'}", folder=files) for w in command]
    benchmark.pedantic(_run("-m", "bench", *argv, code=2), rounds=3, iterations=1)
