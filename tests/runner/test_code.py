"""A record's code hash covers the files that define its method and system."""

from __future__ import annotations

from bench.runner.spec import code_files


def test_a_method_that_is_a_package_is_hashed_with_every_module_of_it():
    files = code_files("syrenets", "double_pendulum")
    for module in ("config", "layer_terms", "network", "training", "multistart", "equations", "method"):
        assert f"methods/syrenets/{module}.py" in files
    assert {"methods/base.py", "methods/torch_method.py", "systems/double_pendulum.py"} <= set(files)


def test_a_method_in_one_module_is_hashed_with_its_bases_only():
    files = code_files("sparse", "double_pendulum")
    assert "methods/sparse.py" in files and "methods/base.py" in files
    assert not any(name.startswith("methods/syrenets/") or name == "methods/mlp.py" for name in files)


def test_a_plugin_is_the_code_of_the_runs_of_what_it_defines_only(tmp_path):
    """One edited plugin redoes its own method's records, not every method's of the matrix."""
    from bench.runner.spec import code_hash

    plugin = tmp_path / "mine.py"
    plugin.write_text(PLUGIN.format(value=1.0))
    mine, sysid = code_hash("toy_code_mine", "double_pendulum", (str(plugin),)), code_hash("sysid", "double_pendulum", (str(plugin),))
    assert str(plugin) in mine["files"] and str(plugin) not in sysid["files"]
    assert sysid == code_hash("sysid", "double_pendulum")
    plugin.write_text(PLUGIN.format(value=2.0))
    assert code_files("toy_code_mine", "double_pendulum", (str(plugin),))[str(plugin)] != mine["files"][str(plugin)]
    assert code_hash("sysid", "double_pendulum", (str(plugin),)) == sysid


def test_a_robot_description_given_as_a_plugin_is_its_systems_code(tmp_path):
    from bench.runner.plugins import system_plugins
    from systems.urdf_arm import DATA_DIR

    import gzip

    urdf = tmp_path / "my_arm.urdf"
    urdf.write_bytes(gzip.decompress((DATA_DIR / "ur5_robot.urdf.gz").read_bytes()))
    (name,), plugins = system_plugins([f"urdf:{urdf}"])
    assert str(urdf.resolve()) in code_files("sysid", name, plugins)
    assert str(urdf.resolve()) not in code_files("sysid", "double_pendulum", plugins)


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
