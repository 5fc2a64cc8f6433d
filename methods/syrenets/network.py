"""The SyReNets network: its symbolic layers, the shared contractive
auto-encoder, the selection heads, and two autograd kernels written by hand
(:class:`HeadsOutput`, :class:`Gram`) whose backward passes form fewer
tensors than autograd's."""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from methods.syrenets.layer_terms import LayerTerms
from methods.syrenets.config import SyReNetsConfig

EPS_LOG = 1e-5


def _uniform(shape, bound, generator=None, dtype=torch.float64):
    return (torch.rand(shape, generator=generator, dtype=dtype) * 2 - 1) * bound


def _layer_norm(x: torch.Tensor) -> torch.Tensor:
    return F.layer_norm(x, x.shape[-1:])


def _heads_forward(W: torch.Tensor, h: torch.Tensor, hidden_first: bool) -> torch.Tensor:
    return (W * h.unsqueeze(-1)).sum(1) if hidden_first else (W * h.unsqueeze(1)).sum(-1)


def _heads_backward(W: torch.Tensor, h: torch.Tensor, g: torch.Tensor, hidden_first: bool, needs) -> tuple:
    gW = gh = None
    if hidden_first:
        if needs[0]:
            gW = h.unsqueeze(-1) * g.unsqueeze(1)
        if needs[1]:
            gh = (W * g.unsqueeze(1)).sum(-1)
    else:
        if needs[0]:
            gW = g.unsqueeze(-1) * h.unsqueeze(1)
        if needs[1]:
            gh = torch.bmm(g.unsqueeze(1), W).squeeze(1)
    return gW, gh, None


class HeadsOutput(torch.autograd.Function):
    """``(W * h.unsqueeze(1)).sum(-1)`` for ``W`` (heads, C, k) and ``h``
    (heads, k): every head's output layer over the terms. With
    ``hidden_first``, ``W`` is stored as (heads, k, C) and the product is
    ``(W * h.unsqueeze(-1)).sum(1)``, the same numbers.

    Autograd's backward of the broadcast product forms two tensors of ``W``'s
    size (2.3 MB in the public configuration): the weights' gradient, and
    ``g * W`` before summing it into ``h``'s. This backward forms only the
    first and gets ``h``'s gradient from one batched product, ``g^T W``.
    (The forward keeps the broadcast product, faster on the CPU than
    ``torch.bmm`` of a matrix and a vector.)

    The (heads, k, C) layout is for the compiled pass: inductor's generated
    code then sums along C, vertically in a vector register, instead of
    ending each sum in a horizontal reduction. The eager pass keeps
    (heads, C, k). Measured: results/syrenets/design.md.

    Several networks' heads at once (under ``vmap``, :mod:`methods.syrenets.stacked`)
    take :class:`_BatchedHeadsOutput`, the same computation in the form torch's
    transforms batch (:func:`heads_output` chooses). This class keeps the
    older form for one network: its ``apply`` costs 35–75 µs less, of about
    1,000 µs with its backward at the public configuration's shapes; the
    batched form everywhere made the eager step 2–3 % slower.
    """

    @staticmethod
    def forward(ctx, W: torch.Tensor, h: torch.Tensor, hidden_first: bool = False) -> torch.Tensor:
        ctx.save_for_backward(W, h)
        ctx.hidden_first = hidden_first
        return _heads_forward(W, h, hidden_first)

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g: torch.Tensor):
        W, h = ctx.saved_tensors
        return _heads_backward(W, h, g, ctx.hidden_first, ctx.needs_input_grad)


class _BatchedHeadsOutput(torch.autograd.Function):
    """:class:`HeadsOutput` in the form ``vmap`` batches (``setup_context``, a generated vmap rule)."""

    generate_vmap_rule = True

    @staticmethod
    def forward(W: torch.Tensor, h: torch.Tensor, hidden_first: bool = False) -> torch.Tensor:
        return _heads_forward(W, h, hidden_first)

    @staticmethod
    def setup_context(ctx, inputs, output) -> None:
        ctx.save_for_backward(inputs[0], inputs[1])
        ctx.hidden_first = inputs[2] if len(inputs) > 2 else False

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g: torch.Tensor):
        W, h = ctx.saved_tensors
        return _heads_backward(W, h, g, ctx.hidden_first, ctx.needs_input_grad)


class Gram(torch.autograd.Function):
    """``W W^T``, whose backward is one matrix product, ``(G + G^T) W``;
    autograd's takes two, ``G W`` and ``G^T W``, each as costly as the
    forward. Under ``vmap``, :class:`_BatchedGram` (see :class:`HeadsOutput`)."""

    @staticmethod
    def forward(ctx, W: torch.Tensor) -> torch.Tensor:
        ctx.save_for_backward(W)
        return W @ W.T

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g: torch.Tensor):
        (W,) = ctx.saved_tensors
        return (g + g.T) @ W


class _BatchedGram(torch.autograd.Function):
    """:class:`Gram` in the form ``vmap`` batches."""

    generate_vmap_rule = True

    @staticmethod
    def forward(W: torch.Tensor) -> torch.Tensor:
        return W @ W.T

    @staticmethod
    def setup_context(ctx, inputs, output) -> None:
        ctx.save_for_backward(inputs[0])

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g: torch.Tensor):
        (W,) = ctx.saved_tensors
        return (g + g.T) @ W


def _batched(*xs: torch.Tensor) -> bool:
    """Whether any of ``xs`` is one slice of a ``vmap``'s batch."""
    return any(torch._C._functorch.is_batchedtensor(x) for x in xs)


def heads_output(W: torch.Tensor, h: torch.Tensor, hidden_first: bool = False) -> torch.Tensor:
    """:class:`HeadsOutput`, or under ``vmap`` its batched form."""
    return (_BatchedHeadsOutput if _batched(W, h) else HeadsOutput).apply(W, h, hidden_first)


def gram(W: torch.Tensor) -> torch.Tensor:
    """:class:`Gram`, or under ``vmap`` its batched form."""
    return (_BatchedGram if _batched(W) else Gram).apply(W)


class SyReNet(torch.nn.Module):
    """The network; :meth:`select` is the training pass, :meth:`evaluate` the frozen function."""

    def __init__(self, n_x: int, cfg: SyReNetsConfig):
        super().__init__()
        self.n_x, self.cfg = n_x, cfg
        H, d, L = cfg.heads, cfg.latent, cfg.layers
        self.spec = LayerTerms(n_x + H, cfg.operators)
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
        self.W2 = per_layer((H, C, k), 1 / math.sqrt(k))        # head output over the terms
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
                    groups: int = 1, e: torch.Tensor | None = None) -> torch.Tensor:
        """Mean squared entry of the encoder Jacobian, averaged over rows.

        ``probes == 0``: exact, in closed form. ``probes > 0``: Hutchinson's
        unbiased estimate ``E ||J^T e||^2`` with that many Rademacher vectors
        ``e``, shared by the rows of a group: the rows are ``groups`` equal
        blocks (the layers' batches, stacked), each with its own vectors.
        16 / probes times cheaper. ``K = W1 W1^T`` may be passed in, and so may
        the vectors ``e`` (:meth:`probe_vectors`), drawn by the caller.
        """
        W1, W2, W3 = self.enc[0].weight, self.enc[1].weight, self.enc[2].weight
        s1, s2 = torch.sigmoid(a1), torch.sigmoid(a2)  # softplus' = sigmoid
        if K is None:
            K = gram(W1)  # (h, h)
        if probes == 0:
            M = torch.matmul(W3.unsqueeze(0) * s2.unsqueeze(1), W2) * s1.unsqueeze(1)  # (B, d, h) = J W1^+
        else:
            rows, h = a1.shape[0] // groups, a1.shape[1]
            if e is None:
                e = self.probe_vectors(groups, probes)
            s1, s2 = s1.view(groups, 1, rows, h), s2.view(groups, 1, rows, h)
            M = ((e @ W3).unsqueeze(2) * s2) @ W2 * s1  # (groups, probes, rows, h) = e^T J W1^+
            M = M.transpose(1, 2).reshape(groups * rows, probes, h) / math.sqrt(probes)
        sq = (torch.matmul(M, K) * M).sum(dim=(1, 2))  # ||J_b||_F^2 (exact or estimated)
        return sq.mean() / (W3.shape[0] * W1.shape[1])

    def probe_vectors(self, groups: int, probes: int) -> torch.Tensor:
        """``groups`` x ``probes`` Rademacher vectors of the latent size, from torch's generator of the device."""
        W3 = self.enc[2].weight
        return torch.randint(0, 2, (groups, probes, W3.shape[0]), dtype=W3.dtype, device=W3.device) * 2 - 1

    def heads(self, layer: int, G: torch.Tensor, prev_prod: torch.Tensor):
        """Selection of every head of ``layer`` at once: (P, phi, weights)."""
        # rows of G mapped by Q, then each head's weighted sum over them: Wq (G Q^T)^T
        a = (self.Wq[layer] @ self.Q[layer]) @ G.T                 # (H, d)
        hidden = F.softplus(_layer_norm((self.W1[layer] * a.unsqueeze(1)).sum(-1)))
        logits = _layer_norm(heads_output(self.W2[layer], hidden, self.cfg.compile))
        P = torch.softmax(logits, dim=-1)                          # (H, C)
        phi = torch.sigmoid((self.G1[layer] * P).sum(-1) + self.G2[layer] @ prev_prod)  # (H,)
        return P, phi, phi.unsqueeze(1) * P * self.S[layer]

    # -- passes -------------------------------------------------------------------
    def select(self, x: torch.Tensor, probes: torch.Tensor | None = None):
        """Training pass on a batch: (output, frozen weights, auxiliary losses);
        ``probes``, the contractive penalty's vectors where the caller draws
        them (:meth:`probe_vectors` with ``layers`` groups), else drawn here."""
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
            penalty = self.contractive(torch.cat(pre1), torch.cat(pre2), cfg.contractive_probes, gram(W1), groups=L,
                                       e=probes)
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
        """The frozen function: each layer's heads are fixed weighted sums of its terms."""
        h = x.new_zeros(x.shape[0], self.cfg.heads)
        for W in weights:
            h = self.spec(torch.cat([x, h], dim=1)) @ W.T
        return h.sum(dim=1)

    def evaluate_tangent(self, x: torch.Tensor, weights: list[torch.Tensor], w: torch.Tensor, k: int) -> torch.Tensor:
        """:meth:`evaluate` with its derivatives (see :meth:`LayerTerms.tangent`)
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
