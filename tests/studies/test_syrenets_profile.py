"""Where SyReNets' step spends its time, and the heads' product with and without torch.profiler."""

from __future__ import annotations

import argparse
import math
import re

import pytest
import torch

from bench.core.data import generate
from bench.studies import syrenets_profile
from methods import METHODS
from methods.syrenets.network import HeadsOutput
from systems import get_system


def _small_method():
    train = generate(get_system("double_pendulum"), 64, 0, cache=False)
    m = METHODS["syrenets"](layers=2, heads=3, latent=4, ae_hidden=8, head_hidden=8)
    m.seed, m.dof = 0, train.dof
    m._setup(train)
    return m, {k: v[:16] for k, v in train.tensors().items()}


def test_the_timers_catch_the_heads_output_layer_forward_and_backward_and_put_it_back():
    forward, backward = HeadsOutput.forward, HeadsOutput.backward
    W = torch.randn(3, 5, 4, dtype=torch.float64, requires_grad=True)
    h = torch.randn(3, 4, dtype=torch.float64, requires_grad=True)
    other = torch.randn(5, 4, dtype=torch.float64, requires_grad=True)
    with syrenets_profile._ProductTimer() as timer:
        (other * other).sum().backward()  # not the heads' layer: not timed
        assert timer.forward == 0.0 and timer.backward == 0.0
        HeadsOutput.apply(W, h).sum().backward()
        assert timer.forward > 0.0 and timer.backward > 0.0
    # the layer is unchanged by the timing, and restored afterwards
    torch.testing.assert_close(W.grad, h.unsqueeze(1).expand_as(W).detach())
    assert (HeadsOutput.forward, HeadsOutput.backward) == (forward, backward)


def test_the_operators_timed_alone_are_those_of_one_step():
    """The matrix products and Adam's updates timed alone are as many as
    torch.profiler counts in a step (the heads' layer's batched products,
    one a layer, counted with the layer), and every group takes some time."""
    m, batch = _small_method()
    m.train_step(batch, "direct")
    alone = syrenets_profile.operators_alone(m, batch, repeat=1)
    assert list(alone) == list(syrenets_profile.PARTS)
    with torch.profiler.profile(activities=[torch.profiler.ProfilerActivity.CPU]) as prof:
        m.train_step(batch, "direct")
    counts = {e.key: e.count for e in prof.key_averages()}
    assert alone["matrix products"][1] + 2 == sum(counts.get(f"aten::{op}", 0) for op in ("mm", "addmm", "bmm"))
    assert alone["Adam's fused update"][1] == counts["aten::_fused_adam_"] == 2  # two parameter groups
    # per layer, forward: a product and a sum; backward: a product and a
    # batched product (and the gradient's hand-over to the weights)
    assert alone["heads' output layer"][1] >= 2 * (2 + 2)
    assert all(ms > 0 for ms, _ in alone.values())


@pytest.mark.slow
def test_a_short_run_writes_one_row_per_mode_and_where_the_time_goes(tmp_path):
    out = tmp_path / "profile.md"
    args = argparse.Namespace(steps=2, rounds=1, out=out, compiled=False, invocation="python -m bench study syrenets-profile")
    assert syrenets_profile.main(args) == 0
    cells = [[c.strip() for c in line.strip("|").split("|")] for line in out.read_text().splitlines()
             if line.startswith("| ")]
    rows = {c[0]: c for c in cells if c[0] in syrenets_profile.MODES}
    assert set(rows) == set(syrenets_profile.MODES)
    for mode, cells_ in rows.items():
        assert float(cells_[1]) > 0 and float(cells_[4]) >= 0
        assert (cells_[2] == "") == (mode == "plain")
    assert [c[0] for c in cells if c[0].isdigit()] == ["1"]  # one row per round
    assert float(rows["profiler"][2]) > 0 and float(rows["timers"][2]) > 0
    assert not math.isnan(float(rows["timers"][2]))
    # where the plain step's time goes: the parts add up to the operators, and
    # those and the time between them to the plain step
    parts = {c[0]: c for c in cells if c[0] in syrenets_profile.PARTS}
    assert set(parts) == set(syrenets_profile.PARTS)
    total = next(c for c in cells if c[0] == "all operators, each alone")
    assert sum(float(c[2]) for c in parts.values()) == pytest.approx(float(total[2]), abs=0.02)
    assert sum(int(c[1]) for c in parts.values()) == int(total[1])
    between = next(c for c in cells if c[0] == "between the operators")
    assert float(total[2]) + float(between[2]) == pytest.approx(float(rows["plain"][1]), abs=0.02)


class _Event:
    def __init__(self, key, self_us, count, flops=0):
        self.key, self.self_cpu_time_total, self.count, self.flops = key, self_us, count, flops


def test_the_compiled_steps_profile_groups_adam_the_matrix_products_and_the_generated_kernels():
    events = [
        _Event("aten::_fused_adam_", 2400.0, 4),
        _Event("aten::mm", 6000.0, 20, 3e8), _Event("aten::addmm", 2000.0, 10, 1e8), _Event("aten::bmm", 0.0, 0),
        _Event("graph_0_cpp_fused_softplus_5", 600.0, 8), _Event("graph_1_cpp_fused_cat_2", 1400.0, 2),
        _Event("## Call CompiledFxGraph abc ##", 9000.0, 2), _Event("aten::add_", 500.0, 66),
        _Event("my_graph_0_cpp_fused_x", 100.0, 2),  # not a generated kernel's name
    ]
    parts, kernels, flops = syrenets_profile.compiled_parts(events, steps=2)
    assert list(parts) == list(syrenets_profile.COMPILED_PARTS)
    assert parts["Adam's fused update"] == (1.2, 2)
    assert parts["matrix products"] == (4.0, 15)
    assert parts["generated kernels"] == (1.0, 5)
    assert kernels == [(0.7, 1, "graph_1_cpp_fused_cat_2"), (0.3, 4, "graph_0_cpp_fused_softplus_5")]
    assert flops == 2e8  # the matrix products' only


@pytest.mark.slow
def test_a_short_compiled_profile_adds_up_to_the_plain_step(tmp_path):
    out = tmp_path / "compiled.md"
    args = argparse.Namespace(steps=3, rounds=1, out=out, compiled=True,
                              invocation="python -m bench study syrenets-profile --compiled")
    assert syrenets_profile.main(args) == 0
    cells = [[c.strip() for c in line.strip("|").split("|")] for line in out.read_text().splitlines()
             if line.startswith("| ")]
    rows = {c[0]: c for c in cells}
    for part in syrenets_profile.COMPILED_PARTS:
        assert float(rows[part][2]) > 0
    assert float(rows["matrix products"][1]) > 0 and float(rows["generated kernels"][1]) > 0
    parts = sum(float(rows[p][2]) for p in (*syrenets_profile.COMPILED_PARTS, "everything else"))
    assert parts == pytest.approx(float(rows["plain step"][2]), abs=0.02)
    assert any(c[2].startswith("`graph_") for c in cells if len(c) == 3)  # the slowest kernels are listed
    gflops = re.search(r"do (\d+) MFLOP a step .*, ([\d.]+) GFLOP/s", out.read_text())
    assert gflops and int(gflops[1]) > 0 and float(gflops[2]) > 0
