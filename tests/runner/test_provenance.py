"""The processor's identity in provenance, from ``/proc/cpuinfo`` text."""

from hypothesis import given, strategies as st

from bench.runner.provenance import cpu_id, describe_cpu, machine, provenance

ZEN3 = """processor\t: 0
vendor_id\t: AuthenticAMD
cpu family\t: 25
model\t\t: 1
model name\t: AMD EPYC
stepping\t: 1
cpu MHz\t\t: 2445.406
flags\t\t: fpu sse2 avx fma avx2 bmi2

processor\t: 1
cpu family\t: 26
model\t\t: 2
flags\t\t: avx512f avx2
"""


def test_two_processors_of_one_generic_name_are_told_apart():
    assert describe_cpu(ZEN3) == "family 25 model 1 stepping 1, AVX2"
    zen5 = ZEN3.replace(": 25", ": 26").replace("avx2 bmi2", "avx2 bmi2 avx512f avx512dq")
    assert describe_cpu(zen5) == "family 26 model 1 stepping 1, AVX-512"


def test_arm_features_and_missing_fields():
    assert describe_cpu("processor : 0\nFeatures : fp asimd evtstrm\nCPU part : 0xd0c\n") == "ASIMD"
    assert describe_cpu("cpu MHz : 2445.4\nmodel : 7\n") == "model 7"
    assert describe_cpu("") == ""


@given(st.text())
def test_any_text_gives_one_line(text):
    out = describe_cpu(text)
    assert isinstance(out, str) and "\n" not in out


def test_provenance_carries_it():
    assert provenance()["cpu_id"] == cpu_id()


def test_machine_line_with_and_without_the_id():
    assert machine({"cpu": "AMD EPYC", "cpu_count": 2}) == "AMD EPYC (2 cores)"
    assert machine({"cpu": "AMD EPYC", "cpu_count": 2, "cpu_id": "family 25 model 1 stepping 1, AVX2"}) == (
        "AMD EPYC (family 25 model 1 stepping 1, AVX2; 2 cores)")


def test_an_unreadable_cpuinfo_gives_no_id_and_the_platform_name(monkeypatch):
    import platform

    from bench.runner import provenance as prov

    class Unreadable:
        def __init__(self, *_):
            pass

        def read_text(self, **_):
            raise PermissionError("/proc/cpuinfo")

    caches = (prov._cpuinfo, prov.cpu_id, prov.cpu_model)
    monkeypatch.setattr(prov, "Path", Unreadable)
    for f in caches:
        f.cache_clear()
    try:
        assert prov.cpu_id() == ""
        assert prov.cpu_model() == (platform.processor() or platform.machine())
        assert prov.machine(prov.provenance()).endswith(f"({prov.provenance()['cpu_count']} cores)")
    finally:
        monkeypatch.undo()
        for f in caches:
            f.cache_clear()
