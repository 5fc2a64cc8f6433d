"""One training step of the paper's 5x300 MLP Lagrangian at batch 32, indirect loss.

``ours``: the suite's batched Hessian-vector product by double backward
(:func:`bench.physics.dynamics.euler_lagrange`).

Baselines, per sample and vectorised with ``torch.func.vmap``:

* ``vmap_jacfwd_lnn``: the formulation of Lagrangian Neural Networks
  (Cranmer et al., 2020), with the Hessian blocks of L each taken by
  ``jacfwd(jacrev(.))``: ``tau = H_{qd qd} qdd + H_{qd q} qd - dL/dq``;
* ``vmap_jacfwd_hessian``: one full Hessian of L over (q, qd) per sample by
  ``jacfwd(jacrev(.))``, then its blocks.

All use the same fused Adam, float64 and one thread. Run with ``make benchmark``.
"""

from __future__ import annotations

import pytest
import torch
from torch.func import functional_call, jacfwd, jacrev, vmap

from bench.physics.dynamics import euler_lagrange
from methods.mlp import LagrangianMLP

pytestmark = pytest.mark.benchmark

DOF, BATCH = 2, 32


@pytest.fixture(autouse=True)
def one_thread():
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def _setup(dtype=torch.float64):
    torch.manual_seed(0)
    model = LagrangianMLP(DOF, 300, 5).to(dtype)
    opt = torch.optim.Adam(model.parameters(), lr=1e-3, fused=True)
    g = torch.Generator().manual_seed(1)
    q, qd, qdd, target = (torch.rand(BATCH, DOF, generator=g, dtype=dtype) * 3 - 1.5 for _ in range(4))
    return model, opt, (q, qd, qdd, target)


def tau_lnn(model):
    def L(p, q, qd):
        return functional_call(model, p, (q.unsqueeze(0), qd.unsqueeze(0))).squeeze(0)

    def one(p, q, qd, qdd):
        h_qdqd = jacfwd(jacrev(L, argnums=2), argnums=2)(p, q, qd)
        h_qdq = jacfwd(jacrev(L, argnums=2), argnums=1)(p, q, qd)
        dL_dq = jacrev(L, argnums=1)(p, q, qd)
        return h_qdqd @ qdd + h_qdq @ qd - dL_dq

    batched = vmap(one, in_dims=(None, 0, 0, 0))
    return lambda q, qd, qdd: batched(dict(model.named_parameters()), q, qd, qdd)


def tau_hessian(model):
    def L(p, z):
        return functional_call(model, p, (z[:DOF].unsqueeze(0), z[DOF:].unsqueeze(0))).squeeze(0)

    def one(p, q, qd, qdd):
        z = torch.cat([q, qd])
        grad = jacrev(L, argnums=1)(p, z)
        hess = jacfwd(jacrev(L, argnums=1), argnums=1)(p, z)
        return hess[DOF:, DOF:] @ qdd + hess[DOF:, :DOF] @ qd - grad[:DOF]

    batched = vmap(one, in_dims=(None, 0, 0, 0))
    return lambda q, qd, qdd: batched(dict(model.named_parameters()), q, qd, qdd)


def tau_ours(model):
    return lambda q, qd, qdd: euler_lagrange(model, q, qd, qdd, create_graph=True)


FORMULATIONS = {"ours": tau_ours, "vmap_jacfwd_lnn": tau_lnn, "vmap_jacfwd_hessian": tau_hessian}


def test_formulations_agree():
    model, _, (q, qd, qdd, _) = _setup()
    ref = tau_ours(model)(q, qd, qdd)
    for name, make in FORMULATIONS.items():
        torch.testing.assert_close(make(model)(q, qd, qdd), ref, rtol=1e-10, atol=1e-10, msg=name)


@pytest.mark.parametrize("name", list(FORMULATIONS))
def test_training_step(benchmark, name):
    benchmark.group = "mlp-5x300-indirect-step-b32-f64"
    model, opt, (q, qd, qdd, target) = _setup()
    tau = FORMULATIONS[name](model)

    def step():
        opt.zero_grad(set_to_none=True)
        loss = ((tau(q, qd, qdd) - target) ** 2).mean()
        loss.backward()
        opt.step()

    for _ in range(5):
        step()
    benchmark.pedantic(step, rounds=60, iterations=1, warmup_rounds=2)
