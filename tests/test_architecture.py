"""The layers hold: import-linter's contracts in pyproject.toml (imports point
down the layers, no cycles between sibling modules, only the scorers open the test
split), and what they do not
cover, measured from the source by :mod:`tests.architecture`."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests import architecture

ROOT = Path(__file__).resolve().parent.parent
LINT = shutil.which("lint-imports", path=str(Path(sys.executable).parent))


def lint(cwd: Path, pythonpath: Path | None = None) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    if pythonpath is not None:
        env["PYTHONPATH"] = str(pythonpath)
    return subprocess.run([LINT, "--no-cache", "--config", str(ROOT / "pyproject.toml")], cwd=cwd,
                          capture_output=True, text=True, env=env)


@pytest.fixture(scope="module")
def measured():
    return architecture.measure()


@pytest.mark.skipif(LINT is None, reason="import-linter is not installed (pip install -e '.[test]')")
def test_the_import_contracts_are_kept():
    r = lint(ROOT)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "Contracts: 3 kept, 0 broken." in r.stdout


@pytest.mark.skipif(LINT is None, reason="import-linter is not installed (pip install -e '.[test]')")
@pytest.mark.parametrize("module, imported, contract", [
    ("bench/core/data.py", "bench.runner.records", "Imports point down the layers"),
    ("bench/evaluation/tuning.py", "bench.core.scoring", "Only the scorers open the test split"),  # a choice
], ids=["upward", "a-chooser-opens-the-test-split"])
def test_an_import_against_a_contract_breaks_it(tmp_path, module, imported, contract):
    for package in architecture.PACKAGES:
        shutil.copytree(ROOT / package, tmp_path / package, ignore=shutil.ignore_patterns("__pycache__", "data"))
    path = tmp_path / module
    package, _, name = imported.rpartition(".")
    path.write_text(path.read_text() + f"\nfrom {package} import {name}  # noqa: E402,F401  (on purpose)\n")
    r = lint(tmp_path, pythonpath=tmp_path)
    assert r.returncode == 1, r.stdout + r.stderr
    assert f"{contract} BROKEN" in r.stdout
    assert f"{module[:-3].replace('/', '.')} -> {imported}" in r.stdout


def test_bench_holds_only_its_entry_points_and_the_layers():
    assert sorted(p.name for p in (ROOT / "bench").glob("*.py")) == ["__init__.py", "__main__.py"]
    layers = sorted(p.name for p in (ROOT / "bench").iterdir() if (p / "__init__.py").is_file())
    assert layers == ["cli", "core", "evaluation", "physics", "reporting", "residual", "runner", "studies", "tools"]


def test_no_module_cycles_and_no_imports_hidden_in_functions(measured):
    assert measured["module cycles"] == []
    assert measured["cycles between packages (methods, systems, each of bench's subpackages or flat modules)"] == []
    # optional heavy dependencies may still be imported late; the suite's own modules may not
    assert [f"{i.importer}:{i.line} {i.target}" for i in measured["in-function imports of suite modules"]] == []


def test_methods_and_systems_use_only_the_core_and_the_physics_of_bench(measured):
    assert measured["imports from methods/ or systems/ into bench outside bench.core and bench.physics"] == []


def test_the_repository_root_holds_only_the_layouts_files():
    # a stray file at the root (a shell's error output, a user's run) is committed by accident, not by design
    try:
        tracked = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    top = {line.split("/", 1)[0] for line in tracked.splitlines() if line}
    assert top <= {".ci", ".gitignore", "LICENSE", "Makefile", "README.md", "pyproject.toml",
                   "bench", "docs", "methods", "results", "systems", "tests"}, sorted(top)


def test_only_the_scoring_module_opens_the_sealed_gate():
    # the import contract guards who may import bench.core.scoring; this guards the gate it opens and the store
    # of the targets it keeps apart
    for name, modules in (("_GATE", ["bench/core/scoring.py", "bench/core/sealed.py"]),
                          ("_HELD", ["bench/core/sealed.py"])):
        word = re.compile(rf"(?<![A-Za-z0-9_]){name}\b")
        touching = sorted(str(p.relative_to(ROOT)) for package in architecture.PACKAGES
                          for p in (ROOT / package).rglob("*.py") if word.search(p.read_text()))
        assert touching == modules, name


def _scorers() -> set[str]:
    import tomllib

    contracts = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]["contracts"]
    (gate,) = [c for c in contracts if c["name"] == "Only the scorers open the test split"]
    return set(gate["allowed_importers"])


def test_the_gate_has_one_import_path_checked_by_identity():
    """Only the scorers the contract names hold the gate (``scoring``, ``opened``, the scoring module or the
    gate itself) among their names: a module that took it from a scorer (``from bench.residual.rollouts import
    scoring``), past the contract, holds the same object and is found."""
    import importlib
    import pkgutil

    from bench.core import scoring, sealed

    gate = {id(scoring): "bench.core.scoring", id(scoring.scoring): "scoring", id(scoring.opened): "opened",
            id(sealed._GATE): "_GATE", id(sealed._HELD): "_HELD"}
    allowed = _scorers() | {"bench.core.scoring", "bench.core.sealed"}
    holders = {}
    for package in architecture.PACKAGES:
        root = importlib.import_module(package.replace("/", "."))
        for info in pkgutil.walk_packages(root.__path__, root.__name__ + "."):
            if info.name.endswith(".__main__"):  # running it is its import
                continue
            module = importlib.import_module(info.name)
            held = sorted(gate[id(v)] for k, v in vars(module).items()
                          if id(v) in gate and getattr(v, "__name__", None) != f"{info.name}.{k}")  # a package's own
            if held:
                holders[info.name] = held
    assert {m for m in holders if m not in allowed} == set(), holders
    assert {"bench.residual.rollouts", "bench.tools.stack_score"} <= set(holders)  # the check sees the scorers


#: what a run leaves beside its records, which the repository does not keep (.gitignore)
DEBRIS = re.compile(r"(^results/.*/logs/|(^|/)\.lock$|\.phase$|\.call\.json$)")


def test_no_run_debris_is_committed():
    try:
        tracked = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    assert [f for f in tracked.splitlines() if DEBRIS.search(f)] == []


@pytest.mark.xdist_group("torch.compile")
def test_the_suites_groups_each_run_on_one_worker(request):
    """``make test`` runs with ``--dist loadgroup``, which sends the tests of one ``xdist_group`` (those that
    compile, those that start a Dask cluster) to one worker by adding the group to each test's id; where a
    version of pytest or pytest-xdist stops doing so, the group's tests are spread over the workers and each
    worker compiles, or starts a cluster, again."""
    if not getattr(request.config.option, "loadgroup", False):
        pytest.skip("not run with --dist loadgroup")
    assert request.node.nodeid.endswith("@torch.compile"), request.node.nodeid
