"""SyReNets: Symbolic Residual Neural Networks (Valle & Haddadin, 2021).

A stack of symbolic layers. Layer ``l`` sees the system inputs ``x`` and the
outputs of the previous layer's heads, builds every candidate term from them,
and each of its selection heads outputs a weighted sum of the candidates; the
last layer's heads are summed into the Lagrangian.

Architecture (the paper's, with the public code's facts where the paper is open)
---------------------------------------------------------------------------------
* **Inputs** ``x = (q, qd)`` by default. ``inputs="q_qd_qdd"`` feeds ``qdd``
  too, as the public code did. That variant is *physically inconsistent*: a
  Lagrangian depends on ``(q, qd)`` only, and with ``qdd`` as an input the
  Euler–Lagrange transform would need third derivatives, which it (like the
  public code) silently drops by treating ``qdd`` as a constant. Its
  expression holds ``qdd``; the record keeps it, and exact recovery and the
  rollout state that they do not apply (:meth:`SyReNets.not_a_lagrangian`).
* **Candidates** of a layer with inputs ``u_1..u_n``, in this order: the
  pairwise sums over the upper triangle (row-major; the diagonal stands for
  ``u_i`` itself), the pairwise products over the upper triangle (squares
  included), ``sin(u_i)``, ``cos(u_i)``. For n inputs, n(n+1)/2 + n(n+1)/2 + n
  + n candidates: 378 for 6 + 12 inputs, 304 for 4 + 12. Further operators
  (``diff`` = u_i - u_j for i < j, ``exp``) can be enabled with ``operators``.
* **Shared representation block**: layer normalisation of the candidates of
  each sample; a contractive auto-encoder shared by all layers (encoder
  C -> 128 -> 128 -> 16, softplus, linear latent; mirrored decoder; biases
  only here); the cosine-similarity Gram matrix of the 16 latent dimensions
  over the batch; per layer, a bias-free linear map applied to each row.
* **Selection head** (all heads of a layer are computed as one batched tensor
  operation): a bias-free weighted sum d x d -> d; a hidden layer of 64
  softplus units with layer normalisation before the activation; an output
  over the candidates with layer normalisation and softmax, giving the
  selection distribution ``P`` shared by the batch; a per-candidate scale
  ``S``; an on-off gate ``phi = sigmoid(w1 . P_j + w2 . prod_j' p_j'(previous
  layer))``; the head outputs ``h_j = phi_j sum_b S_jb v_b P_jb`` over the raw
  candidates ``v``.
* **Losses**: ``L_b + L_ae + L_c``. ``L_ae`` = reconstruction MSE +
  ``lambda1 * ||J_encoder||^2``. ``L_c`` = per layer
  ``lambda2 * H(p_j) - lambda3 * sum_{j' != j} H(p_j', p_j)`` with
  ``p_j = phi_j P_j``, lambda2 = 0.001, lambda3 = 1.
* **Training**: Adam, lr 1e-3 divided by 10 after every 1000 steps without
  improvement of the mini-batch loss, down to 1e-5 (the paper's schedule; the
  public code waited 2000 steps); mini-batches of 32; float64; best state kept.
  ``lr_smoothing=a`` lets the plateau schedule watch an exponential moving
  average of the mini-batch loss instead of each batch's (the paper does not
  say which; a single low batch otherwise starts the 1000-step count early).
  ``replay=16`` re-feeds the 16 worst-fitted samples of the previous batch at
  every step, as the public code did.
* **Evaluation**: a fixed function; each layer's weights are frozen at the
  head outputs' ``phi * S * P`` of the most recent training batch (as in the
  public code).

Choices and deviations, each deliberate
---------------------------------------
* *Means, not sums*, in ``L_c`` and in the contractive penalty, as in the
  public code: ``L_c`` uses the mean entropy over heads and the mean
  cross-entropy over the ``H(H-1)`` ordered pairs of distinct heads; the
  contractive term is the mean squared entry of the encoder Jacobian
  (``||J||_F^2 / (16 C)`` per sample, averaged over the batch). Entropies use
  ``log(p + 1e-5)`` like the public code.
* The contractive penalty is computed in closed form for the softplus
  encoder, ``J = W3 diag(s'(a2)) W2 diag(s'(a1)) W1``, with
  ``||J||_F^2 = tr(M K M^T)``, ``M = W3 diag(s'(a2)) W2 diag(s'(a1))`` and
  ``K = W1 W1^T``, instead of an autograd Jacobian. Even so, the exact value
  costs two (16 B x 128) x (128 x 128) products per layer and their
  backward, about as much as the rest of a step together. By default it is
  therefore *estimated* without bias by Hutchinson's trace estimator,
  ``E_e ||e^T J||^2`` with one Rademacher vector ``e`` per step (the same
  closed form applied to ``e^T J``), which is 16 times cheaper;
  ``contractive_probes=0`` computes it exactly.
* The three layers' reconstruction, contractive and selection losses are
  computed after the layer loop, each in one pass over the layers' stacked
  tensors (each layer with its own Rademacher vector). The loss and its
  gradients are those of the per-layer sums to rounding. With the heads'
  weighted sum written as two matrix products instead of an ``einsum``, a
  step of the public configuration makes 2,014 aten calls instead of
  2,765; each costs dispatch and autograd time on top of its arithmetic.
* The scale ``S`` comes, in the public code, from a bias-free ``C x C``
  linear layer applied to a vector of ``C`` ones. Every weight of a row then
  receives the same gradient, so under Adam the row sum moves ``C`` times
  the step of one weight. ``S`` is therefore stored directly, initialised as
  the sum of ``C`` draws of the layer's default uniform initialisation, and
  trained with ``C`` times the learning rate: the same dynamics (up to Adam's
  epsilon) with ``C`` times fewer parameters.
* The gate of the first layer sees the product of uniform distributions
  ``(1/H)^H`` in place of a previous layer, as in the public code.
* Layer normalisations have no affine parameters and the per-layer linear map
  has no bias ("biases only in the auto-encoder"); the public code had both.
* The cosine similarity is the standard one, ``<z_i, z_j> / (|z_i| |z_j|)``.
* In the indirect experiment, the selection (``P``, ``phi``, ``S``) is
  computed from the batch with the inputs detached, and the torques are those
  of the resulting fixed function of ``(q, qd)``. The public code
  differentiated through the batch statistics as well, which makes each
  sample's torque depend on the other samples of its batch.
* The kept state is the one with the lowest training MSE on a fixed subset
  of the training data (see :class:`methods.progress.Progress`), not the lowest
  mini-batch MSE, and the test set is not evaluated during training.
* ``dtype="float32"`` trains in single precision (the paper's is float64);
  the fitted function is then evaluated, pruned and refined in float64. On
  this kind of CPU a step is about 1.7 times faster in the indirect
  experiment (26,400 against 15,300 steps in 300 s, with ``replay=16``).
* ``starts=k`` (beyond the paper; default 1) trains k networks from their own
  initialisations in turns and keeps one by successive halving (Jamieson &
  Talwalkar, 2016) on each network's lowest training MSE so far, within
  ``start_share`` of the training time. It is what the paper's "Best" row does across seeds, inside
  one run's budget: in the indirect experiment a run either finds the
  Lagrangian's structure within its first minutes or stays on a wrong one for
  the rest of the run, whatever the learning-rate schedule. Each network
  keeps its own optimiser and schedule; under the plateau schedule a
  network's rate can already be cut to its floor during the selection, so
  the cosine schedule, which keeps the rates high through it, suits
  ``starts`` better (results/further.md).
* ``compile=True`` (an engineering option; default off) compiles the
  training pass (selection, torques and loss) with ``torch.compile``
  (inductor), once per process: the model is an argument of the compiled
  function, so the networks of a multi-start fit share it. The compilation
  runs on a network of the fit's shapes before the budget starts
  (:meth:`methods.base.Method.prepare`), so that a machine whose compile
  cache is empty leaves a run as much learning time as a warm one; the
  record gives its time as ``details.compile_seconds``. Compiled autograd cannot take the backward of a backward,
  which the transform's reverse passes need, so in a compiled pass the
  indirect torques come from derivatives
  propagated *forward* through the frozen function
  (:meth:`CandidateSpec.tangent`, the product and chain rules of
  ``methods/jets.py`` applied to a layer's candidates at once, on tensors the
  loss differentiates), which the one Euler–Lagrange transform takes from
  :class:`_Fixed`'s ``tangent`` method. The two agree to rounding
  (``test_derivatives_propagated_forward_match_the_reverse_passes``). A
  compiling network stores its heads' output weights ``W2`` as (heads,
  hidden units, candidates), the same numbers transposed, so that the
  generated code sums the heads' products along the candidates instead of
  across a vector register (see :class:`HeadsOutput`). Eager
  passes keep the reverse passes: uncompiled, the forward propagation was
  about 10 % slower. The steps each does in a budget are measured in
  results/syrenets/ (listed in results/index.md).

Readable equations and exact recovery (beyond the paper)
--------------------------------------------------------
The frozen model pushed through sympy (:meth:`SyReNets.expression`) is exact
but long, since softmax weights are never zero. After training, within the
budget (``post_fraction`` of it is reserved), two variants are derived and
reported beside the paper's model:

* ``pruned``: the fewest terms, ranked by ``|weight| * rms(candidate)``, whose
  frozen model is within 10 % of the full model's training MSE; its equation
  is what records store as the run's expression;
* ``refined``: the dominant terms' structure with its inner constants rounded
  to simple rationals, refitted by least squares (linear in L, and in tau
  through g), see :meth:`SyReNets._refine`.
"""

from __future__ import annotations

import math
import time
import typing
from dataclasses import dataclass
from typing import Annotated

import numpy as np
import sympy
import torch
import torch.nn.functional as F

from bench.core import regression, symbolic
from bench.core.data import mse
from bench.core.dynamics import euler_lagrange
from bench.core.errors import ConfigError
from bench.core.models import ExpressionModel, FittedModel
from bench.core.timeouts import Timeout, call_with_timeout
from methods.base import METHODS
from methods.config import Range
from methods.torch_method import TorchConfig, TorchLagrangianMethod, fused_adam_ok

BINARY = ("sum", "prod", "diff")
#: the refinement gives up on pruned equations that expand into more terms
MAX_REFIT_TERMS = 2000
#: a pruned equation keeping more weights than this is not written out: its
#: text would exceed the record's 20 000 characters, and pushing it through
#: sympy grows faster than linearly (1.5 s at 512 terms, 15 s at 1600)
MAX_READABLE_TERMS = 512
UNARY = ("sin", "cos", "exp")
EPS_LOG = 1e-5
_COMPILED = None  # see _compiled_pass


@dataclass(frozen=True)
class SyReNetsConfig(TorchConfig):
    """Hyperparameters; the defaults are the paper's.

    Attributes
    ----------
    layers, heads
        Symbolic layers and selection heads per layer.
    inputs
        ``"q_qd"`` (default, consistent) or ``"q_qd_qdd"`` (the public code's).
    operators
        Candidate operators, a subset of ``sum, prod, diff, sin, cos, exp``.
    latent, ae_hidden, head_hidden
        Auto-encoder latent (d) and hidden widths; head hidden units.
    lambda_contractive, lambda_entropy, lambda_diversity
        lambda1, lambda2, lambda3.
    contractive_probes
        0: the exact closed-form contractive penalty; k > 0: Hutchinson's
        unbiased estimate with k Rademacher probes (cheaper, stochastic).
    lr_schedule
        ``"plateau"`` (the paper's): divide the learning rate by
        ``1 / lr_factor`` after ``lr_patience`` steps without improvement of
        the mini-batch loss, down to ``lr_min``. ``"cosine"``: anneal it from
        ``lr`` to ``lr_min`` along half a cosine over the training time (over
        the steps when ``max_steps`` is set).
    lr_patience, lr_factor, lr_min
        The plateau schedule; ``lr_min`` is the cosine's end too.
    lr_smoothing
        What the plateau schedule watches: 0 (the paper's) the loss of each
        mini-batch; ``a`` in (0, 1) an exponential moving average of it,
        ``a * previous + (1 - a) * batch`` (a window of about ``1 / (1 - a)``
        steps), so that one lucky batch does not start the patience count.
    replay
        Worst-fitted samples of the previous batch replayed each step
        (public code: 16; paper: 0).
    starts, start_share
        ``starts`` k > 1 initialises k networks and keeps one by successive
        halving within ``start_share`` of the training time (see
        :meth:`SyReNets._halve`); 1 (the paper's) trains one network.
    compile
        Compile the training pass (selection, transform and loss) with
        ``torch.compile``; see the module docstring.
    refine
        Run the exact-recovery refinement at the end (a separate variant).
    post_fraction
        Share of the budget reserved for pruning and refinement after training.
    """

    layers: Annotated[int, Range(1)] = 3
    heads: Annotated[int, Range(1)] = 12
    inputs: typing.Literal["q_qd", "q_qd_qdd"] = "q_qd"
    operators: tuple[str, ...] = ("sum", "prod", "sin", "cos")
    latent: Annotated[int, Range(1)] = 16
    ae_hidden: Annotated[int, Range(1)] = 128
    head_hidden: Annotated[int, Range(1)] = 64
    lambda_contractive: Annotated[float, Range(0)] = 1.0
    lambda_entropy: Annotated[float, Range(0)] = 1e-3
    lambda_diversity: Annotated[float, Range(0)] = 1.0
    contractive_probes: Annotated[int, Range(0)] = 1
    lr_schedule: typing.Literal["plateau", "cosine"] = "plateau"
    lr_patience: Annotated[int, Range(0)] = 1000
    lr_factor: Annotated[float, Range(0, 1, low_open=True, high_open=True)] = 0.1
    lr_min: Annotated[float, Range(0)] = 1e-5
    lr_smoothing: Annotated[float, Range(0, 1, high_open=True)] = 0.0
    replay: Annotated[int, Range(0)] = 0
    starts: Annotated[int, Range(1)] = 1
    start_share: Annotated[float, Range(0, 1, low_open=True, high_open=True)] = 0.5
    compile: bool = False
    refine: bool = True
    post_fraction: Annotated[float, Range(0, 1, high_open=True)] = 0.1

    def validate(self) -> None:
        bad = [op for op in self.operators if op not in BINARY + UNARY]
        if bad or not self.operators:
            raise ConfigError(f"syrenets: unknown operator(s) {bad}; choose from {', '.join(BINARY + UNARY)}")
        if len(set(self.operators)) != len(self.operators):
            raise ConfigError("syrenets: operators must not repeat")


# -- candidates ------------------------------------------------------------------------

class CandidateSpec:
    """The candidate terms of a layer with ``n`` inputs, in order.

    ``names(symbols)`` returns them as sympy expressions; :meth:`__call__`
    evaluates them on a batch.
    """

    def __init__(self, n: int, operators: tuple[str, ...]):
        self.n, self.operators = n, tuple(operators)
        i, j = np.triu_indices(n)
        self.I, self.J = torch.as_tensor(i), torch.as_tensor(j)
        self.offdiag = torch.as_tensor(i != j)
        ui, uj = np.triu_indices(n, k=1)
        self.Ui, self.Uj = torch.as_tensor(ui), torch.as_tensor(uj)
        sizes = {"sum": len(i), "prod": len(i), "diff": len(ui), "sin": n, "cos": n, "exp": n}
        self.size = sum(sizes[op] for op in self.operators)
        # linear operators as constant matrices: one matrix product instead of two
        # gathers (whose backward is a slower scatter)
        self._linear = {}
        for op in ("sum", "diff"):
            if op in self.operators:
                rows, cols = (i, j) if op == "sum" else (ui, uj)
                A = np.zeros((n, len(rows)))
                A[rows, np.arange(len(rows))] = 1.0
                off = rows != cols
                A[cols[off], np.arange(len(rows))[off]] += 1.0 if op == "sum" else -1.0
                self._linear[op] = torch.as_tensor(A)
        self._flat_triu = torch.as_tensor(i * n + j)
        self._cache: dict = {}

    def _matrix(self, op: str, like: torch.Tensor) -> torch.Tensor:
        if torch.compiler.is_compiling():  # a constant of the graph; filling the cache would guard on it
            return self._linear[op].to(dtype=like.dtype, device=like.device)
        key = (op, like.dtype, like.device)
        if key not in self._cache:
            self._cache[key] = self._linear[op].to(dtype=like.dtype, device=like.device)
        return self._cache[key]

    def __call__(self, u: torch.Tensor) -> torch.Tensor:
        parts = []
        for op in self.operators:
            if op in ("sum", "diff"):
                parts.append(u @ self._matrix(op, u))
            elif op == "prod":
                outer = (u.unsqueeze(2) * u.unsqueeze(1)).reshape(u.shape[0], -1)
                parts.append(outer[:, self._flat_triu])
            elif op == "sin":
                parts.append(torch.sin(u))
            elif op == "cos":
                parts.append(torch.cos(u))
            elif op == "exp":
                parts.append(torch.exp(u))
        return torch.cat(parts, dim=1)

    def tangent(self, X: torch.Tensor, w: torch.Tensor, k: int) -> torch.Tensor:
        """The candidates with their derivatives, propagated forward.

        ``X`` is ``(B, 1 + m + k, n)``: for each input, its value, its gradient
        over ``m`` coordinates ``z``, and the derivative of its gradient's last
        ``k`` components along the per-sample direction ``w`` (``(B, m)``), i.e.
        those rows of ``Hess(u) w``. Returns the same rows for the candidates,
        ``(B, 1 + m + k, size)``, by the product and chain rules: for
        ``a b``, ``H w = a H_b w + b H_a w + grad a (grad b . w) + grad b (grad a . w)``;
        for ``f(a)``, ``H w = f'(a) H_a w + f''(a) grad a (grad a . w)``.
        """
        m = X.shape[1] - 1 - k
        U, G, T = X[:, :1], X[:, 1:1 + m], X[:, 1 + m:]
        Gk = G[:, m - k:]                          # the gradients' last k components
        d = torch.bmm(w.unsqueeze(1), G)          # (B, 1, n): each input's derivative along w
        parts = []
        for op in self.operators:
            if op in ("sum", "diff"):
                parts.append(X @ self._matrix(op, X))
            elif op == "prod":
                I, J = self.I, self.J
                UI, UJ, GI, GJ, TI, TJ = U[..., I], U[..., J], G[..., I], G[..., J], T[..., I], T[..., J]
                dI, dJ, GkI, GkJ = d[..., I], d[..., J], Gk[..., I], Gk[..., J]
                parts.append(torch.cat([UI * UJ, UI * GJ + UJ * GI, UI * TJ + UJ * TI + GkI * dJ + GkJ * dI], 1))
            else:  # f(a): f', f'' from the value
                if op == "sin":
                    f, f1 = torch.sin(U), torch.cos(U)
                    f2 = -f
                elif op == "cos":
                    f, s = torch.cos(U), torch.sin(U)
                    f1, f2 = -s, -f
                else:  # exp
                    f = f1 = f2 = torch.exp(U)
                parts.append(torch.cat([f, f1 * G, f1 * T + f2 * Gk * d], 1))
        return torch.cat(parts, dim=2)

    def symbolic(self, u: list) -> list:
        out = []
        I, J = self.I.tolist(), self.J.tolist()
        for op in self.operators:
            if op == "sum":
                out += [u[a] if a == b else u[a] + u[b] for a, b in zip(I, J)]
            elif op == "prod":
                out += [u[a] * u[b] for a, b in zip(I, J)]
            elif op == "diff":
                out += [u[a] - u[b] for a, b in zip(self.Ui.tolist(), self.Uj.tolist())]
            elif op in ("sin", "cos", "exp"):
                f = getattr(sympy, op)
                out += [f(v) for v in u]
        return out


def _uniform(shape, bound, generator=None, dtype=torch.float64):
    return (torch.rand(shape, generator=generator, dtype=dtype) * 2 - 1) * bound


def _layer_norm(x: torch.Tensor) -> torch.Tensor:
    return F.layer_norm(x, x.shape[-1:])


class HeadsOutput(torch.autograd.Function):
    """``(W * h.unsqueeze(1)).sum(-1)`` for ``W`` (heads, C, k) and ``h``
    (heads, k): every head's output layer over the candidates. With
    ``hidden_first``, ``W`` is stored as (heads, k, C) and the product is
    ``(W * h.unsqueeze(-1)).sum(1)``, the same numbers.

    Autograd's backward of the broadcast product forms two tensors of ``W``'s
    size (2.3 MB in the public configuration): the weights' gradient, and
    ``g * W`` before summing it into ``h``'s. This backward forms only the
    first and gets ``h``'s gradient from one batched product, ``g^T W``.
    (The forward keeps the broadcast product: ``torch.bmm`` of a matrix and
    a vector was twice as slow on the CPU.)

    The (heads, k, C) layout is for the compiled pass. Inductor's generated
    code sums the (heads, C, k) product over its contiguous last axis, 64
    numbers for each of the 4,536 outputs of a layer, and each such sum ends
    in a horizontal reduction of a vector register, which took most of the
    three forward kernels' time (0.23 ms a layer; 0.13 ms in the other
    layout, ``python -m bench syrenets-profile --compiled``). Over the
    middle axis, the sums are vertical, along C. Eagerly, ATen's kernels
    were not faster with it, so the eager pass keeps (heads, C, k).
    """

    @staticmethod
    def forward(ctx, W: torch.Tensor, h: torch.Tensor, hidden_first: bool = False) -> torch.Tensor:
        ctx.save_for_backward(W, h)
        ctx.hidden_first = hidden_first
        return (W * h.unsqueeze(-1)).sum(1) if hidden_first else (W * h.unsqueeze(1)).sum(-1)

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g: torch.Tensor):
        W, h = ctx.saved_tensors
        gW = gh = None
        if ctx.hidden_first:
            if ctx.needs_input_grad[0]:
                gW = h.unsqueeze(-1) * g.unsqueeze(1)
            if ctx.needs_input_grad[1]:
                gh = (W * g.unsqueeze(1)).sum(-1)
        else:
            if ctx.needs_input_grad[0]:
                gW = g.unsqueeze(-1) * h.unsqueeze(1)
            if ctx.needs_input_grad[1]:
                gh = torch.bmm(g.unsqueeze(1), W).squeeze(1)
        return gW, gh, None


class Gram(torch.autograd.Function):
    """``W W^T``, whose backward is one matrix product, ``(G + G^T) W``;
    autograd's takes two, ``G W`` and ``G^T W``, each as costly as the
    forward."""

    @staticmethod
    def forward(ctx, W: torch.Tensor) -> torch.Tensor:
        ctx.save_for_backward(W)
        return W @ W.T

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g: torch.Tensor):
        (W,) = ctx.saved_tensors
        return (g + g.T) @ W


class SyReNet(torch.nn.Module):
    """The network; :meth:`select` is the training pass, :meth:`evaluate` the frozen function."""

    def __init__(self, n_x: int, cfg: SyReNetsConfig):
        super().__init__()
        self.n_x, self.cfg = n_x, cfg
        H, d, L = cfg.heads, cfg.latent, cfg.layers
        self.spec = CandidateSpec(n_x + H, cfg.operators)
        C = self.spec.size
        self.C = C
        k = cfg.head_hidden
        # the shared contractive auto-encoder (the only biases of the model)
        self.enc = torch.nn.ModuleList([torch.nn.Linear(C, cfg.ae_hidden), torch.nn.Linear(cfg.ae_hidden, cfg.ae_hidden),
                                        torch.nn.Linear(cfg.ae_hidden, d)])
        self.dec = torch.nn.ModuleList([torch.nn.Linear(d, cfg.ae_hidden), torch.nn.Linear(cfg.ae_hidden, cfg.ae_hidden),
                                        torch.nn.Linear(cfg.ae_hidden, C)])
        # per layer (separate tensors: indexing one stacked tensor would make its
        # backward fill a zero gradient of the whole stack for every layer)
        def per_layer(shape, bound, reduce_last=False):
            return torch.nn.ParameterList(
                [torch.nn.Parameter(_uniform(shape, bound).sum(-1) if reduce_last else _uniform(shape, bound)) for _ in range(L)]
            )

        self.Q = per_layer((d, d), 1 / math.sqrt(d))            # row-wise linear map of the Gram matrix
        self.Wq = per_layer((H, d), 1 / math.sqrt(d))           # weighted sum d x d -> d, per head
        self.W1 = per_layer((H, k, d), 1 / math.sqrt(d))        # head hidden layer
        self.W2 = per_layer((H, C, k), 1 / math.sqrt(k))        # head output over the candidates
        if cfg.compile:  # the same weights, stored (H, k, C) for the compiled pass (see HeadsOutput)
            for w in self.W2:
                w.data = w.data.transpose(1, 2).contiguous()
        # scale: row sums of a C x C layer on a vector of ones (see the module docstring)
        self.S = per_layer((H, C, C), 1 / math.sqrt(C), reduce_last=True)
        # gate: sigmoid(g1 . P_j + g2 . prod of the previous layer's distributions)
        self.G1 = per_layer((H, C), 1 / math.sqrt(2 * C))
        self.G2 = per_layer((H, C), 1 / math.sqrt(2 * C))

    # -- pieces -------------------------------------------------------------------
    def encode(self, v: torch.Tensor):
        a1 = self.enc[0](v)
        h1 = F.softplus(a1)
        a2 = self.enc[1](h1)
        z = self.enc[2](F.softplus(a2))
        return z, a1, a2

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        h = F.softplus(self.dec[0](z))
        h = F.softplus(self.dec[1](h))
        return self.dec[2](h)

    def contractive(self, a1: torch.Tensor, a2: torch.Tensor, probes: int = 0, K: torch.Tensor | None = None,
                    groups: int = 1) -> torch.Tensor:
        """Mean squared entry of the encoder Jacobian, averaged over rows.

        ``probes == 0``: exact, in closed form. ``probes > 0``: Hutchinson's
        unbiased estimate ``E ||J^T e||^2`` with that many Rademacher vectors
        ``e``, shared by the rows of a group: the rows are ``groups`` equal
        blocks (the layers' batches, stacked), each with its own vectors.
        16 / probes times cheaper. ``K = W1 W1^T`` may be passed in.
        """
        W1, W2, W3 = self.enc[0].weight, self.enc[1].weight, self.enc[2].weight
        s1, s2 = torch.sigmoid(a1), torch.sigmoid(a2)  # softplus' = sigmoid
        if K is None:
            K = Gram.apply(W1)  # (h, h)
        if probes == 0:
            M = torch.matmul(W3.unsqueeze(0) * s2.unsqueeze(1), W2) * s1.unsqueeze(1)  # (B, d, h) = J W1^+
        else:
            rows, h = a1.shape[0] // groups, a1.shape[1]
            e = torch.randint(0, 2, (groups, probes, W3.shape[0]), dtype=W3.dtype, device=W3.device) * 2 - 1
            s1, s2 = s1.view(groups, 1, rows, h), s2.view(groups, 1, rows, h)
            M = ((e @ W3).unsqueeze(2) * s2) @ W2 * s1  # (groups, probes, rows, h) = e^T J W1^+
            M = M.transpose(1, 2).reshape(groups * rows, probes, h) / math.sqrt(probes)
        sq = (torch.matmul(M, K) * M).sum(dim=(1, 2))  # ||J_b||_F^2 (exact or estimated)
        return sq.mean() / (W3.shape[0] * W1.shape[1])

    def heads(self, layer: int, G: torch.Tensor, prev_prod: torch.Tensor):
        """Selection of every head of ``layer`` at once: (P, phi, weights)."""
        # rows of G mapped by Q, then each head's weighted sum over them: Wq (G Q^T)^T
        a = (self.Wq[layer] @ self.Q[layer]) @ G.T                 # (H, d)
        hidden = F.softplus(_layer_norm((self.W1[layer] * a.unsqueeze(1)).sum(-1)))
        logits = _layer_norm(HeadsOutput.apply(self.W2[layer], hidden, self.cfg.compile))
        P = torch.softmax(logits, dim=-1)                          # (H, C)
        phi = torch.sigmoid((self.G1[layer] * P).sum(-1) + self.G2[layer] @ prev_prod)  # (H,)
        return P, phi, phi.unsqueeze(1) * P * self.S[layer]

    # -- passes -------------------------------------------------------------------
    def select(self, x: torch.Tensor):
        """Training pass on a batch: (output, frozen weights, auxiliary losses)."""
        cfg = self.cfg
        B, H = x.shape[0], cfg.heads
        h = x.new_zeros(B, H)
        prev = x.new_full((self.C,), (1.0 / H) ** H)
        weights, parts = [], []
        for layer in range(cfg.layers):
            v = self.spec(torch.cat([x, h], dim=1))
            vn = _layer_norm(v)
            z, a1, a2 = self.encode(vn)
            zn = z / z.norm(dim=0, keepdim=True).clamp_min(1e-12)
            G = zn.T @ zn
            P, phi, W = self.heads(layer, G, prev)
            p = phi.unsqueeze(1) * P
            prev = p.clamp_min(1e-14).prod(dim=0)
            h = v @ W.T
            weights.append(W)
            parts.append((vn, z, a1, a2, p))
        # the layers' auto-encoder and selection losses, summed over the layers, in one pass each
        L = cfg.layers
        normed, latents, pre1, pre2, selections = zip(*parts)
        ae_loss = L * F.mse_loss(self.decode(torch.cat(latents)), torch.cat(normed))
        if cfg.lambda_contractive:
            W1 = self.enc[0].weight
            penalty = self.contractive(torch.cat(pre1), torch.cat(pre2), cfg.contractive_probes, Gram.apply(W1), groups=L)
            ae_loss = ae_loss + L * cfg.lambda_contractive * penalty
        return h.sum(dim=1), weights, ae_loss + self._diversity(torch.stack(selections))

    def _diversity(self, p: torch.Tensor) -> torch.Tensor:
        """``lambda2 * mean_j H(p_j) - lambda3 * mean_{j' != j} H(p_j', p_j)``,
        summed over the layers when ``p`` stacks them (``(layers, H, C)``).

        With ``H(a, b) = -sum_c a_c log b_c``, the sum over all ordered pairs
        is ``-sum_c (sum_j' p_j'c)(sum_j log p_jc)``, so no H x H matrix is formed.
        """
        cfg = self.cfg
        H = p.shape[-2]
        logp = torch.log(p + EPS_LOG)
        diagonal = -(p * logp).sum()
        everything = -(p.sum(-2) * logp.sum(-2)).sum()
        off = (everything - diagonal) / max(H * (H - 1), 1)
        return cfg.lambda_entropy * diagonal / H - cfg.lambda_diversity * off

    def evaluate(self, x: torch.Tensor, weights: list[torch.Tensor]) -> torch.Tensor:
        """The frozen function: each layer's heads are fixed weighted sums of its candidates."""
        h = x.new_zeros(x.shape[0], self.cfg.heads)
        for W in weights:
            h = self.spec(torch.cat([x, h], dim=1)) @ W.T
        return h.sum(dim=1)

    def evaluate_tangent(self, x: torch.Tensor, weights: list[torch.Tensor], w: torch.Tensor, k: int) -> torch.Tensor:
        """:meth:`evaluate` with its derivatives (see :meth:`CandidateSpec.tangent`)
        over the first ``m = w.shape[1]`` inputs; the others are constants.
        Returns ``(B, 1 + m + k)``: the value, the gradient, and the last ``k``
        rows of ``Hess w``."""
        (B, n_x), m = x.shape, w.shape[1]
        X = x.new_zeros(B, 1 + m + k, n_x)
        X[:, 0] = x
        X[:, 1:1 + m, :m] = torch.eye(m, dtype=x.dtype, device=x.device)
        h = x.new_zeros(B, 1 + m + k, self.cfg.heads)
        for W in weights:
            h = self.spec.tangent(torch.cat([X, h], dim=2), w, k) @ W.T
        return h.sum(dim=2)


# -- the method ------------------------------------------------------------------------

@METHODS.add("syrenets", "neural", "symbolic", "paper")
class SyReNets(TorchLagrangianMethod):
    Config = SyReNetsConfig
    smoke = {"layers": 2, "heads": 3, "latent": 4, "ae_hidden": 8, "head_hidden": 8, "max_steps": 10,
             "eval_samples": 128, "refine": False}

    # -- model plumbing -------------------------------------------------------------
    def _inputs(self, q, qd, qdd=None):
        return _inputs(q, qd, qdd, self.config.inputs)

    def build_model(self, train):
        n_x = train.dof * (2 if self.config.inputs == "q_qd" else 3)
        torch.manual_seed(getattr(self, "_init_seed", self.seed))
        return SyReNet(n_x, self.config)

    def _setup(self, train, start: int = 0) -> None:
        """Model, optimiser (the scale ``S`` at ``C`` times the learning rate)
        and schedule; ``start`` k > 0 initialises the k-th network of a
        multi-start fit from its own seed."""
        cfg = self.config
        self._init_seed = self.seed if start == 0 else int(np.random.SeedSequence([self.seed, start]).generate_state(1)[0])
        self.model = self.build_model(train).to(self.dtype)
        C = self.model.C
        scale_params = list(self.model.S.parameters())
        other = [p for n, p in self.model.named_parameters() if not n.startswith("S.")]
        self.optimizer = torch.optim.Adam(
            [{"params": other, "lr": cfg.lr}, {"params": scale_params, "lr": cfg.lr * C}],
            betas=cfg.betas, **({"fused": True} if fused_adam_ok(self.dtype) else {}),
        )
        if cfg.lr_schedule == "plateau":
            self.scheduler = torch.optim.lr_scheduler.ReduceLROnPlateau(
                self.optimizer, mode="min", factor=cfg.lr_factor, patience=cfg.lr_patience, min_lr=[cfg.lr_min, cfg.lr_min * C]
            )
        else:
            self.scheduler = _Cosine(self.optimizer, [cfg.lr_min, cfg.lr_min * C])
        self._watched = None  # the loss the schedule watches (smoothed when lr_smoothing > 0)

    def train_step(self, batch: dict[str, torch.Tensor], experiment: str) -> torch.Tensor:
        """One optimisation step on ``batch``; returns each sample's squared error."""
        loss, err, weights = self._pass(batch, experiment)
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        self.optimizer.step()
        batch_loss, a = err.mean().item(), self.config.lr_smoothing
        self._watched = batch_loss if self._watched is None or not a else a * self._watched + (1 - a) * batch_loss
        self.scheduler.step(self._watched)
        self.frozen = weights
        return err

    def _pass(self, batch: dict[str, torch.Tensor], experiment: str):
        """:func:`_training_pass` of the network in place, compiled with ``compile``."""
        cfg = self.config
        target = batch["L"] if experiment == "direct" else batch["tau"]
        return (_compiled_pass() if cfg.compile else _training_pass)(
            self.model, batch["q"], batch["qd"], batch["qdd"], target, experiment, cfg.inputs, cfg.compile)

    #: what one network of a multi-start fit carries between its turns
    _SLOT = ("model", "optimizer", "scheduler", "frozen", "_watched", "_lr_drops")

    def _fit(self, train, experiment, progress):
        cfg = self.config
        self._trained = False
        t = train.tensors(self.dtype)
        generator = torch.Generator().manual_seed(self.seed)
        n, bs = len(train), min(cfg.batch_size, len(train))
        feed = {"order": torch.randperm(n, generator=generator), "cursor": 0, "generator": generator,
                "replay": torch.empty(0, dtype=torch.long), "n": n, "bs": bs}
        progress.reserve(cfg.post_fraction * progress.remaining())
        self._starts = None
        if self.warm_start:  # continue the network, its optimiser and its frozen weights
            self.model.to(self.dtype)  # back to the training arithmetic, which the optimiser's state has
            self.frozen = [w.to(self.dtype) for w in self.frozen]
            self._lr_drops = []
            if isinstance(self.scheduler, _Cosine):
                self.scheduler.start(progress)
            self._train(t, experiment, progress, feed)
            return
        slots = []
        for k in range(cfg.starts):
            self._setup(train, k)
            # frozen weights before the first step, from the first batch
            with torch.no_grad():
                self.frozen = [w.detach() for w in self.model.select(self._inputs(t["q"][:bs], t["qd"][:bs], t["qdd"][:bs]))[1]]
            if isinstance(self.scheduler, _Cosine):
                self.scheduler.start(progress)
            self._lr_drops = []
            slots.append(self._slot(feed))
        if cfg.starts > 1:  # otherwise the one network is in place
            self._halve(slots, t, experiment, progress, feed)
        del slots
        if progress.stop_reason is None:
            self._train(t, experiment, progress, feed)

    def _prepare(self, train, experiment) -> None:
        """With ``compile``, compile the training pass for the loop's batch
        sizes (with and without the replayed samples) on a network of the
        fit's shapes, before the budget starts: the compiled pass takes the
        network as an argument, so the fit's networks reuse it. A fresh
        machine (an empty compile cache) then leaves a run the same learning
        time as a warm one. The gradients are discarded; the time it took is
        the record's ``details.compile_seconds``."""
        self._compile_seconds = None
        if not self.config.compile:
            return
        start = time.perf_counter()
        cfg, dtype = self.config, getattr(torch, self.config.dtype)
        with torch.random.fork_rng():
            torch.manual_seed(0)
            model = SyReNet(train.dof * (2 if cfg.inputs == "q_qd" else 3), cfg).to(dtype)
            t = train.tensors(dtype)
            bs = min(cfg.batch_size, len(train))
            for size in sorted({bs, bs + cfg.replay}):
                idx = torch.arange(size) % len(train)
                b = {k: v[idx] for k, v in t.items()}
                target = b["L"] if experiment == "direct" else b["tau"]
                _compiled_pass()(model, b["q"], b["qd"], b["qdd"], target, experiment, cfg.inputs, True)[0].backward()
        self._compile_seconds = round(time.perf_counter() - start, 2)

    def _train(self, t, experiment, progress, feed, until: float = math.inf) -> bool:
        """Steps until ``progress.fraction()`` reaches ``until``; ``False`` once the budget is spent."""
        cfg, n, bs = self.config, feed["n"], feed["bs"]
        lr = self.optimizer.param_groups[0]["lr"]
        while progress.fraction() < until:
            if not progress.step():
                return False
            if feed["cursor"] + bs > n:
                feed["order"], feed["cursor"] = torch.randperm(n, generator=feed["generator"]), 0
            idx = torch.cat([feed["order"][feed["cursor"]:feed["cursor"] + bs], feed["replay"]])
            feed["cursor"] += bs
            err = self.train_step({k: v[idx] for k, v in t.items()}, experiment)
            if cfg.lr_schedule == "plateau" and self.optimizer.param_groups[0]["lr"] != lr:
                lr = self.optimizer.param_groups[0]["lr"]
                self._lr_drops.append([progress.steps + 1, round(progress.elapsed(), 2), lr])
            if cfg.replay:
                feed["replay"] = idx[torch.argsort(err, descending=True)[: cfg.replay]]
        return True

    def _slot(self, feed) -> dict:
        """What the network in place carries between its turns, its replayed samples included."""
        return {**{name: getattr(self, name) for name in self._SLOT}, "replay": feed["replay"]}

    def _use(self, slot: dict, feed) -> None:
        """Put a network from :meth:`_slot` in place."""
        for name in self._SLOT:
            setattr(self, name, slot[name])
        feed["replay"] = slot["replay"]

    def _halve(self, slots, t, experiment, progress, feed) -> None:
        """Successive halving over the networks of ``slots``; leaves the survivor in place.

        ``start_share`` of the loop is split into ceil(log2 k) rounds of equal
        length; in each, the networks still in train in turns for equal
        shares of the round, then the half with the higher score is dropped.
        A network's score is the lowest training MSE (on the evaluation
        subset, as the best-state tracking measures it) of all its
        evaluations so far, the scheduled ones during its turns and one at
        the end of each turn: at the high learning rates of the selection,
        the MSE of a network's current state swings by an order of
        magnitude from one evaluation to the next, and a network that has
        found the structure was dropped on such a swing (seed 5 of
        results/syrenets/studies/syrenets_300s_compiled: 0.036 after the first round, 0.38
        after the second). The replayed samples are each network's own.
        """
        alive, rounds = list(range(len(slots))), math.ceil(math.log2(len(slots)))
        begin = progress.fraction()
        length = self.config.start_share * (1 - begin) / rounds
        self._starts = {"networks": len(slots), "rounds": []}
        best = {k: math.inf for k in alive}
        for r in range(rounds):
            scores, turn = {}, length / len(alive)
            for i, k in enumerate(alive):
                self._use(slots[k], feed)
                seen = len(progress.measured)
                more = self._train(t, experiment, progress, feed, until=begin + r * length + (i + 1) * turn)
                if math.isfinite(progress.measure()):
                    best[k] = scores[k] = min(v for v in [best[k], *progress.measured[seen:]] if not math.isnan(v))
                else:  # a network whose state is no longer finite is dropped first
                    best[k] = scores[k] = math.inf
                slots[k] = self._slot(feed)
                if not more:
                    break
            ranked = sorted(scores, key=lambda k: scores[k] if math.isfinite(scores[k]) else math.inf)
            # a network whose current training MSE is not finite is listed with null and dropped first
            self._starts["rounds"].append([[k, scores[k] if math.isfinite(scores[k]) else None] for k in sorted(scores)])
            alive = ranked[: max(1, math.ceil(len(alive) / 2))] if more else ranked[:1]
            if len(alive) == 1:
                break
        self._starts["kept"] = alive[0]
        self._use(slots[alive[0]], feed)

    def _get_state(self):
        return {"model": {k: v.detach().clone() for k, v in self.model.state_dict().items()},
                "frozen": [w.clone() for w in self.frozen]}

    def _set_state(self, state):
        self.model.load_state_dict(state["model"])
        self.frozen = [w.clone() for w in state["frozen"]]

    # -- the frozen function --------------------------------------------------------------
    def _frozen_lagrangian(self, qdd=None):
        def lag(q, qd):
            return self.model.evaluate(self._inputs(q, qd, qdd), self.frozen)
        return lag

    def predict_lagrangian(self, data):
        t = data.tensors(self.dtype)
        with torch.no_grad():
            out = self.model.evaluate(self._inputs(t["q"], t["qd"], t["qdd"]), self.frozen)
        return out.double().numpy()

    def predict_torque(self, data):
        if self.config.inputs == "q_qd":
            return super().predict_torque(data)
        # qdd is an input too: each chunk's Lagrangian sees its own accelerations
        t = data.tensors(self.dtype)
        taus = []
        for sl in range(0, len(data), 8192):
            part = slice(sl, sl + 8192)
            taus.append(euler_lagrange(self._frozen_lagrangian(t["qdd"][part]), t["q"][part], t["qd"][part], t["qdd"][part]))
        return torch.cat(taus).double().numpy()

    def lagrangian(self, q, qd):
        return self._frozen_lagrangian()(q, qd)

    def not_a_lagrangian(self):
        if self.config.inputs == "q_qd":
            return None
        return ("inputs='q_qd_qdd' feeds qdd into L (the public code's choice), so its torques are not affine in "
                "qdd: no exact recovery or rollout")

    def _with_weights(self, weights, fn, *args):
        saved, self.frozen = self.frozen, weights
        try:
            return fn(*args)
        finally:
            self.frozen = saved

    # -- pruning and refinement -----------------------------------------------------------
    @property
    def dtype(self) -> torch.dtype:
        """``config.dtype`` while the network trains; float64 once the fit is
        done, for evaluation, pruning and refinement."""
        return torch.float64 if getattr(self, "_trained", False) else super().dtype

    def _post_fit(self, train, experiment, seconds_left):
        deadline = time.perf_counter() + seconds_left
        self._trained = True  # the fitted function is evaluated in float64 from here on
        self.model.to(torch.float64)
        self.frozen = [w.to(torch.float64) for w in self.frozen]
        self._variants, self._notes = {}, {}
        rng = np.random.default_rng(self.seed)
        ref = train.subset(np.sort(rng.choice(len(train), min(len(train), 1024), replace=False)))
        self._pruned = self._prune(ref, experiment)
        self._variants["pruned"] = self._pruned
        if not self.config.refine:
            return
        if self.config.inputs != "q_qd":
            refined = "refinement needs inputs='q_qd' (a Lagrangian of q and qd)"
        else:
            refined = self._refine(train, experiment, deadline)
        self._variants["refined"] = refined
        if isinstance(refined, str):
            self._notes["refined"] = refined

    def _layer_values(self, data, weights):
        """Candidate values of every layer on ``data`` (frozen function)."""
        t = data.tensors(self.dtype)
        x = self._inputs(t["q"], t["qd"], t["qdd"])
        h = x.new_zeros(x.shape[0], self.config.heads)
        values = []
        with torch.no_grad():
            for W in weights:
                v = self.model.spec(torch.cat([x, h], dim=1))
                values.append(v)
                h = v @ W.T
        return values

    def _prune(self, ref, experiment, tolerance: float = 0.1) -> "_FrozenVariant":
        """Keep the fewest terms whose frozen model is within ``tolerance`` of the full one.

        Terms (layer, head, candidate) are ranked by their contribution
        ``|w| * rms(candidate)`` on ``ref``; the smallest prefix of that ranking
        whose MSE on ``ref`` is at most ``(1 + tolerance)`` times the full
        model's is kept (found by bisection).
        """
        values = self._layer_values(ref, self.frozen)
        contrib = [W.abs() * v.pow(2).mean(0).sqrt().unsqueeze(0) for W, v in zip(self.frozen, values)]
        flat = torch.cat([c.reshape(-1) for c in contrib])
        self._ranking = (torch.argsort(flat, descending=True), [c.numel() for c in contrib])
        target = ref.target(experiment)
        full = mse(self.predict(ref, experiment), target)

        def error(k):
            return mse(self._top_terms(k).predict(ref, experiment), target)

        limit = full * (1 + tolerance) if np.isfinite(full) else np.inf
        lo, hi = 0, flat.numel()
        k = 1
        while k < hi and not error(k) <= limit:
            lo, k = k, min(2 * k, hi)
        hi = k
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if error(mid) <= limit:
                hi = mid
            else:
                lo = mid
        self._notes["pruned_terms"] = int(hi)
        self._notes["total_terms"] = int(flat.numel())
        return self._top_terms(hi)

    def _top_terms(self, k: int) -> "_FrozenVariant":
        """The frozen model with only its ``k`` largest terms (see :meth:`_prune`)."""
        order, sizes = self._ranking
        keep_flat = torch.zeros(sum(sizes), dtype=torch.bool)
        keep_flat[order[:k]] = True
        weights, keep, start = [], [], 0
        for W, size in zip(self.frozen, sizes):
            m = keep_flat[start:start + size].reshape(W.shape)
            start += size
            weights.append(W * m)
            keep.append([torch.nonzero(m[j]).flatten().tolist() for j in range(W.shape[0])])
        return _FrozenVariant(self, weights, keep)

    #: sizes of the candidate structures the refinement tries, smallest first
    REFINE_SIZES = (8, 16, 32, 64)

    def _refine(self, train, experiment, deadline):
        """Exact-recovery refinement: dominant terms, rounded structure, least squares.

        For the ``k`` dominant terms (k = 8, 16, 32, 64, and the pruned
        equation's own size when smaller), smallest first while the budget
        lasts:

        1. expand the k-term equation into additive terms ``c_i f_i``;
        2. round the constants inside each ``f_i`` (function arguments) to
           simple rationals (denominator <= 4) when within 1e-2, and drop those
           below 1e-2;
        3. refit the ``c_i`` by sequentially thresholded least squares, on ``L``
           (direct) or on ``g(f_i)`` against ``tau`` (indirect; g is linear in
           L), the threshold chosen on held-out samples.

        The refit with the lowest MSE on further held-out training samples is
        kept. The symbolic steps run under a hard time limit (they cannot be
        interrupted otherwise), so the refinement never overruns the budget.
        """
        pruned_k = self._notes["pruned_terms"]
        sizes = sorted({min(k, pruned_k) for k in self.REFINE_SIZES})
        rng = np.random.default_rng(self.seed + 1)
        pick = rng.permutation(len(train))
        fit_set = train.subset(np.sort(pick[:4096]))
        check_set = train.subset(np.sort(pick[4096:6144])) if len(train) > 4096 else fit_set
        best, best_err, reasons = None, np.inf, []
        for k in sizes:
            variant = self._top_terms(k)

            def structure(variant=variant):
                basis = {}
                for term in sympy.Add.make_args(sympy.expand(variant.expression())):
                    _, f = term.as_coeff_Mul()
                    f = _round_inner_constants(f)
                    if f.free_symbols:
                        _, f = f.as_independent(*f.free_symbols, as_Add=False)  # drop numeric factors such as sin(1/2)
                        basis[sympy.srepr(f)] = f
                return list(basis.values())

            try:
                basis = call_with_timeout(structure, deadline - time.perf_counter())
                if len(basis) > MAX_REFIT_TERMS:
                    reasons.append(f"{k} terms: {len(basis)} after expansion")
                    continue
                refit, coef = regression.fit_basis(basis, fit_set, experiment, deadline=deadline)
            except Timeout:
                reasons.append(f"{k} terms: out of budget")
                break
            model = ExpressionModel(refit, self.dof)
            err = mse(model.predict(check_set, experiment), check_set.target(experiment))
            if err < best_err:
                best, best_err = model, err
                self._notes["refined_from_terms"] = k
                self._notes["refined_terms"] = int(np.count_nonzero(coef))
        if best is None:
            return "no refit finished: " + "; ".join(reasons)
        return best

    def variants(self):
        return dict(getattr(self, "_variants", {}))

    def readable_expression(self):
        pruned = getattr(self, "_pruned", None)
        return pruned.readable_expression() if pruned is not None else None

    def record_details(self):
        notes = dict(getattr(self, "_notes", {}))
        if self.config.lr_schedule == "plateau" and hasattr(self, "_lr_drops"):
            # [step, seconds into the fit, new learning rate] for each cut of the plateau schedule
            notes["lr_drops"] = self._lr_drops
        if getattr(self, "_starts", None):
            # the multi-start fit: each round's [network, its lowest training MSE so far], and the network kept
            notes["starts"] = self._starts
        if getattr(self, "_compile_seconds", None) is not None:
            notes["compile_seconds"] = self._compile_seconds
        if notes.get("pruned_terms", 0) > MAX_READABLE_TERMS:
            notes["expression_omitted"] = f"the pruned equation keeps {notes['pruned_terms']} terms (> {MAX_READABLE_TERMS})"
        return notes

    # -- equations ---------------------------------------------------------------------
    def _input_symbols(self):
        q, qd = symbolic.coordinate_symbols(self.dof)
        syms = list(q) + list(qd)
        if self.config.inputs == "q_qd_qdd":
            syms += list(symbolic.acceleration_symbols(self.dof))
        return syms

    def expression_terms_bound(self) -> int:
        """The candidates of a layer to the power of the layers: pushing the
        frozen model through sympy takes minutes, so callers that only need
        a small expression ask this first."""
        return int(self.model.spec.size) ** len(self.frozen)

    def expression(self) -> sympy.Expr:
        """The frozen model pushed through sympy, term for term (large)."""
        return self._push(self.frozen, self.model.spec)

    def _push(self, weights, spec, keep=None) -> sympy.Expr:
        x = self._input_symbols()
        h = [sympy.Integer(0)] * self.config.heads
        for layer, W in enumerate(weights):
            cands = spec.symbolic(x + h)
            Wn = W.double().numpy()
            new_h = []
            for j in range(Wn.shape[0]):
                cols = range(Wn.shape[1]) if keep is None else keep[layer][j]
                new_h.append(sympy.Add(*[sympy.Float(Wn[j, b]) * cands[b] for b in cols]))
            h = new_h
        return sympy.Add(*h)


def _inputs(q, qd, qdd, inputs: str) -> torch.Tensor:
    return torch.cat([q, qd] if inputs == "q_qd" else [q, qd, qdd], dim=1)


def _training_pass(model: SyReNet, q, qd, qdd, target, experiment: str, inputs: str, tangent: bool):
    """(loss, each sample's squared error, frozen weights) of one batch, the
    last two detached; with ``tangent`` the indirect torques come from
    derivatives propagated forward."""
    out, weights, aux = model.select(_inputs(q, qd, qdd, inputs))
    if experiment == "direct":
        err = (out - target) ** 2
    else:
        # the torques of the fixed function the batch selected: gradients flow
        # into the selection, not through the batch statistics
        fixed = _Fixed(model, inputs, weights, qdd)
        tau = euler_lagrange(fixed if tangent else fixed.__call__, q, qd, qdd, create_graph=True)
        err = ((tau - target) ** 2).mean(dim=1)
    return err.mean() + aux, err.detach(), [w.detach() for w in weights]


def _compiled_pass():
    """:func:`_training_pass` compiled, one for the process: the model is an
    argument, so each new network reuses the compiled graphs."""
    global _COMPILED
    if _COMPILED is None:
        import torch._inductor.config

        torch._inductor.config.compile_threads = 1  # a run has one core: no pool of compiling processes
        _COMPILED = torch.compile(_training_pass, dynamic=False)
    return _COMPILED


class _Fixed:
    """The fixed function of ``weights`` as a Lagrangian of ``(q, qd)``, with
    its derivatives propagated forward (``qdd``, where it is an input, is held
    constant, as the transform's reverse passes would hold it)."""

    def __init__(self, model: SyReNet, inputs: str, weights: list[torch.Tensor], qdd: torch.Tensor):
        self.model, self.inputs, self.weights, self.qdd = model, inputs, weights, qdd

    def __call__(self, q, qd):
        return self.model.evaluate(_inputs(q, qd, self.qdd, self.inputs), self.weights)

    def tangent(self, q, qd, dq, dqd):
        dof = q.shape[1]
        out = self.model.evaluate_tangent(_inputs(q, qd, self.qdd, self.inputs), self.weights, torch.cat([dq, dqd], dim=1), dof)
        return out[:, 0], out[:, 1:1 + dof], out[:, 1 + dof:1 + 2 * dof], out[:, 1 + 2 * dof:]


class _Cosine:
    """Half a cosine from each group's learning rate to its minimum over the
    share of the budget that is left when :meth:`start` is called
    (:meth:`methods.progress.Progress.fraction`: of the steps when the run has a
    step limit, else of the time, as read at the fit's evaluations). :meth:`step` sets the rate of the
    next step, like the plateau schedule's. A warm start calls :meth:`start`
    again, and the rate anneals anew from its highest value."""

    def __init__(self, optimizer: torch.optim.Optimizer, min_lrs: list[float]):
        self.optimizer, self.min_lrs = optimizer, min_lrs
        self.max_lrs = [g["lr"] for g in optimizer.param_groups]
        self.fraction = lambda: 0.0

    def start(self, progress) -> None:
        if progress.max_steps is not None:
            # called after a step's update: the fraction for the next step, so
            # that the first step takes the highest rate and the last the lowest
            first, total = progress.steps, max(progress.max_steps - progress.steps - 1, 1)
            self.fraction = lambda: (progress.steps + 1 - first) / total
        else:  # the share of the budget spent since, as the fit's progress reads it (so a replay repeats it)
            begin = progress.fraction()
            self.fraction = lambda: (progress.fraction() - begin) / max(1.0 - begin, 1e-9)

    def step(self, loss: float) -> None:
        f = min(max(self.fraction(), 0.0), 1.0)
        for group, high, low in zip(self.optimizer.param_groups, self.max_lrs, self.min_lrs):
            group["lr"] = low + (high - low) * 0.5 * (1 + math.cos(math.pi * f))


def _round_inner_constants(f: sympy.Expr, tol: float = 1e-2) -> sympy.Expr:
    """Round every float inside ``f`` to a simple rational when within ``tol``."""
    from fractions import Fraction

    def simple(x: sympy.Float):
        value = float(x)
        if abs(value) < tol:
            return sympy.Integer(0)
        frac = Fraction(value).limit_denominator(4)
        if abs(float(frac) - value) <= tol * max(1.0, abs(value)):
            return sympy.Rational(frac.numerator, frac.denominator)
        return x

    return f.xreplace({a: simple(a) for a in f.atoms(sympy.Float)})


class _FrozenVariant(FittedModel):
    """SyReNets' frozen function with some weights pruned to zero."""

    def __init__(self, owner: SyReNets, weights: list[torch.Tensor], keep: list[list[list[int]]]):
        self.owner, self.weights, self.keep = owner, weights, keep

    def predict_lagrangian(self, data):
        return self.owner._with_weights(self.weights, self.owner.predict_lagrangian, data)

    def predict_torque(self, data):
        return self.owner._with_weights(self.weights, self.owner.predict_torque, data)

    def expression(self):
        return self.owner._push(self.weights, self.owner.model.spec, self.keep)

    def not_a_lagrangian(self):
        return self.owner.not_a_lagrangian()

    def readable_expression(self):
        """The equation, or ``None`` when it keeps more than :data:`MAX_READABLE_TERMS` weights."""
        kept = sum(len(cols) for layer in self.keep for cols in layer)
        return self.expression() if kept <= MAX_READABLE_TERMS else None
