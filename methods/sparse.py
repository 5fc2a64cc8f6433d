"""Sparse Lagrangian regression, in the manner of Lagrangian-SINDy / xL-SINDy
(Purnomo & Hayashibe, 2023).

The Lagrangian is sought as a sparse combination of a library of terms built
generically from the system's coordinates:

* position terms ``P``: 1; ``sin q_i`` and ``cos q_i`` of every angle;
  ``sin(q_i - q_j)`` and ``cos(q_i - q_j)`` of every pair of angles; ``q_k``
  and ``q_k^2`` of every linear coordinate, and ``q_k sin q_i``,
  ``q_k cos q_i`` for a linear coordinate and an angle;
* velocity terms ``V``: 1, ``qd_i`` and ``qd_i qd_j`` (degree <= 2);
* the library is every product ``v * p``; ``v = 1`` gives the potential terms.

Gauge: in the indirect experiment the library is mapped through ``g``, and
terms whose image is zero (constants, total time derivatives such as
``qd_i cos q_i``) or a combination of earlier terms' images are removed
(:func:`bench.physics.regression.independent_columns`), so the fit is unique. Columns
are scaled to unit RMS (the scale of ``L`` is fixed by ``tau``, or by ``L``
itself in the direct experiment).

Fit: sequentially thresholded least squares, on ``g(library)`` against
``tau`` (indirect) or on the library against ``L`` (direct), with the
threshold chosen on held-out samples (:func:`bench.physics.regression.fit_columns`: the validation
protocol's folds, :mod:`bench.core.folds`, where the data name trajectories; a 3:1 split of independent samples).
It is the "knows a good basis" reference: when the true Lagrangian lies in
the library's span, it is recovered exactly.

Size
----
The library grows as the fourth power of the coordinates (2052 terms at 7
angles, 97 251 at 20). The design matrix is held in memory: at most
:data:`MAX_DESIGN_BYTES`, so larger libraries are fitted on fewer samples
(the record says how many), and a library whose smallest useful design (two
rows per term) would exceed it is not applicable, with the reason.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import numpy as np
import sympy

from bench.physics import regression
from bench.core.folds import folds
from bench.core.data import Dataset
from bench.physics.models import ExpressionModel
from bench.physics.terms import TermLibrary, lagrangian_library, lagrangian_library_size
from methods.base import METHODS, ExpressionMethod
from methods.config import MethodConfig, Range
from methods.progress import Progress


#: the most memory the design matrix may take
MAX_DESIGN_BYTES = 256 * 2**20


@dataclass(frozen=True)
class SparseConfig(MethodConfig):
    """Attributes: ``samples`` used for the fit; ``threshold`` (None: validated)."""

    samples: Annotated[int, Range(1)] = 4096
    threshold: Annotated[float, Range(0)] | None = None


@METHODS.add("sparse", "symbolic", "library")
class SparseLagrangian(ExpressionMethod):
    title = "sparse regression"
    #: what the method is, for docs/methods_and_systems.md (generated from the registry)
    summary = ("sparse Lagrangian regression (Lagrangian-SINDy style) over a library built from the coordinates, "
               "with the gauge removed; the library grows as the fourth power of the coordinates (2052 terms at "
               "7), so its design matrix is capped at 256 MB (fewer samples, recorded) and a library too large "
               "for even that is not applicable")
    Config = SparseConfig
    smoke = {"samples": 64, "max_steps": 1, "eval_samples": 128}
    work = 1  # one solve

    @classmethod
    def not_applicable_reason(cls, experiment, system=None):
        reason = super().not_applicable_reason(experiment, system)
        if reason or system is None:
            return reason
        terms = lagrangian_library_size(system.dof, system.kinds)
        smallest = 2 * terms * terms * 8
        if smallest > MAX_DESIGN_BYTES:
            return (f"the library has {terms:,} terms for {system.dof} coordinates; even its smallest least-squares "
                    f"problem (two rows a term) needs {smallest / 2**20:,.0f} MB, above the "
                    f"{MAX_DESIGN_BYTES // 2**20} MB this method allows")
        return None

    def _fit(self, train: Dataset, experiment: str, progress: Progress) -> None:
        kinds = self.system.kinds if self.system is not None else ("angle",) * train.dof
        self.library = lagrangian_library(train.dof, kinds)
        rows = experiment.rows(train.dof)
        fits = max(1, MAX_DESIGN_BYTES // (8 * len(self.library) * rows))  # samples whose design fits in memory
        self.samples = min(len(train), self.config.samples, fits)
        rng = np.random.default_rng(self.seed)
        sub = train.subset(np.sort(rng.choice(len(train), self.samples, replace=False)))
        self.model = ExpressionModel(sympy.Integer(0), train.dof)
        while progress.step():
            F = self.library.design(sub, experiment, deadline=progress.deadline)
            keep = regression.independent_columns(F, deadline=progress.deadline)
            y = sub.target(experiment).ravel()
            coef = regression.fit_columns(F[:, keep], y, len(sub), self.config.threshold, deadline=progress.deadline,
                                          folds=folds(sub).indices() if sub.trajectories() else None)
            self.kept_terms = len(keep)
            kept = TermLibrary(self.library[k] for k in keep)
            self.model = ExpressionModel(kept.lagrangian(coef), train.dof)
            progress.stop("solved")

    def record_details(self):
        return {"library": len(self.library), "independent_terms": getattr(self, "kept_terms", None),
                "samples": getattr(self, "samples", None)}
