"""A symbolic layer's terms: every pairwise sum and product of its
inputs, and their sines and cosines, in one fixed order (the package
docstring), computed by matrix products, with their forward derivatives and
their sympy form."""

from __future__ import annotations

import numpy as np
import sympy
import torch



class LayerTerms:
    """The terms of a layer with ``n`` inputs, in order.

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
        """The terms with their derivatives, propagated forward.

        ``X`` is ``(B, 1 + m + k, n)``: for each input, its value, its gradient
        over ``m`` coordinates ``z``, and the derivative of its gradient's last
        ``k`` components along the per-sample direction ``w`` (``(B, m)``), i.e.
        those rows of ``Hess(u) w``. Returns the same rows for the terms,
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
