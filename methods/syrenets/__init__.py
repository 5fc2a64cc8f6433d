"""SyReNets: Symbolic Residual Neural Networks (Valle & Haddadin, 2021).

A stack of symbolic layers. Layer ``l`` sees the system inputs ``x`` and the
outputs of the previous layer's heads, builds every term from them,
and each of its selection heads outputs a weighted sum of the terms; the
last layer's heads are summed into the Lagrangian.

Architecture (the paper's, with the public code's facts where the paper is open)
---------------------------------------------------------------------------------
* **Inputs** ``x = (q, qd)`` by default. ``inputs="q_qd_qdd"`` feeds ``qdd``
  too, as the public code did. That variant is *physically inconsistent*: a
  Lagrangian depends on ``(q, qd)`` only, and with ``qdd`` as an input the
  Euler–Lagrange transform would need third derivatives, which it (like the
  public code) silently drops by treating ``qdd`` as a constant. Its
  expression holds ``qdd``; the record keeps it, and exact recovery and the
  rollout state that they do not apply (:meth:`~methods.syrenets.method.SyReNets.not_a_lagrangian`).
* **Candidates** of a layer with inputs ``u_1..u_n``, in this order: the
  pairwise sums over the upper triangle (row-major; the diagonal stands for
  ``u_i`` itself), the pairwise products over the upper triangle (squares
  included), ``sin(u_i)``, ``cos(u_i)``. For n inputs, n(n+1)/2 + n(n+1)/2 + n
  + n terms: 378 for 6 + 12 inputs, 304 for 4 + 12. Further operators
  (``diff`` = u_i - u_j for i < j, ``exp``) can be enabled with ``operators``.
* **Shared representation block**: layer normalisation of the terms of
  each sample; a contractive auto-encoder shared by all layers (encoder
  C -> 128 -> 128 -> 16, softplus, linear latent; mirrored decoder; biases
  only here); the cosine-similarity Gram matrix of the 16 latent dimensions
  over the batch; per layer, a bias-free linear map applied to each row.
* **Selection head** (all heads of a layer are computed as one batched tensor
  operation): a bias-free weighted sum d x d -> d; a hidden layer of 64
  softplus units with layer normalisation before the activation; an output
  over the terms with layer normalisation and softmax, giving the
  selection distribution ``P`` shared by the batch; a per-term scale
  ``S``; an on-off gate ``phi = sigmoid(w1 . P_j + w2 . prod_j' p_j'(previous
  layer))``; the head outputs ``h_j = phi_j sum_b S_jb v_b P_jb`` over the raw
  terms ``v``.
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
  the fitted function is then evaluated, pruned and refined in float64.
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
  ``starts`` better.
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
  (:meth:`~methods.syrenets.layer_terms.LayerTerms.tangent`, the product and chain rules of
  ``methods/jets.py`` applied to a layer's terms at once, on tensors the
  loss differentiates), which the one Euler–Lagrange transform takes from
  :class:`~methods.syrenets.training.Fixed`'s ``tangent`` method. The two agree to rounding
  (``test_derivatives_propagated_forward_match_the_reverse_passes``). A
  compiling network stores its heads' output weights ``W2`` as (heads,
  hidden units, terms), the same numbers transposed, so that the
  generated code sums the heads' products along the terms instead of
  across a vector register (see :class:`~methods.syrenets.network.HeadsOutput`). Eager
  passes keep the reverse passes, which are faster uncompiled.

Readable equations and exact recovery (beyond the paper)
--------------------------------------------------------
The frozen model pushed through sympy (:meth:`~methods.syrenets.equations.Equations.expression`) is exact
but long, since softmax weights are never zero. After training, within the
budget (``post_fraction`` of it is reserved), two variants are derived and
reported beside the paper's model:

* ``pruned``: the fewest terms, ranked by ``|weight| * rms(term)``, whose
  frozen model is within 10 % of the full model's training MSE; its equation
  is what records store as the run's expression;
* ``refined``: the dominant terms' structure with its inner constants rounded
  to simple rationals, refitted by least squares (linear in L, and in tau
  through g), see :meth:`~methods.syrenets.equations.Equations.refine`.

Modules
-------
:mod:`~methods.syrenets.config` the hyperparameters; :mod:`~methods.syrenets.layer_terms`
a layer's terms; :mod:`~methods.syrenets.network` the network and its
two hand-written autograd kernels; :mod:`~methods.syrenets.training` one network's
training state and pass; :mod:`~methods.syrenets.multistart` successive halving over
several networks; :mod:`~methods.syrenets.equations` pruning, refinement and the
equations; :mod:`~methods.syrenets.method` the method. Why the kernels and layouts
are what they are, measured: results/syrenets/design.md.
"""

from __future__ import annotations

from methods.syrenets.config import SyReNetsConfig
from methods.syrenets.method import SyReNets

__all__ = ["SyReNets", "SyReNetsConfig"]
