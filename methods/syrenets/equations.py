"""SyReNets' equations: the frozen network pushed through sympy, the pruned
equation (the fewest terms within 10 % of the full model's training MSE)
and the refined one (the dominant terms' structure with rounded inner
constants, refitted by least squares)."""

from __future__ import annotations

import time
from fractions import Fraction

import numpy as np
import sympy
import torch

from bench.core import protocols, symbolic
from bench.physics import regression
from bench.core.data import mse
from bench.physics.models import ExpressionModel, FittedModel, NoVariant
from bench.core.timeouts import Timeout, call_with_timeout

#: the refinement gives up on pruned equations that expand into more terms
MAX_REFIT_TERMS = 2000
#: the refinement's samples: at most this many of the training data, evenly spaced
REFINE_SAMPLES = 4096
#: ... and its folds (the validation protocol's, ``auto``)
REFINE_FOLDS = 4
#: a pruned equation keeping more weights than this is not written out: its
#: text would exceed the record's 20 000 characters, and pushing it through
#: sympy grows faster than linearly (results/syrenets/design.md)
MAX_READABLE_TERMS = 512


class Equations:
    """The equations of a fitted :class:`~methods.syrenets.method.SyReNets`
    (its network ``model``, frozen weights ``frozen`` and ``config``)."""

    def _layer_values(self, data, weights):
        """Term values of every layer on ``data`` (frozen function)."""
        t = data.tensors(self.dtype, self.device)
        x = self._inputs(t["q"], t["qd"], t["qdd"])
        h = x.new_zeros(x.shape[0], self.config.heads)
        values = []
        with torch.no_grad():
            for W in weights:
                v = self.model.spec(torch.cat([x, h], dim=1))
                values.append(v)
                h = v @ W.T
        return values

    def _prune(self, ref, experiment, tolerance: float = 0.1) -> "FrozenVariant":
        """Keep the fewest terms whose frozen model is within ``tolerance`` of the full one.

        Terms (layer, head, term) are ranked by their contribution
        ``|w| * rms(term)`` on ``ref``; the smallest prefix of that ranking
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

    def _top_terms(self, k: int) -> "FrozenVariant":
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
        return FrozenVariant(self, weights, keep)

    #: sizes of the structures the refinement tries, smallest first
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
           L), the threshold chosen within each fold's fitted samples.

        The size whose refits predict the held-out samples of the validation
        protocol's folds best (:func:`bench.core.protocols.folds`, ``auto``:
        whole trajectories, regions of one trajectory's states, or blocks of
        independent samples) is kept, refitted on all of them. A size is
        refitted on all of them as soon as it predicts better than the smaller
        ones, so a larger size that runs out of budget (its symbolic expansion
        takes far longer than any refit) leaves the best refit finished, and
        the record's ``refine_left_out`` says which sizes were left out, and why. The samples
        are at most :data:`REFINE_SAMPLES` of the training data, evenly spaced
        in its order. The symbolic steps run under a hard time limit (they
        cannot be interrupted otherwise), so the refinement never overruns the
        budget.
        """
        pruned_k = self._notes["pruned_terms"]
        sizes = sorted({min(k, pruned_k) for k in self.REFINE_SIZES})
        sample = train.subset(train.evenly(REFINE_SAMPLES))
        folding = protocols.folds(sample, "auto", max_folds=REFINE_FOLDS)
        held, y = folding.indices(), sample.target(experiment).ravel()
        self._notes["refine_folds"] = folding.describe()
        best, best_err, reasons = None, np.inf, []
        for k in sizes:
            variant = self._top_terms(k)

            def structure(variant=variant):
                basis = {}
                for term in sympy.Add.make_args(sympy.expand(variant.expression())):
                    _, f = term.as_coeff_Mul()
                    f = round_inner_constants(f)
                    if f.free_symbols:
                        _, f = f.as_independent(*f.free_symbols, as_Add=False)  # drop numeric factors such as sin(1/2)
                        basis[sympy.srepr(f)] = f
                return list(basis.values())

            try:
                basis = call_with_timeout(structure, deadline - time.perf_counter())
                if len(basis) > MAX_REFIT_TERMS:
                    reasons.append(f"{k} terms: {len(basis)} after expansion")
                    continue
                library, F = regression.design(basis, sample, experiment, deadline)
                err = regression.held_out_mse(F, y, len(sample), held, deadline)
                if err < best_err:
                    coef = regression.fit_columns(F, y, len(sample), deadline=deadline, folds=held)
                    best, best_err = (k, library, coef), err
            except Timeout:
                reasons.append(f"{k} terms: out of budget")
                break
        if best is None:
            out_of_budget = bool(reasons) and reasons[-1].endswith("out of budget")
            return NoVariant("no refit finished: " + "; ".join(reasons), "timeout" if out_of_budget else "failed")
        k, library, coef = best
        self._notes["refined_from_terms"] = k
        self._notes["refined_terms"] = int(np.count_nonzero(coef))
        self._notes["refined_heldout_mse"] = best_err
        if reasons:
            self._notes["refine_left_out"] = "; ".join(reasons)
        return ExpressionModel(library.lagrangian(coef), self.dof)

    def variants(self):
        return dict(getattr(self, "_variants", {}))

    def readable_expression(self):
        pruned = getattr(self, "_pruned", None)
        return pruned.readable_expression() if pruned is not None else None

    # -- equations ---------------------------------------------------------------------
    def _input_symbols(self):
        q, qd = symbolic.coordinate_symbols(self.dof)
        syms = list(q) + list(qd)
        if self.config.inputs == "q_qd_qdd":
            syms += list(symbolic.acceleration_symbols(self.dof))
        return syms

    def expression_terms_bound(self) -> int:
        """The terms of a layer to the power of the layers: pushing the
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


def round_inner_constants(f: sympy.Expr, tol: float = 1e-2) -> sympy.Expr:
    """Round every float inside ``f`` to a simple rational when within ``tol``."""
    def simple(x: sympy.Float):
        value = float(x)
        if abs(value) < tol:
            return sympy.Integer(0)
        frac = Fraction(value).limit_denominator(4)
        if abs(float(frac) - value) <= tol * max(1.0, abs(value)):
            return sympy.Rational(frac.numerator, frac.denominator)
        return x

    return f.xreplace({a: simple(a) for a in f.atoms(sympy.Float)})


class FrozenVariant(FittedModel):
    """SyReNets' frozen function with some weights pruned to zero; ``owner``
    evaluates it (``_with_weights``) and writes it out (``_push``)."""

    def __init__(self, owner: Equations, weights: list[torch.Tensor], keep: list[list[list[int]]]):
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
