"""The test MSE of ``bench select``'s stack (:mod:`bench.evaluation.stacking`),
read after the choice, to score: the weighted sum of the candidates' saved
models' torques on the test data against its torques. The one module of
``bench select`` that opens the test split (pyproject.toml's contract "Only the
scorers open the test split")."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bench.core.data import Dataset, mse
from bench.core.scoring import scoring
from bench.evaluation.stacking import combine
from methods.saving import load_model


def test_mse(models: dict[str, str | Path], weights: dict[str, float], test: Dataset) -> float:
    """The MSE on ``test``'s torques of the sum of ``models``' (name: model file) torques, weighted by
    ``weights``; a candidate of weight zero is not loaded."""
    names = [n for n in models if weights.get(n, 0.0) > 0.0]
    if not names:
        return float("nan")
    predictions = [np.asarray(load_model(models[n])[0].predict_torque(test), np.float64) for n in names]
    with scoring():  # the test split's torques are read here, once, to score
        return mse(combine(predictions, np.array([weights[n] for n in names])), test.target("indirect"))
