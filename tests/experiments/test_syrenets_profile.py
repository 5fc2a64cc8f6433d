"""The heads' product timed with and without torch.profiler."""

from __future__ import annotations

import argparse
import math

import pytest
import torch

from bench.experiments import syrenets_profile


def test_the_timers_catch_every_product_of_w2s_shape_forward_and_backward():
    W = torch.randn(3, 5, 4, dtype=torch.float64, requires_grad=True)
    h = torch.randn(3, 4, dtype=torch.float64, requires_grad=True)
    other = torch.randn(5, 4, dtype=torch.float64, requires_grad=True)
    timer = syrenets_profile._ProductTimer(W.shape)
    with timer:
        (other * other).sum().backward()  # another shape: not timed
        assert timer.forward == 0.0 and timer.backward == 0.0
        (W * h.unsqueeze(1)).sum().backward()
    assert timer.forward > 0.0 and timer.backward > 0.0
    # the product is unchanged by the timing
    torch.testing.assert_close(W.grad, h.unsqueeze(1).expand_as(W).detach())


@pytest.mark.slow
def test_a_short_run_writes_one_row_per_mode(tmp_path):
    out = tmp_path / "profile.md"
    args = argparse.Namespace(steps=2, rounds=1, out=out, invocation="python -m bench syrenets-profile")
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
