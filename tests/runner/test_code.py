"""A record's code hash covers the files its run's result depends on (bench.runner.sources)."""

from __future__ import annotations

from pathlib import Path

from bench.core.fileio import file_digest
from bench.runner.sources import code_files


def test_a_method_that_is_a_package_is_hashed_with_every_module_of_it():
    files = code_files("syrenets", "double_pendulum")
    for module in ("config", "layer_terms", "network", "training", "multistart", "equations", "method"):
        assert f"methods/syrenets/{module}.py" in files
    assert {"methods/base.py", "methods/torch_method.py", "systems/double_pendulum.py"} <= set(files)


def test_a_method_in_one_module_is_hashed_with_its_bases_only():
    files = code_files("sparse", "double_pendulum")
    assert "methods/sparse.py" in files and "methods/base.py" in files
    assert not any(name.startswith("methods/syrenets/") or name == "methods/mlp.py" for name in files)


def test_what_every_run_imports_is_its_code_however_deep():
    """The data format, the tuning and the scoring are imported by the runner, not by a method's class."""
    files = code_files("sparse", "double_pendulum")
    assert {"bench/core/data.py", "bench/evaluation/tuning.py", "bench/evaluation/scores.py",
            "bench/physics/regression.py", "methods/__init__.py", "bench/runner/stacked.py"} <= set(files)
    assert not any(name.startswith(("bench/cli/", "bench/reporting/", "bench/studies/")) for name in files)


def test_a_hybrids_code_is_its_residuals_and_its_priors_too():
    """An edited Gaussian process or SysId redoes the hybrids' runs; a loop prior's code is the loop's."""
    gp = code_files("standard+gp", "kuka_lwr4")
    assert {"methods/hybrid.py", "methods/gp.py", "methods/sysid.py", "bench/physics/feasible.py"} <= set(gp)
    assert "methods/delan.py" not in gp and not any(name.startswith("bench/residual/") for name in gp)
    loop = code_files("loop+gp", "kuka_lwr4")
    assert {"methods/gp.py", "bench/residual/prior.py", "bench/residual/loop.py"} <= set(loop)


def test_imports_are_read_from_the_source_relative_and_inside_functions(tmp_path):
    from bench.runner.provenance import PROJECT_ROOT
    from bench.runner.sources import imported

    source = tmp_path / "mine.py"
    source.write_text("import numpy\nfrom bench.core import errors\n\ndef f():\n    from bench.physics.regression import fit_columns\n"
                      "    import methods.sparse_torque as st\n")
    assert {p.relative_to(PROJECT_ROOT).as_posix() for p in imported(source)} == {
        "bench/__init__.py", "bench/core/__init__.py", "bench/core/errors.py", "bench/physics/__init__.py",
        "bench/physics/regression.py", "methods/__init__.py", "methods/sparse_torque.py"}


def test_relative_imports_resolve_from_the_modules_package(tmp_path, monkeypatch):
    from bench.runner import sources

    for name in ("bench/__init__.py", "bench/a/__init__.py", "bench/a/c.py", "bench/d.py", "bench/a/e/__init__.py"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text("")
    (tmp_path / "bench/a/b.py").write_text("from . import c\nfrom .e import thing\nfrom ..d import f\n")
    (tmp_path / "bench/a/__init__.py").write_text("from .c import g\n")
    monkeypatch.setattr(sources, "PROJECT_ROOT", tmp_path)
    assert {p.relative_to(tmp_path).as_posix() for p in sources.imported(tmp_path / "bench/a/b.py")} == {
        "bench/__init__.py", "bench/a/__init__.py", "bench/a/c.py", "bench/a/e/__init__.py", "bench/d.py"}
    assert {p.relative_to(tmp_path).as_posix() for p in sources.imported(tmp_path / "bench/a/__init__.py")} == {
        "bench/__init__.py", "bench/a/__init__.py", "bench/a/c.py"}


def test_a_plugin_is_the_code_of_the_runs_of_what_it_defines_only(tmp_path):
    """One edited plugin redoes its own method's records, not every method's of the matrix."""
    from bench.runner.sources import code_hash

    plugin = tmp_path / "mine.py"
    plugin.write_text(PLUGIN.format(value=1.0))
    mine, sysid = code_hash("toy_code_mine", "double_pendulum", (str(plugin),)), code_hash("sysid", "double_pendulum", (str(plugin),))
    assert str(plugin) in mine["files"] and str(plugin) not in sysid["files"]
    bare = code_hash("sysid", "double_pendulum")
    assert (sysid["hash"], sysid["files"]) == (bare["hash"], bare["files"]) and "plugins" not in bare
    assert sysid["plugins"] == {str(plugin): file_digest(plugin)}  # what a rerun checks before importing it
    plugin.write_text(PLUGIN.format(value=2.0))
    assert code_files("toy_code_mine", "double_pendulum", (str(plugin),))[str(plugin)] != mine["files"][str(plugin)]
    assert code_hash("sysid", "double_pendulum", (str(plugin),))["hash"] == sysid["hash"]


def test_a_robot_description_given_as_a_plugin_is_its_systems_code(tmp_path):
    from bench.runner.plugins import system_plugins
    from systems.urdf_arm import DATA_DIR

    import gzip

    urdf = tmp_path / "my_arm.urdf"
    urdf.write_bytes(gzip.decompress((DATA_DIR / "ur5_robot.urdf.gz").read_bytes()))
    (name,), plugins = system_plugins([f"urdf:{urdf}"])
    assert str(urdf.resolve()) in code_files("sysid", name, plugins)
    assert str(urdf.resolve()) not in code_files("sysid", "double_pendulum", plugins)


def test_a_shipped_measured_arms_file_recordings_and_urdf_are_its_runs_code():
    from systems import SYSTEMS

    files = code_files("sysid", "kuka_lwr4")
    sources = SYSTEMS["kuka_lwr4"].source_files()
    assert len(sources) >= 3 and any(s.endswith(".toml") for s in sources) and any("urdf" in s for s in sources)
    named = {str(Path(s).resolve().relative_to(Path(__file__).resolve().parents[2])) for s in sources}
    assert named <= set(files)
    assert not named & set(code_files("sysid", "double_pendulum"))


PLUGIN = '''
import numpy as np
from methods import METHODS, Method


@METHODS.add("toy_code_mine")
class Mine(Method):
    def _fit(self, train, experiment, progress):
        progress.step()

    def _get_state(self):
        return None

    def _set_state(self, state):
        pass

    def predict_lagrangian(self, data):
        return np.full(len(data), {value})

    def predict_torque(self, data):
        return np.zeros((len(data), data.dof))
'''
