"""One SyReNets training step (3 layers x 12 heads, float64, one thread).

Configurations:

* ``public``: the authors' public configuration, 6 inputs (q, qd, qdd) and a
  batch of 32 plus 16 replayed samples. On this kind of machine the public
  implementation was measured at 6.5 steps/s (direct) and 1.5 steps/s
  (indirect); the summary prints our figure as a multiple of those.
* ``default``: the suite's default, inputs (q, qd) and batch 32.

Each with the exact closed-form contractive penalty (``exact``) and the
default one-probe Hutchinson estimate (``hutchinson``).
"""

from __future__ import annotations

import pytest
import torch

from bench.core.data import generate
from bench.studies.syrenets_speed import CONFIGS
from methods import METHODS
from systems import get_system

pytestmark = pytest.mark.benchmark

PUBLIC_STEPS_PER_S = {"direct": 6.5, "indirect": 1.5}


@pytest.fixture(scope="module")
def train():
    return generate(get_system("double_pendulum"), 256, 0)


@pytest.mark.parametrize("penalty", ["exact", "hutchinson"])
@pytest.mark.parametrize("config", list(CONFIGS))
@pytest.mark.parametrize("experiment", ["direct", "indirect"])
def test_training_step(benchmark, train, experiment, config, penalty):
    torch.set_num_threads(1)
    benchmark.group = f"syrenets-step-{experiment}"
    cfg = dict(CONFIGS[config]["hyperparameters"], contractive_probes=0 if penalty == "exact" else 1)
    m = METHODS["syrenets"](**cfg)
    m.seed, m.dof = 0, train.dof
    m._setup(train)
    t = train.tensors()
    batch = {k: v[:CONFIGS[config]["batch"]] for k, v in t.items()}
    for _ in range(3):
        m.train_step(batch, experiment)
    benchmark.pedantic(m.train_step, args=(batch, experiment), rounds=40, iterations=1, warmup_rounds=2)
    steps = 1.0 / benchmark.stats.stats.mean
    benchmark.extra_info["steps_per_s"] = steps
    if config == "public":
        benchmark.extra_info["x_public"] = steps / PUBLIC_STEPS_PER_S[experiment]
