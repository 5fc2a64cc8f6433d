r"""The suite's one Euler–Lagrange transform ``g``.

For a Lagrangian :math:`L(q, \dot q)` the generalized forces are

.. math::

    \tau = \frac{d}{dt}\frac{\partial L}{\partial \dot q} - \frac{\partial L}{\partial q}
         = \frac{\partial^2 L}{\partial \dot q\,\partial \dot q}\,\ddot q
         + \frac{\partial^2 L}{\partial \dot q\,\partial q}\,\dot q
         - \frac{\partial L}{\partial q}.

It is used by data generation, by every method's indirect loss and by
evaluation, so that all of them agree on what a torque is.

Implementation
--------------
One reverse pass gives :math:`\partial L/\partial q` and
:math:`\partial L/\partial \dot q` for the whole batch (samples are independent,
so the gradient of the batch sum is the per-sample gradient). The time
derivative of :math:`\partial L/\partial \dot q` is a Hessian-vector product
with the direction :math:`u = (\dot q, \ddot q)`. Because the Hessian of
:math:`L` over :math:`z = (q, \dot q)` is symmetric, it is the
:math:`\dot q`-block of :math:`\nabla_z (\nabla_z L \cdot u)`, which a second
reverse pass gives.

The direction must be *detached* inside that product: ``qd`` is both a
variable of :math:`L` and a component of :math:`u`. Without the detach the
second pass also differentiates :math:`u` and adds :math:`\partial L/\partial q`
to the result, silently giving wrong torques.

A Lagrangian may instead supply these derivatives itself, as a method
``tangent(q, qd, dq, dqd)`` returning ``(L, dL/dq, dL/dqd, D)`` with ``D``
the derivative of :math:`\partial L/\partial \dot q` along
:math:`(dq, dqd)` (see :class:`TangentLagrangian`); the transform then calls it
with :math:`u = (\dot q, \ddot q)` and takes no reverse pass. A model that
propagates these derivatives forward through its own layers gets torques
whose loss needs one ordinary backward pass instead of the backward of a
second-order graph, which compilers can trace.
"""

from __future__ import annotations

import typing
from typing import Callable

import torch

Lagrangian = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]


class TangentLagrangian(typing.Protocol):
    """A Lagrangian that gives its own first derivatives and the derivative
    of ``dL/dqd`` along a direction, each of shape ``(batch, dof)``."""

    def __call__(self, q: torch.Tensor, qd: torch.Tensor) -> torch.Tensor: ...

    def tangent(self, q: torch.Tensor, qd: torch.Tensor, dq: torch.Tensor, dqd: torch.Tensor
                ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]: ...


def _grad_or_zeros(out: torch.Tensor, inputs: tuple[torch.Tensor, ...], create_graph: bool):
    if not out.requires_grad:
        return tuple(torch.zeros_like(x) for x in inputs)
    grads = torch.autograd.grad(out, inputs, create_graph=create_graph, allow_unused=True)
    return tuple(torch.zeros_like(x) if g is None else g for g, x in zip(grads, inputs))


def _check_shape(L: torch.Tensor, q: torch.Tensor) -> None:
    if L.shape != q.shape[:1]:
        raise ValueError(f"the Lagrangian returned shape {tuple(L.shape)}, expected ({q.shape[0]},)")


def euler_lagrange(
    lagrangian: Lagrangian,
    q: torch.Tensor,
    qd: torch.Tensor,
    qdd: torch.Tensor,
    *,
    create_graph: bool = False,
    return_lagrangian: bool = False,
):
    """Generalized forces ``tau = d/dt dL/dqd - dL/dq`` for a batch.

    Parameters
    ----------
    lagrangian
        ``L(q, qd) -> (batch,)``. It must treat samples independently. One
        with a ``tangent`` method (:class:`TangentLagrangian`) gives its own
        derivatives.
    q, qd, qdd
        Tensors of shape ``(batch, dof)``, float32 or float64.
    create_graph
        Keep the graph so that a loss on ``tau`` can be back-propagated into
        the parameters of ``lagrangian`` (training). Leave ``False`` for data
        generation and evaluation.
    return_lagrangian
        Also return the values of ``L``.

    Returns
    -------
    tau : Tensor of shape ``(batch, dof)``
    L : Tensor of shape ``(batch,)``, only with ``return_lagrangian=True``
    """
    if not (q.shape == qd.shape == qdd.shape) or q.dim() != 2:
        raise ValueError(
            f"q, qd, qdd must share one (batch, dof) shape; got "
            f"{tuple(q.shape)}, {tuple(qd.shape)}, {tuple(qdd.shape)}"
        )
    tangent = getattr(lagrangian, "tangent", None)  # a TangentLagrangian
    if tangent is not None:
        L, dL_dq, _, along = tangent(q, qd, qd.detach(), qdd.detach())
        _check_shape(L, q)
        tau = along - dL_dq
        if not create_graph:
            tau, L = tau.detach(), L.detach()
        return (tau, L) if return_lagrangian else tau
    direction_qd = qd.detach()
    direction_qdd = qdd.detach()
    with torch.enable_grad():
        q = q.detach().requires_grad_(True)
        qd = qd.detach().requires_grad_(True)
        L = lagrangian(q, qd)
        _check_shape(L, q)
        dL_dq, dL_dqd = _grad_or_zeros(L.sum(), (q, qd), create_graph=True)
        directional = (dL_dq * direction_qd).sum() + (dL_dqd * direction_qdd).sum()
        (hvp_qd,) = _grad_or_zeros(directional, (qd,), create_graph=create_graph)
        tau = hvp_qd - dL_dq
    if not create_graph:
        tau = tau.detach()
        L = L.detach()
    return (tau, L) if return_lagrangian else tau


def euler_lagrange_chunked(
    lagrangian: Lagrangian,
    q: torch.Tensor,
    qd: torch.Tensor,
    qdd: torch.Tensor,
    chunk: int = 1024,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Evaluation-only ``(tau, L)`` over a large batch, ``chunk`` rows at a time."""
    taus, Ls = [], []
    for start in range(0, q.shape[0], chunk):
        sl = slice(start, start + chunk)
        tau, L = euler_lagrange(lagrangian, q[sl], qd[sl], qdd[sl], return_lagrangian=True)
        taus.append(tau)
        Ls.append(L)
    return torch.cat(taus), torch.cat(Ls)
