"""The contract tests: every registered system, and every registered method on
every system and experiment, pass the checks of :mod:`tests.contract`."""

from __future__ import annotations

import pytest

from bench.core.data import generate
from methods import METHODS
from systems import SYSTEMS
from bench.core.scoring import opened
from tests.contract import check_method, check_system, one_system_per_kind, suite_entries

SUITE_METHODS = [n for n in suite_entries(METHODS, "methods") if METHODS.entry(n).available]
SUITE_SYSTEMS = suite_entries(SYSTEMS, "systems")
#: the systems a method's fit is checked on its device on, and its expression written out (see one_system_per_kind)
DEVICE_SYSTEMS = one_system_per_kind(SUITE_SYSTEMS)


def test_the_device_check_covers_each_kind_of_data():
    assert len(DEVICE_SYSTEMS) == 3 and {SYSTEMS[n].simulated for n in DEVICE_SYSTEMS} == {True, False}


@pytest.mark.parametrize("name", SUITE_SYSTEMS)
def test_system_contract(name):
    check_system(SYSTEMS[name]())


@pytest.fixture(scope="module")
def datasets():
    out = {}
    for name in SUITE_SYSTEMS:
        system = SYSTEMS[name]()
        if system.simulated:
            out[name] = (generate(system, 256, 0), generate(system, 128, 1000))
        else:
            train, test = system.load("train"), opened(system.load("test"))
            out[name] = (train.subset(slice(0, 256)), test.subset(slice(0, 128)))
    return out


@pytest.mark.parametrize("system_name", SUITE_SYSTEMS)
@pytest.mark.parametrize("experiment", ["direct", "indirect"])
@pytest.mark.parametrize("method_name", SUITE_METHODS)
def test_method_contract(method_name, experiment, system_name, datasets):
    cls = METHODS[method_name]
    reason = cls.not_applicable_reason(experiment, SYSTEMS[system_name]()) or (
        SYSTEMS[system_name].not_applicable if experiment not in SYSTEMS[system_name].experiments else None)
    if reason:
        pytest.skip(reason)
    check_method(cls, *datasets[system_name], experiment, device=system_name in DEVICE_SYSTEMS)

