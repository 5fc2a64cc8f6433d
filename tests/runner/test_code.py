"""A record's code hash covers the files that define its method and system."""

from __future__ import annotations

from bench.runner.code import code_files


def test_a_method_that_is_a_package_is_hashed_with_every_module_of_it():
    files = code_files("syrenets", "double_pendulum")
    for module in ("config", "candidates", "network", "training", "multistart", "equations", "method"):
        assert f"methods/syrenets/{module}.py" in files
    assert {"methods/base.py", "methods/torch_method.py", "systems/double_pendulum.py"} <= set(files)


def test_a_method_in_one_module_is_hashed_with_its_bases_only():
    files = code_files("sparse", "double_pendulum")
    assert "methods/sparse.py" in files and "methods/base.py" in files
    assert not any(name.startswith("methods/syrenets/") or name == "methods/mlp.py" for name in files)
