"""SyReNets: terms, selection, losses, the frozen function and its equations."""

from __future__ import annotations

import numpy as np
import pytest
import sympy
import torch

from bench.core import symbolic
from bench.core.data import generate, mse
from bench.core.experiment import Experiment
from bench.core.timeouts import Timeout
from bench.physics.dynamics import euler_lagrange
from methods import METHODS
from methods.syrenets.layer_terms import LayerTerms
from methods.syrenets.config import SyReNetsConfig
from methods.syrenets.equations import round_inner_constants
from methods.syrenets.multistart import halve
from methods.syrenets.network import Gram, HeadsOutput, SyReNet
from methods.syrenets.training import Fixed, Network, training_pass
from bench.core.budget import Budget

SMALL = dict(layers=2, heads=3, latent=4, ae_hidden=8, head_hidden=8)


def test_candidate_count_and_order():
    spec = LayerTerms(3, ("sum", "prod", "sin", "cos"))
    u = torch.tensor([[2.0, 3.0, 5.0]], dtype=torch.float64)
    expected = [2, 5, 7, 3, 8, 5,  # sums: u1, u1+u2, u1+u3, u2, u2+u3, u3
                4, 6, 10, 9, 15, 25,  # products: u1^2, u1u2, u1u3, u2^2, u2u3, u3^2
                *np.sin([2, 3, 5]), *np.cos([2, 3, 5])]
    np.testing.assert_allclose(spec(u)[0].numpy(), expected, rtol=1e-15)
    a, b, c = sympy.symbols("a b c")
    assert spec.symbolic([a, b, c])[:6] == [a, a + b, a + c, b, b + c, c]
    assert spec.symbolic([a, b, c])[6:9] == [a**2, a * b, a * c]
    assert LayerTerms(6 + 12, ("sum", "prod", "sin", "cos")).size == 378
    assert LayerTerms(4 + 12, ("sum", "prod", "sin", "cos")).size == 304
    assert LayerTerms(3, ("diff", "exp")).size == 3 + 3


def test_operator_set_is_validated():
    with pytest.raises(Exception, match="unknown operator"):
        METHODS["syrenets"](operators=("sum", "tan"))


def _net(n_x=4, **kw):
    torch.manual_seed(0)
    return SyReNet(n_x, SyReNetsConfig(**{**SMALL, **kw})).double()


def test_selection_distributions_gates_and_scales():
    net = _net(heads=5, layers=3)
    G = torch.rand(4, 4, dtype=torch.float64)
    prev = torch.full((net.C,), 0.2**5, dtype=torch.float64)
    P, phi, W = net.heads(1, G, prev)
    assert P.shape == (5, net.C) and phi.shape == (5,) and W.shape == (5, net.C)
    torch.testing.assert_close(P.sum(-1), torch.ones(5, dtype=torch.float64))
    assert ((phi > 0) & (phi < 1)).all()
    assert len(net.S) == 3 and net.S[1].shape == (5, net.C)
    torch.testing.assert_close(W, phi[:, None] * P * net.S[1])


def test_closed_form_contractive_penalty_matches_autograd():
    net = _net()
    v = torch.randn(7, net.C, dtype=torch.float64)
    _, a1, a2 = net.encode(v)
    closed = net.contractive(a1, a2)
    J = torch.autograd.functional.jacobian(lambda x: net.encode(x)[0].sum(0), v)  # (d, B, C)
    torch.testing.assert_close(closed, J.pow(2).mean(), rtol=1e-12, atol=0)


def test_frozen_function_equals_the_training_pass():
    net = _net(layers=3)
    x = torch.rand(32, 4, dtype=torch.float64) * 3 - 1.5
    out, weights, _ = net.select(x)
    torch.testing.assert_close(net.evaluate(x, weights), out, rtol=1e-13, atol=1e-13)


def test_gram_matrix_ignores_sample_order():
    net = _net()
    x = torch.rand(16, 4, dtype=torch.float64)
    _, w1, _ = net.select(x)
    _, w2, _ = net.select(x[torch.randperm(16)])
    for a, b in zip(w1, w2):
        torch.testing.assert_close(a, b, rtol=1e-12, atol=1e-14)


@pytest.fixture(scope="module")
def data(double_pendulum):
    return generate(double_pendulum, 512, 0), generate(double_pendulum, 128, 1000)


@pytest.mark.parametrize("experiment", ["direct", "indirect"])
def test_expression_evaluates_to_the_frozen_model(data, experiment):
    m = METHODS["syrenets"](**SMALL, max_steps=5, eval_samples=64, refine=False).fit(data[0], experiment, 0, Budget(seconds=60))
    f = symbolic.to_numpy(m.expression(), 2)
    np.testing.assert_allclose(f(data[1].q, data[1].qd), m.predict_lagrangian(data[1]), rtol=1e-10, atol=1e-10)
    # the indirect training loss uses exactly the torques of the frozen function
    t = data[1].tensors()
    tau = euler_lagrange(m.lagrangian, t["q"], t["qd"], t["qdd"]).numpy()
    np.testing.assert_allclose(tau, m.predict_torque(data[1]), rtol=1e-12, atol=1e-12)


def test_pruned_variant_keeps_few_terms_within_tolerance(data):
    m = METHODS["syrenets"](**SMALL, max_steps=30, eval_samples=64, refine=False).fit(data[0], "direct", 0, Budget(seconds=60))
    pruned = m.variants()["pruned"]
    details = m.record_details()
    assert 0 < details["pruned_terms"] < details["total_terms"]
    full = mse(m.predict(data[0], "direct"), data[0].L)
    assert mse(pruned.predict(data[0], "direct"), data[0].L) <= 1.3 * full
    f = symbolic.to_numpy(pruned.expression(), 2)
    np.testing.assert_allclose(f(data[1].q, data[1].qd), pruned.predict_lagrangian(data[1]), rtol=1e-9, atol=1e-9)


def test_round_inner_constants():
    q1, q2 = sympy.symbols("q_1 q_2", real=True)
    f = sympy.cos(1.0004 * q1 - 0.9991 * q2 + 0.003) * sympy.sin(0.4999 * q1 + 0.3)
    assert round_inner_constants(f) == sympy.cos(q1 - q2) * sympy.sin(q1 / 2 + sympy.Float(0.3))


@pytest.mark.parametrize("experiment", ["direct", "indirect"])
def test_refinement_recovers_the_exact_lagrangian_from_a_near_miss(data, double_pendulum, experiment):
    """A pruned equation with the right structure but perturbed constants and a
    spurious term is refined into the true Lagrangian."""
    (q1, q2), (qd1, qd2) = symbolic.coordinate_symbols(2)
    near = (7.13 * qd1**2 + 0.4651 * qd2**2 + 2.2301 * qd1 * qd2 * sympy.cos(1.0003 * q1 - 0.9996 * q2)
            + 65.47 * sympy.cos(0.9998 * q1) + 8.19 * sympy.cos(q2) + 0.002 * q1 * qd2)
    m = METHODS["syrenets"](**SMALL, max_steps=1, eval_samples=64).fit(data[0], experiment, 0, Budget(seconds=60))

    class Fake:  # stands for the dominant terms of a trained model
        def expression(self):
            return near

    m._notes["pruned_terms"] = 1
    m._top_terms = lambda k: Fake()
    refined = m._refine(data[0], experiment, deadline=float("inf"))
    assert mse(refined.predict(data[1], experiment), data[1].target(experiment)) < 1e-20
    assert "blocks" in m._notes["refine_folds"]  # the protocol's folds of independent samples, not a random split
    terms = sympy.Add.make_args(sympy.expand(refined.expression()))
    assert len([t for t in terms if t.free_symbols]) == 5


def test_refinement_keeps_the_best_refit_when_a_larger_size_runs_out_of_budget(data):
    """The 8-term structure is refitted as soon as it is the best so far, so the 16-term one running out of
    budget in its symbolic expansion (the refinement's slow step) leaves a refined equation, not a timeout."""
    (q1, q2), (qd1, qd2) = symbolic.coordinate_symbols(2)
    near = (7.13 * qd1**2 + 0.4651 * qd2**2 + 2.2301 * qd1 * qd2 * sympy.cos(1.0003 * q1 - 0.9996 * q2)
            + 65.47 * sympy.cos(0.9998 * q1) + 8.19 * sympy.cos(q2))
    m = METHODS["syrenets"](**SMALL, max_steps=1, eval_samples=64).fit(data[0], "indirect", 0, Budget(seconds=60))

    class Terms:  # the dominant terms of a trained model: the 8 in time, the 16 past the deadline
        def __init__(self, k):
            self.k = k

        def expression(self):
            if self.k > 8:
                raise Timeout("expansion past the deadline")
            return near

    m._notes["pruned_terms"] = 16
    m._top_terms = Terms
    refined = m._refine(data[0], "indirect", deadline=float("inf"))
    assert mse(refined.predict(data[1], "indirect"), data[1].tau) < 1e-20
    assert m._notes["refined_from_terms"] == 8
    assert m._notes["refine_left_out"] == "16 terms: out of budget"


def test_six_input_variant_runs_and_is_flagged(data):
    m = METHODS["syrenets"](**SMALL, inputs="q_qd_qdd", max_steps=3, eval_samples=64).fit(data[0], "indirect", 0, Budget(seconds=60))
    assert np.isfinite(m.predict_torque(data[1])).all()
    assert "refinement needs inputs='q_qd'" in m.record_details()["refined"]


def _encoder_pre_activations(rows: int):
    """A small network, its encoder's two pre-activations on ``rows`` random term rows, and the exact penalty."""
    net = _net()
    _, a1, a2 = net.encode(torch.randn(rows, net.C, dtype=torch.float64))
    return net, a1, a2, net.contractive(a1, a2).item()


def test_hutchinson_contractive_estimate_is_unbiased():
    net, a1, a2, exact = _encoder_pre_activations(6)
    torch.manual_seed(1)
    estimate = np.mean([net.contractive(a1, a2, probes=8).item() for _ in range(400)])
    assert estimate == pytest.approx(exact, rel=0.03)


def test_grouped_contractive_estimate_gives_each_group_its_own_probes():
    net, a1, a2, exact = _encoder_pre_activations(9)
    torch.manual_seed(1)
    estimates = [net.contractive(a1, a2, probes=1, groups=3).item() for _ in range(2000)]
    assert np.mean(estimates) == pytest.approx(exact, rel=0.03)
    # the three groups' probes are drawn independently: one draw of the whole
    # batch with a single shared probe has a larger spread
    torch.manual_seed(1)
    shared = [net.contractive(a1, a2, probes=1).item() for _ in range(2000)]
    assert np.std(estimates) < 0.8 * np.std(shared)


def test_the_training_pass_sums_each_layers_losses():
    """The batched losses of :meth:`SyReNet.select` are the sums of each layer's own."""
    net = SyReNet(4, SyReNetsConfig(**{**SMALL, "layers": 3}, contractive_probes=0)).double()
    x = torch.randn(10, 4, dtype=torch.float64)
    _, weights, aux = net.select(x)
    expected, h = 0.0, x.new_zeros(10, SMALL["heads"])
    prev = x.new_full((net.C,), (1.0 / SMALL["heads"]) ** SMALL["heads"])
    for layer, W in enumerate(weights):
        v = net.spec(torch.cat([x, h], dim=1))
        vn = torch.nn.functional.layer_norm(v, v.shape[-1:])
        z, a1, a2 = net.encode(vn)
        zn = z / z.norm(dim=0, keepdim=True)
        P, phi, _ = net.heads(layer, zn.T @ zn, prev)
        p = phi.unsqueeze(1) * P
        prev = p.prod(dim=0)
        expected += torch.nn.functional.mse_loss(net.decode(z), vn) + net.contractive(a1, a2) + net._diversity(p)
        h = v @ W.T
    torch.testing.assert_close(aux, expected, rtol=1e-12, atol=1e-12)


def test_the_hand_written_backward_passes_match_finite_differences():
    """The heads' output layer and the Gram matrix of the contractive penalty
    have their own backward; torch's gradcheck compares them with central
    differences, and the forward with the plain expressions."""
    torch.manual_seed(0)
    W = torch.randn(3, 7, 5, dtype=torch.float64, requires_grad=True)
    h = torch.randn(3, 5, dtype=torch.float64, requires_grad=True)
    A = torch.randn(4, 9, dtype=torch.float64, requires_grad=True)
    Wt = W.detach().transpose(1, 2).contiguous().requires_grad_(True)  # stored (heads, k, C)
    assert torch.autograd.gradcheck(HeadsOutput.apply, (W, h))
    assert torch.autograd.gradcheck(HeadsOutput.apply, (Wt, h, True))
    assert torch.autograd.gradcheck(Gram.apply, (A,))
    torch.testing.assert_close(HeadsOutput.apply(W, h), (W * h.unsqueeze(1)).sum(-1), rtol=0, atol=0)
    torch.testing.assert_close(HeadsOutput.apply(Wt, h, True), HeadsOutput.apply(W, h), rtol=1e-14, atol=0)
    torch.testing.assert_close(Gram.apply(A), A @ A.T, rtol=0, atol=0)
    # only the gradients asked for are formed, in either layout
    g = torch.randn(3, 7, dtype=torch.float64)
    for weights, hidden_first in ((W, False), (Wt, True)):
        class Ctx:
            saved_tensors = (weights.detach(), h.detach())

        Ctx.hidden_first = hidden_first
        for asked in ((False, True), (True, False)):
            Ctx.needs_input_grad = (*asked, False)
            formed = HeadsOutput.backward(Ctx(), g)
            assert [x is not None for x in formed] == [*asked, False]
        expected = g.unsqueeze(-1) * h.detach().unsqueeze(1)
        torch.testing.assert_close(formed[0], expected.transpose(1, 2) if hidden_first else expected)


def test_a_compiling_network_stores_the_same_head_weights_hidden_units_first():
    """(Its pass is then compiled; see HeadsOutput.) Same seed, same weights,
    same outputs and losses."""
    plain, compiling = _net(), _net(compile=True)
    for a, b in zip(plain.W2, compiling.W2):
        assert b.shape == (a.shape[0], a.shape[2], a.shape[1]) and b.is_contiguous()
        torch.testing.assert_close(b, a.transpose(1, 2), rtol=0, atol=0)
    x = torch.randn(16, 4, dtype=torch.float64)
    torch.manual_seed(1)
    out_plain = plain.select(x)
    torch.manual_seed(1)  # the same Rademacher probe
    out_compiling = compiling.select(x)
    torch.testing.assert_close(out_compiling[0], out_plain[0], rtol=1e-12, atol=1e-14)
    torch.testing.assert_close(out_compiling[2], out_plain[2], rtol=1e-12, atol=1e-14)


def test_diversity_loss_matches_its_definition():
    net = _net(heads=4)
    p = torch.softmax(torch.randn(4, net.C, dtype=torch.float64), -1) * torch.rand(4, 1, dtype=torch.float64)
    ce = lambda a, b: -(a * torch.log(b + 1e-5)).sum()  # noqa: E731
    entropy = sum(ce(p[j], p[j]) for j in range(4)) / 4
    cross = sum(ce(p[i], p[j]) for i in range(4) for j in range(4) if i != j) / 12
    torch.testing.assert_close(net._diversity(p), 1e-3 * entropy - 1.0 * cross)


def test_cosine_schedule_anneals_from_lr_to_lr_min_over_the_steps(data):
    m = METHODS["syrenets"](**SMALL, lr_schedule="cosine", lr=1e-2, lr_min=1e-4, max_steps=20, eval_samples=64,
                            refine=False)
    seen = []
    step = m.train_step

    def recording(batch, experiment):
        seen.append(m.optimizer.param_groups[0]["lr"])
        return step(batch, experiment)

    m.train_step = recording
    m.fit(data[0], "direct", 0, Budget(seconds=60))
    C = m.model.C
    expected = [1e-4 + (1e-2 - 1e-4) * 0.5 * (1 + np.cos(np.pi * k / 19)) for k in range(20)]
    np.testing.assert_allclose(seen, expected, rtol=1e-12)  # first step 1e-2, last 1e-4
    assert m.optimizer.param_groups[1]["lr"] == pytest.approx(1e-4 * C)  # the scale keeps its C times


def test_the_plateau_schedule_watches_a_moving_average_of_the_batch_loss(data):
    for a in (0.0, 0.9):
        m = METHODS["syrenets"](**SMALL, lr_smoothing=a, max_steps=12, eval_samples=64, refine=False)
        batch_losses, watched = [], []
        step = m.train_step

        def recording(batch, experiment):
            if not watched:  # the schedule exists from the first step on
                plateau_step = m.scheduler.step
                m.scheduler.step = lambda value: (watched.append(value), plateau_step(value))[1]
            err = step(batch, experiment)
            batch_losses.append(err.mean().item())
            return err

        m.train_step = recording
        m.fit(data[0], "direct", 0, Budget(seconds=60))
        expected = [batch_losses[0]]
        for loss in batch_losses[1:]:
            expected.append(a * expected[-1] + (1 - a) * loss)
        assert len(watched) == 12
        np.testing.assert_allclose(watched, expected, rtol=1e-12)
        if a == 0:
            assert watched == batch_losses  # the paper's: each batch's own loss


def test_a_multi_start_fit_keeps_the_network_with_the_lowest_training_mse(data):
    m = METHODS["syrenets"](**SMALL, starts=4, start_share=0.5, max_steps=40, eval_samples=64, refine=False)
    inits, network = [], m._network

    def recording(train, start=0):
        net = network(train, start)
        inits.append(torch.cat([p.detach().flatten() for p in net.model.parameters()]))
        return net

    m._network = recording
    m.fit(data[0], "direct", 0, Budget(seconds=60))
    starts = m.record_details()["starts"]
    assert starts["networks"] == 4 and len(inits) == 4
    assert all(not torch.equal(inits[0], other) for other in inits[1:])  # each network its own initialisation
    first, second = starts["rounds"]  # ceil(log2 4) rounds: 4 networks, then the better 2
    assert [k for k, _ in first] == [0, 1, 2, 3]
    better = sorted(first, key=lambda pair: pair[1])[:2]
    assert sorted(k for k, _ in second) == sorted(k for k, _ in better)
    assert starts["kept"] == min(second, key=lambda pair: pair[1])[0]
    assert m.fit_info["steps"] == 40  # the rounds share the run's steps, they do not add to them
    single = METHODS["syrenets"](**SMALL, max_steps=5, eval_samples=64, refine=False).fit(data[0], "direct", 0, Budget(seconds=60))
    assert "starts" not in single.record_details()


def test_float32_training_is_evaluated_in_float64_and_can_continue(data):
    train, test = data
    m = METHODS["syrenets"](**SMALL, dtype="float32", max_steps=5, eval_samples=64, refine=False)
    seen = []
    step = m.train_step
    m.train_step = lambda batch, experiment: (seen.append(batch["q"].dtype), step(batch, experiment))[1]
    m.fit(train, "indirect", 0, Budget(seconds=60))
    assert set(seen) == {torch.float32}
    assert all(p.dtype == torch.float64 for p in m.model.parameters())
    assert all(w.dtype == torch.float64 for w in m.frozen)
    # the prediction is the float64 evaluation of the trained weights, not a float32 one
    t = test.tensors(torch.float64)
    expected = euler_lagrange(m.lagrangian, t["q"], t["qd"], t["qdd"]).numpy()
    np.testing.assert_array_equal(m.predict_torque(test), expected)
    m.fit(train, "indirect", 0, Budget(seconds=60), warm_start=True)  # continues in float32, with the optimiser's float32 state
    assert seen[-1] == torch.float32 and len(seen) == 10
    assert all(p.dtype == torch.float64 for p in m.model.parameters())


def test_the_record_lists_when_the_plateau_schedule_cut_the_learning_rate(data):
    m = METHODS["syrenets"](**SMALL, lr_patience=0, max_steps=30, eval_samples=64, refine=False)
    m.fit(data[0], "direct", 0, Budget(seconds=60))
    drops = m.record_details()["lr_drops"]
    assert drops, "with no patience the rate is cut at the first step without a new best"
    steps, seconds, lrs = zip(*drops)
    assert list(steps) == sorted(set(steps)) and all(0 < s <= 30 for s in steps)
    assert list(seconds) == sorted(seconds)
    expected = [1e-3 * 0.1 ** (k + 1) for k in range(len(lrs))]
    np.testing.assert_allclose(lrs, [max(e, 1e-5) for e in expected][: len(lrs)])
    assert lrs[-1] == m.optimizer.param_groups[0]["lr"]
    cosine = METHODS["syrenets"](**SMALL, lr_schedule="cosine", max_steps=3, eval_samples=64, refine=False)
    assert "lr_drops" not in cosine.fit(data[0], "direct", 0, Budget(seconds=60)).record_details()


ALL_OPERATORS = ("sum", "prod", "diff", "sin", "cos", "exp")


@pytest.mark.parametrize("hp", [{}, {"inputs": "q_qd_qdd"}, {"operators": ALL_OPERATORS}])
def test_derivatives_propagated_forward_match_the_reverse_passes(data, hp):
    """The torques of the fixed function from LayerTerms.tangent equal
    those of the transform's reverse passes, and so do their gradients with
    respect to every parameter."""
    m = METHODS["syrenets"](**hp)
    m.seed, m.dof = 0, data[0].dof
    m._setup(data[0])
    b = {k: v[:40] for k, v in data[0].tensors().items()}
    weights = m.model.select(m._inputs(b["q"], b["qd"], b["qdd"]))[1]
    fixed = Fixed(m.model, m.config.inputs, weights, b["qdd"])
    forward = euler_lagrange(fixed, b["q"], b["qd"], b["qdd"], create_graph=True)
    reverse = euler_lagrange(fixed.__call__, b["q"], b["qd"], b["qdd"], create_graph=True)
    assert reverse.abs().max() > 1e-3
    torch.testing.assert_close(forward, reverse, rtol=1e-10, atol=1e-13)
    params = list(m.model.parameters())
    g_forward = torch.autograd.grad((forward ** 2).sum(), params, retain_graph=True, allow_unused=True)
    g_reverse = torch.autograd.grad((reverse ** 2).sum(), params, allow_unused=True)
    assert sum(g is not None for g in g_reverse) > 10
    for a, c in zip(g_forward, g_reverse):
        assert (a is None) == (c is None)
        if a is not None:
            torch.testing.assert_close(a, c, rtol=1e-9, atol=1e-12)


@pytest.mark.slow  # each compilation takes about a minute on a cold cache
@pytest.mark.parametrize("experiment", ["direct", "indirect"])
def test_the_compiled_training_pass_equals_the_eager_one(data, experiment):
    """torch.compile's pass (indirect: with the derivatives propagated
    forward) against the eager pass on one batch: loss, errors and the
    parameters' gradients. The exact contractive penalty draws no probes."""
    m = METHODS["syrenets"](**SMALL, contractive_probes=0, compile=True)
    m.seed, m.dof = 0, data[0].dof
    m._setup(data[0])
    b = {k: v[:32] for k, v in data[0].tensors().items()}
    target = b["L"] if experiment == "direct" else b["tau"]
    params = list(m.model.parameters())
    results = []
    for tangent in (False, True):
        pass_ = torch.compile(training_pass, dynamic=False) if tangent else training_pass
        loss, err, weights = pass_(m.model, b["q"], b["qd"], b["qdd"], target, Experiment.of(experiment).learns_torque,
                                   "q_qd", tangent)
        results.append((loss, err, weights, torch.autograd.grad(loss, params, allow_unused=True)))
    (loss0, err0, w0, g0), (loss1, err1, w1, g1) = results
    torch.testing.assert_close(loss1, loss0, rtol=1e-10, atol=0)
    torch.testing.assert_close(err1, err0, rtol=1e-9, atol=1e-14)
    for a, c in zip(w1, w0):
        torch.testing.assert_close(a, c, rtol=1e-10, atol=1e-14)
    for a, c in zip(g1, g0):
        assert (a is None) == (c is None)
        if a is not None:
            torch.testing.assert_close(a, c, rtol=1e-8, atol=1e-12)


@pytest.mark.slow
def test_a_compiled_fit_compiles_before_its_budget_and_says_how_long_it_took(data):
    m = METHODS["syrenets"](**SMALL, compile=True, starts=2, replay=4, eval_samples=64, refine=False)
    m.fit(data[0], "indirect", 0, budget=Budget(steps=20))
    details = m.record_details()
    assert 0 < details["compile_seconds"] <= m.fit_info["prepare_seconds"]  # before the budget's clock started
    assert m.fit_info["steps"] == 20
    assert np.isfinite(m.fit_info["curve"][-1][1])
    plain = METHODS["syrenets"](**SMALL, max_steps=5, eval_samples=64, refine=False).fit(data[0], "indirect", 0, Budget(seconds=60))
    assert "compile_seconds" not in plain.record_details()


def test_the_selection_scores_each_network_by_its_lowest_evaluation_so_far():
    """At the selection's learning rates a network's current MSE swings; the
    halving ranks networks by the lowest of all their evaluations, so that
    network 1, which reached 0.05 during its first turn, is kept although its
    state at the end of each turn looks worse than network 0's."""
    during = {0: [[0.9], [0.35]], 1: [[0.05], [0.04]], 2: [[0.5]], 3: [[0.7]]}  # scheduled evaluations, per turn
    end = {0: [0.3, 0.2], 1: [0.6, 0.5], 2: [0.4], 3: [0.7]}                    # at the end of each turn
    m = METHODS["syrenets"](**SMALL, starts=4)

    class Scripted:
        measured: list = []

        def fraction(self):
            return 0.0

        def measure(self):
            self.measured.append(end[m.model].pop(0))
            return self.measured[-1]

    def turn(t, experiment, progress, feed, until):  # a turn of no steps: a generator that yields nothing
        progress.measured.extend(during[m.model].pop(0))
        return True
        yield

    m._train = turn
    networks = [Network(model=k, optimizer=None, scheduler=None, frozen=[]) for k in range(4)]
    with pytest.raises(StopIteration) as done:
        next(halve(m, networks, None, "direct", Scripted(), feed=None))
    starts = done.value.value
    first, second = starts["rounds"]
    assert first == [[0, 0.3], [1, 0.05], [2, 0.4], [3, 0.7]]
    assert second == [[0, 0.2], [1, 0.04]]
    assert starts["kept"] == 1 and m.net is networks[1] and m.model == 1
