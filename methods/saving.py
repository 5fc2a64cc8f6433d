"""Saving a fitted model to a model file (:mod:`bench.core.modelfile`) and loading it back.

:func:`save_model` writes what a model's :meth:`~bench.physics.models.FittedModel.saved`
gives, then loads the file it wrote and checks that it predicts the fitted
model's torques on the samples it is given (at most :data:`CHECK_SAMPLES`) to
:data:`TOLERANCE`; only then is the file put in place, so that no file is
kept that would not give the fitted model back.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from bench.core import modelfile
from bench.core.data import Dataset
from bench.core.modelfile import ModelFileError, Packer
from bench.physics.system import SYSTEMS, System

#: samples a saved model is checked on
CHECK_SAMPLES = 256
#: the largest difference of a loaded model's torques from the fitted one's, relative to their scale
TOLERANCE = 1e-10


def save_model(model, path: str | Path, header: dict, check: Dataset, system: System | None,
               held_out: dict | None = None) -> dict:
    """Write ``model`` (fitted on data of ``check``'s joints) to ``path`` with
    ``header`` (what it was fitted with) and, where it was tuned, the held-out
    predictions its validation made (:attr:`bench.evaluation.tuning.Tuned.held_out`);
    returns the check's figures. A ``ValueError`` where the model cannot be saved
    or does not load back the same."""
    packer = Packer()
    tree = model.saved(packer)
    path = Path(path)
    header = {**header, "dof": int(check.dof), "kind": tree["kind"], **torque_bound(check)}
    if held_out:
        header["held_out"] = {name: packer.array(value) for name, value in held_out.items()}
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".check")
    os.close(fd)
    try:
        modelfile.save(tmp, header, tree, packer)
        loaded, _ = load_model(tmp, system)
        part = check.subset(slice(0, CHECK_SAMPLES))
        before = np.asarray(model.predict_torque(part), dtype=np.float64)
        after = np.asarray(loaded.predict_torque(part), dtype=np.float64)
        scale = max(float(np.max(np.abs(before), initial=0.0)), 1e-300)
        difference = float(np.max(np.abs(after - before), initial=0.0)) / scale
        if not difference <= TOLERANCE:
            raise ValueError(f"the {tree['kind']} model loaded back predicts torques {difference:.2g} apart "
                             f"(relative to their largest) from the fitted one's; not saved")
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return {"checked_samples": len(part), "largest_relative_difference": difference}


def torque_bound(data: Dataset) -> dict:
    """The header's ``torque_bound`` for a model fitted on ``data``: :data:`~bench.core.modelfile.TORQUE_BOUND_FACTOR`
    times each joint's largest torque there (none where a joint's torques are all zero)."""
    largest = np.max(np.abs(data.tau), axis=0) if len(data) else np.zeros(0)
    if not len(largest) or not (np.isfinite(largest).all() and (largest > 0).all()):
        return {}
    return {"torque_bound": [min(float(v), modelfile.MAX_COEFFICIENT) for v in modelfile.TORQUE_BOUND_FACTOR * largest]}


def check_torques(tau: np.ndarray, header: dict, model: str, log: str) -> None:
    """:class:`~bench.core.modelfile.ModelFileError` where ``tau``, a model's torques on ``log``, is not finite or
    leaves the bound its file states (``torque_bound``), naming the first such sample and joint."""
    if not np.isfinite(tau).all():
        raise ModelFileError(f"{model}: predicts non-finite torques on {log}")
    bound = header.get("torque_bound")
    if bound is None:
        return
    if len(bound) != tau.shape[1]:
        raise ModelFileError(f"{model}: its torque_bound names {len(bound)} joint(s), its model {tau.shape[1]}")
    over = np.argwhere(np.abs(tau) > np.asarray(bound, dtype=np.float64))
    if len(over):
        row, joint = (int(v) for v in over[0])
        raise ModelFileError(f"{model}: predicts {tau[row, joint]:.4g} on joint {joint + 1} at row {row + 1} of {log}, "
                             f"past the bound of {bound[joint]:.4g} its file states ({modelfile.TORQUE_BOUND_FACTOR:g} "
                             f"times the largest torque of the data it was fitted on)")


def held_out(path: str | Path) -> dict[str, np.ndarray] | None:
    """The held-out predictions a tuned model's file keeps (:func:`save_model`): ``index``, ``fold`` and
    ``prediction``; ``None`` where it keeps none."""
    header, unpacker = modelfile.read(path)
    refs = header.get("held_out")
    if not isinstance(refs, dict):
        return None
    out = {name: unpacker.array(refs.get(name)) for name in ("index", "fold", "prediction")}
    for name in ("index", "fold"):
        value = out[name]
        if value.ndim != 1 or value.dtype.kind not in "iu" or (value.size and value.min() < 0):
            raise ModelFileError(f"{path}: its held-out {name} is not a list of sample numbers (0 or more)")
    prediction = out["prediction"]
    if prediction.ndim not in (1, 2) or prediction.dtype.kind != "f" or not np.isfinite(prediction).all():
        raise ModelFileError(f"{path}: its held-out predictions are not finite numbers a sample")
    if not (len(out["index"]) == len(out["fold"]) == len(prediction)):
        raise ModelFileError(f"{path}: its held-out predictions' arrays differ in length")
    return out


def load_model(path: str | Path, system: System | None = None):
    """The fitted model in the file ``path`` and the file's header; ``system``
    is the model's system (by default the one the file names, from the
    registry). :class:`~bench.core.modelfile.ModelFileError` in one line for
    a file that is not such a model."""
    header, unpacker = modelfile.read(path)
    if system is None:
        name = header.get("system")
        if name is not None and name not in SYSTEMS:
            raise ModelFileError(f"{path}: its system {name!r} is not registered here (a measured arm's or a URDF's "
                                 f"file is given to the command that reads the model)")
        system = None if name is None else SYSTEMS[name]()
    dof = int(header["dof"])  # an integer from 1 up: the header is checked (bench.core.modelfile.HEADER_SCHEMA)
    if system is not None and system.dof != dof:
        raise ModelFileError(f"{path}: a model of {dof} joint(s), but its system {system.name} has {system.dof}")
    model = modelfile.build(header["model"], unpacker, {"system": system, "dof": dof})
    return model, header
