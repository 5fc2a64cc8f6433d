"""DeLaN: its structure, its own derivatives against autograd, and that it learns."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from bench.core.data import Dataset, generate, mse
from bench.physics.dynamics import euler_lagrange
from bench.evaluation.forces import decomposition
from methods import METHODS
from methods.delan import DeepLagrangian, DeLaNConfig
from bench.core.budget import Budget

# The tests that compile share one test process (``make test`` runs pytest with --dist loadgroup): torch's
# compiler starts once there, and a graph compiled for a shape is compiled once for all of them
pytestmark = pytest.mark.xdist_group("torch.compile")


@pytest.mark.parametrize("activation", ["softplus", "tanh", "relu"])
@pytest.mark.parametrize("diagonal", ["softplus", "relu"])
@pytest.mark.parametrize("dof", [1, 2, 4])
@pytest.mark.parametrize("potential", ["separate", "shared"])
def test_its_own_derivatives_give_the_torques_autograd_gives(activation, diagonal, dof, potential):
    torch.manual_seed(dof)
    config = DeLaNConfig(activation=activation, diagonal=diagonal, diagonal_bias_init=0.3, output_gain=1.0,
                         potential=potential)
    net = DeepLagrangian(dof, config).double()
    q, qd, qdd = (torch.randn(64, dof, dtype=torch.float64) for _ in range(3))
    own = euler_lagrange(net, q, qd, qdd)  # the model's tangent
    generic = euler_lagrange(net.forward, q, qd, qdd)  # two reverse passes
    assert torch.allclose(own, generic, rtol=1e-10, atol=1e-10)
    assert generic.abs().max() > 0.1  # not a vacuous match


def test_the_mass_matrix_is_positive_definite_by_construction():
    torch.manual_seed(0)
    net = DeepLagrangian(3, DeLaNConfig(output_gain=3.0, hidden_gain=3.0)).double()
    H, _ = net.parts(torch.randn(500, 3, dtype=torch.float64) * 5)
    eig = torch.linalg.eigvalsh(H)
    # at least epsilon, within eigvalsh's rounding (a few ulps of the largest eigenvalue)
    assert (eig[:, 0] >= 0.01 - 16 * torch.finfo(torch.float64).eps * eig[:, -1]).all()


@pytest.mark.long
def test_delan_learns_the_double_pendulum_from_torques(double_pendulum):
    """Eager: the compiled loss and its gradients are the eager ones (the test below), and a fit of 1,500 steps
    is over before compiling would pay for itself (its record's ``prepare_seconds``)."""
    train, test = generate(double_pendulum, 2048, 0), generate(double_pendulum, 512, 1000)
    m = METHODS["delan"](eval_samples=512, compile=False).fit(train, "indirect", 0, budget=Budget(steps=1500))
    assert mse(m.predict(test), test.tau) / np.var(test.tau) < 0.01
    # its learned parts add up to its torque, and its mass matrix is the model's H
    parts = decomposition(m, test)
    np.testing.assert_allclose(sum(parts.values()), m.predict(test), rtol=1e-5, atol=1e-4)
    H = m.mass_matrix(test.q[:16])
    np.testing.assert_allclose(np.einsum("bij,bj->bi", H, test.qdd[:16]), parts["inertial"][:16], rtol=1e-4, atol=1e-4)


def test_delan_learns_the_double_pendulums_lagrangian_directly(double_pendulum):
    train, test = generate(double_pendulum, 2048, 0), generate(double_pendulum, 512, 1000)
    assert abs(train.L.mean()) > 10  # far from V's initial constant: what the start at the data's level is for
    m = METHODS["delan"](eval_samples=512).fit(train, "direct", 0, budget=Budget(steps=1500))
    assert mse(m.predict(test), test.L) / np.var(test.L) < 0.01


def test_the_warm_up_raises_the_rate_linearly_then_holds_it():
    from methods.torch_method import Warmup

    optimizer = torch.optim.Adam([torch.nn.Parameter(torch.zeros(2))], lr=1e-2)
    warmup, rates = Warmup(optimizer, 4), []
    for _ in range(6):
        rates.append(optimizer.param_groups[0]["lr"])
        warmup.step(0.0)
    assert rates == pytest.approx([2.5e-3, 5e-3, 7.5e-3, 1e-2, 1e-2, 1e-2])


def test_the_public_configuration_is_the_authors_optimiser():
    method = METHODS["delan"](**METHODS["delan"].configuration("public"))
    h = method.hyperparameters()
    assert (h["lr"], h["amsgrad"], h["batch_size"], h["warmup"], h["potential"]) == (5e-4, True, 512, 0, "shared")
    assert method.make_scheduler(torch.optim.Adam([torch.nn.Parameter(torch.zeros(1))], lr=5e-4)) is None


def test_a_fitted_network_is_evaluated_in_float64_and_a_warm_start_trains_in_float32(double_pendulum):
    train = generate(double_pendulum, 256, 0)
    m = METHODS["delan"](**METHODS["delan"].smoke_config()).fit(train, "indirect", 0, budget=Budget(steps=5))
    assert m.dtype == torch.float64 and all(p.dtype == torch.float64 for p in m.model.parameters())
    before = m.predict(train)
    m.fit(train, "indirect", 0, budget=Budget(steps=5), warm_start=True)  # Adam's float32 state would refuse float64 weights
    assert all(p.dtype == torch.float64 for p in m.model.parameters())
    assert not np.allclose(m.predict(train), before)  # it trained on


def test_the_compiled_loss_and_its_gradients_are_the_eager_ones(double_pendulum):
    from methods.delan import compiled_torque_loss, torque_loss

    batch = generate(double_pendulum, 256, 0).tensors(torch.float32)
    torch.manual_seed(0)
    net = DeepLagrangian(2, DeLaNConfig())
    grads = []
    for loss in (torque_loss, compiled_torque_loss()):
        net.zero_grad()
        value = loss(net, batch["q"], batch["qd"], batch["qdd"], batch["tau"])
        value.backward()
        grads.append((value.item(), [torch.zeros_like(p) if p.grad is None else p.grad.clone() for p in net.parameters()]))
    (eager, g_eager), (compiled, g_compiled) = grads
    assert compiled == pytest.approx(eager, rel=1e-5)
    for a, b in zip(g_eager, g_compiled):
        torch.testing.assert_close(b, a, rtol=1e-4, atol=1e-6)


def test_its_mass_matrix_and_bias_are_the_networks_own_and_the_transforms(double_pendulum):
    """``M`` is the network's ``H(q)`` and ``c`` the transform's torque at ``qdd = 0``, bit for bit, from one
    pass; both are what the torque at dof + 1 accelerations a state decomposes into."""
    from bench.physics.models import FittedModel

    train = generate(double_pendulum, 256, 0)
    m = METHODS["delan"](**METHODS["delan"].smoke_config()).fit(train, "indirect", 0, budget=Budget(steps=5))
    q, qd = train.q[:40], train.qd[:40]
    M, c = m.mass_and_bias(q, qd)
    zeros = np.zeros_like(q)
    np.testing.assert_array_equal(M, m.mass_matrix(q))
    np.testing.assert_array_equal(c, m.predict_torque(Dataset(q, qd, zeros, zeros)))
    M_ref, c_ref = FittedModel.mass_and_bias(m, q, qd)
    np.testing.assert_allclose(M, M_ref, rtol=1e-9, atol=1e-9 * np.abs(M_ref).max())
    np.testing.assert_allclose(c, c_ref, rtol=0, atol=0)
