"""``--device cpu|cuda|auto`` on run, fit, rerun and residual: a GPU that is not
there is refused in one line before any work; ``auto`` is the CPU here; the
record says where its fit trained; methods that are not torch methods say so."""

from __future__ import annotations

from bench.core.budget import Budget
import json

import pytest
import torch

from bench.cli.options import device
from bench.core.data import generate
from bench.residual import residual_loop
from bench.runner.records import read_record
from bench.runner.spec import RunSpec
from systems import get_system
from tests.commandline import cli

SMALL = ("--n-train", "128", "--n-test", "32", "--steps", "3", "--smoke")


@pytest.fixture
def no_gpu(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)


@pytest.mark.parametrize("command", [
    ("fit", "--system", "double_pendulum", "--method", "mlp", "--experiment", "indirect", *SMALL),
    ("run", "--methods", "mlp,sparse", "--experiments", "indirect", "--seeds", "0", *SMALL),
    ("residual", "--system", "kuka_lwr4", "--method", "sysid", "--steps", "1"),
])
def test_a_gpu_that_is_not_there_is_refused_in_one_line_and_nothing_is_written(command, tmp_path, no_gpu):
    out = tmp_path / "out"
    extra = ("--out", out) if command[0] == "run" else ("--json", out)
    r = cli(*command, "--device", "cuda", *extra)
    assert r.returncode == 2 and not out.exists()
    assert r.stderr.count("\n") == 1 and "--device cuda" in r.stderr and "sees no CUDA device" in r.stderr


def test_auto_is_the_cpu_without_a_gpu_and_the_record_says_where_the_fit_trained(tmp_path, no_gpu):
    out = tmp_path / "fit.json"
    r = cli("fit", "--system", "double_pendulum", "--method", "mlp", "--experiment", "indirect", *SMALL,
            "--device", "auto", "--json", out)
    assert r.returncode == 0, r.stderr
    record = json.loads(out.read_text())
    assert record["spec"]["device"] == "cpu" and record["details"]["device"]["type"] == "cpu"
    assert record["details"]["device"]["name"] == record["provenance"]["cpu"]  # the processor's model
    # the rerun keeps the recorded device, and gives the same numbers
    again = cli("rerun", out, "--json", tmp_path / "again.json")
    assert again.returncode == 0 and "the same up to" in again.stdout
    assert read_record(tmp_path / "again.json").spec["device"] == "cpu"


def test_a_record_written_before_runs_named_their_device_stands_for_a_cpu_run():
    spec = RunSpec("double_pendulum", "mlp", "indirect", 0, None, steps=3)
    older = {k: v for k, v in spec.to_dict().items() if k != "device"}
    assert RunSpec.from_dict(older).to_dict() == spec.to_dict()  # what a resume compares (bench.runner.matrix.stale)


def test_methods_that_are_not_torch_methods_say_once_that_they_run_on_the_cpu(monkeypatch, capsys):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    assert device("auto", ["mlp", "sparse", "mggp", "syrenets"]) == "cuda"
    out = capsys.readouterr().out
    assert out == "--device auto: sparse, mggp are not torch methods and run on the CPU\n"
    assert device("cpu", ["sparse"]) == "cpu" and capsys.readouterr().out == ""


def test_the_residual_loop_says_where_its_fits_trained():
    s = get_system("double_pendulum")
    train, test = generate(s, 400, 0), generate(s, 100, 1)
    out = residual_loop("mlp", train, test, budget=Budget(steps=5), hyperparameters={"hidden": 8, "layers": 1}, report=lambda _: None,
                        device="cpu")
    assert out.device["type"] == "cpu" and out.device["name"] and out.to_json()["details"]["device"] == out.device

