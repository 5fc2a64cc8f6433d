"""Named configurations: what a method offers, how ``--config`` picks them
in a matrix, and what the records and tables say of them."""

from __future__ import annotations

import argparse
import json

import pytest

from bench.cli.parser import UsageError
from bench.cli.options import configurations
from bench.core.errors import ConfigError
from methods import METHODS
from tests.commandline import cli


def _args(*configs: str, smoke: bool = False) -> argparse.Namespace:
    return argparse.Namespace(configs=list(configs), smoke=smoke)


def test_every_named_configuration_builds_a_valid_method():
    for entry in METHODS.entries():
        if entry.available:
            for name in entry.obj.configuration_names():
                entry.obj(**entry.obj.configuration(name))  # a bad value or name raises ConfigError


def test_syrenets_offers_the_papers_the_authors_code_and_the_300_s_configurations():
    syrenets = METHODS["syrenets"]
    assert syrenets.configuration("public") == {"inputs": "q_qd_qdd", "replay": 16}
    assert syrenets.configuration("best-300s")["starts"] == 4
    assert syrenets.configuration("default") == {}
    with pytest.raises(ConfigError, match="syrenets has no configuration 'fast'; it offers default, smoke, paper"):
        syrenets.configuration("fast")


def test_a_name_alone_picks_it_for_the_methods_that_offer_it_and_a_method_prefix_wins():
    methods = ["syrenets", "mlp"]
    assert configurations(_args("paper"), methods) == {"syrenets": "paper", "mlp": "default"}
    assert configurations(_args("syrenets=public", "paper"), methods) == {"syrenets": "public", "mlp": "default"}
    assert configurations(_args("syrenets=public", smoke=True), methods) == {"syrenets": "public", "mlp": "smoke"}
    assert configurations(_args("smoke"), ["pysr"]) == {"pysr": "smoke"}  # an unavailable method still names its own


@pytest.mark.parametrize("given, message", [
    (("fast",), "--config fast: no method of this command offers it"),
    (("mlp=paper",), "--config mlp=paper: mlp offers default, smoke"),
    (("sysid=paper",), "'sysid' is not a method of this command"),
])
def test_a_configuration_nobody_offers_is_one_line(given, message):
    with pytest.raises(UsageError, match=message):
        configurations(_args(*given), ["syrenets", "mlp"])


def test_a_matrix_runs_a_named_configuration_with_sets_on_top_and_its_tables_name_it(tmp_path):
    out = tmp_path / "run"
    tiny = ["--set", "syrenets.layers=1", "--set", "syrenets.heads=2", "--set", "syrenets.latent=2",
            "--set", "syrenets.ae_hidden=4", "--set", "syrenets.head_hidden=4", "--set", "syrenets.eval_samples=16",
            "--set", "syrenets.refine=false"]
    r = cli("run", "--methods", "syrenets,sysid", "--experiments", "indirect", "--seeds", "0", "--steps", "2",
            "--n-train", "64", "--n-test", "32", "--workers", "1", "--no-rollout", "--config", "paper", *tiny,
            "--out", out)
    assert r.returncode == 0, r.stderr
    records = {json.loads(p.read_text())["method"]: json.loads(p.read_text()) for p in (out / "records").glob("*.json")}
    assert records["syrenets"]["spec"]["profile"] == "paper" and records["sysid"]["spec"]["profile"] == "default"
    assert records["syrenets"]["hyperparameters"]["contractive_probes"] == 0  # the configuration's value
    assert records["syrenets"]["hyperparameters"]["heads"] == 2  # and --set on top of it
    assert "configuration: default; syrenets: paper." in (out / "tables.md").read_text()
