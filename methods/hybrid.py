"""Hybrid learners: an identified rigid body (the prior) plus a learned residual
of the torque, named ``PRIOR+RESIDUAL`` wherever a method name goes
(``standard+gp``, ``feasible+delan``).

How the field learns a real arm (Nguyen-Tuong & Peters, ICRA 2010; Reuss et al.
2022): the rigid body the data identify, and a learner for what it lacks.

* **The prior** is SysId identified on the training data in one of its
  configurations (:data:`PRIORS`): ``standard`` (rigid-body base parameters
  plus Coulomb and viscous friction, rotor inertia and a torque offset per
  joint, by least squares) or ``feasible`` (SysId's ``feasible``
  configuration: the physically feasible rigid body with nonnegative
  friction and rotor inertia and a free offset per joint). It
  needs an arm's linear form (a URDF).
* **The residual** is any registered method that fits torques (the indirect
  experiment), a user's plugin included, fitted to ``tau - tau_prior`` on the
  same training data within the hybrid's budget: one composition for every
  pair (:class:`Hybrid`, made for a name by :func:`compose`). The hybrid's
  hyperparameters are the residual's, and its steps are the residual's.
* **The prior's work does not depend on the budget.** Every prior is
  identified with fixed work (SysId's one solve; the residual loop's rounds,
  until one accepts nothing), the same on any machine, so it is the hybrid's
  one-time work on its samples (:meth:`Hybrid.prepare_samples`), done before
  the budget starts, and the budget is the residual's. A tuned hybrid's
  priors, one per fold and one for all the training data, are identified
  before its search starts (:mod:`bench.evaluation.tuning`).
* **Never worse than its prior where the data end.** A residual learner
  that falls back to zero far from its training states by itself (a Gaussian
  process with a zero mean, :attr:`~methods.base.Method.falls_back_to_zero`)
  is added as it is. Any other is multiplied by a gate,
  ``exp(-d^2 / (2 gate_length^2))``, with ``d`` the state's distance to the
  nearest training state (:class:`bench.core.distance.TrainingStates`: ``(q, qd)``
  in training standard deviations): 1 on the training states, towards 0 away
  from them, so that there the hybrid predicts its prior. The gate depends on
  the state only, so the torque stays affine in ``qdd``: the hybrid's mass
  matrix is the prior's plus the gated residual's (DeLaN's is positive
  definite by construction, the feasible prior's too), and its forward
  dynamics exist for driven rollouts.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Callable, ClassVar

import numpy as np

from bench.core.experiment import INDIRECT
from bench.core.budget import Budget
from bench.core.data import Dataset
from bench.core.distance import TrainingStates
from bench.core.kept import Kept, digest, read_only
from bench.core.modelfile import Unpacker, build, loader
from bench.physics.models import FittedModel
from bench.core.names import MethodName, MethodNameError
from bench.core.registry import RegistryError, UnknownName
from bench.physics.system import System
from methods.base import METHODS, Method, restored, saved_hyperparameters
from methods.config import POSITIVE
from methods.progress import Progress
from methods.saving import load_model, save_model
from methods.sysid import SysId

#: the method that identifies the prior
PRIOR_METHOD = "sysid"


@dataclass(frozen=True)
class Prior:
    """A prior a hybrid may name: how it is identified on the training data
    (``identify(train, system, seed)``, a fitted model, with work that does
    not depend on the hybrid's budget: the same for the same samples and
    seed on any machine) and what it is, in words. A prior registered outside
    this package is registered by a module the method registry imports
    (:mod:`bench.core.registry`: an entry point, or a ``--plugin`` file)."""

    name: str
    words: str
    identify: Callable[[Dataset, "System | None", int], FittedModel]
    #: its name on the pages, before its residual's (``standard model + GP``)
    title: str = ""
    #: what else is the code of its identification, where ``identify`` looks it up by name as it runs (a
    #: registered method's class): part of a hybrid's code (:meth:`Hybrid.code_objects`)
    extra_code: tuple = ()

    @property
    def code(self) -> tuple:
        """``identify`` and :attr:`extra_code`."""
        return (self.identify, *self.extra_code)


#: the priors a hybrid may name, by name (:func:`register_prior`)
PRIORS: dict[str, Prior] = {}


def register_prior(prior: Prior) -> Prior:
    """Let hybrids name ``prior`` (``NAME+RESIDUAL``); a name taken already is refused."""
    if prior.name in PRIORS and PRIORS[prior.name] != prior:
        raise RegistryError(f"a prior named {prior.name!r} is registered already")
    PRIORS[prior.name] = prior
    return prior


def sysid_prior(configuration: str):
    """The identification of SysId's configuration ``configuration``: one solve."""
    def identify(train: Dataset, system, seed: int) -> FittedModel:
        method = METHODS[PRIOR_METHOD](**METHODS[PRIOR_METHOD].configuration(configuration))
        return method.fit(train, INDIRECT, seed, Budget(steps=1), system=system)
    return identify


register_prior(Prior("standard", "SysId's standard configuration", sysid_prior("standard"), "standard model",
                     extra_code=(SysId,)))
register_prior(Prior("feasible", "SysId's feasible configuration (the feasible rigid bodies, nonnegative joint "
                                 "friction and rotor inertia, and joint offsets)", sysid_prior("feasible"),
                     "feasible rigid body",
                     extra_code=(SysId,)))

#: the gate lengths a tuned hybrid tries, where its residual is gated (:mod:`bench.evaluation.tuning`)
GATE_LENGTHS = (1.0, 3.0)
#: priors kept for reuse: a tuned hybrid fits the same prior on each fold for every combination
PRIOR_CACHE = 8
#: prior torques kept for reuse: a tuned hybrid's fits of one combination go through every fold (at most four,
#: :data:`bench.evaluation.tuning.MAX_FOLDS`) before the next combination's, and each asks for the prior's torque on
#: three data sets of its fold (the fitted samples, the subset its training MSE is evaluated on, the scored samples),
#: so that fewer kept than the folds' sets are made again for every combination; the whole training set's two and
#: the test set's are kept beside them
TORQUES_KEPT = 16


def naming() -> str:
    """How a hybrid is named, for ``bench list`` and errors."""
    METHODS.load_declared()  # the priors that modules declared to the registry register
    priors = "; ".join(f"{name}: {prior.words}" for name, prior in PRIORS.items())
    return (f"a hybrid is named PRIOR+RESIDUAL: PRIOR one of {', '.join(PRIORS)} ({priors}), RESIDUAL any method that "
            f"fits torques, e.g. standard+gp, feasible+delan")


class Hybrid(Method):
    """A prior plus a residual learner (see the module docstring); one class is
    made per name by :func:`compose`, which sets :attr:`prior_name` and
    :attr:`residual_name` and the hyperparameters (the residual's, and
    ``gate_length``)."""

    prior_name: ClassVar[str] = ""
    residual_name: ClassVar[str] = ""
    experiments: ClassVar[tuple[str, ...]] = (INDIRECT,)

    def __init__(self, **hyperparameters):
        super().__init__(**hyperparameters)
        own = {k: v for k, v in hyperparameters.items() if k != "gate_length"}
        self.residual: Method = METHODS[self.residual_name](**own)
        self.prior: Method | None = None
        self.gate: TrainingStates | None = None

    # -- class-level facts ---------------------------------------------------
    @classmethod
    def unavailable_reason(cls) -> str | None:
        return METHODS.entry(PRIOR_METHOD).unavailable_reason() or METHODS.entry(cls.residual_name).unavailable_reason()

    @classmethod
    def display_name(cls) -> str:
        """``PRIOR + RESIDUAL`` in the pages' words: ``standard model + GP``."""
        prior = PRIORS[cls.prior_name]
        return f"{prior.title or prior.name} + {METHODS[cls.residual_name].display_name()}"

    @classmethod
    def not_applicable_reason(cls, experiment: str, system: System | None = None) -> str | None:
        if experiment not in cls.experiments:
            return f"{cls.name} learns the residual of the torque of its prior: the {experiment} experiment has no torques"
        if system is not None and system.linear_form() is None:
            return prior_unavailable(cls.prior_name, system)
        return METHODS[cls.residual_name].not_applicable_reason(INDIRECT, system)

    @classmethod
    def code_objects(cls) -> tuple:
        """The hybrid's class, its residual's and what identifies its prior (looked up by name as it runs)."""
        prior = PRIORS.get(cls.prior_name)
        return (cls, METHODS[cls.residual_name], *(() if prior is None else prior.code))

    @classmethod
    def refused_on(cls, system: System) -> str | None:
        return None if system.linear_form() is not None else f"{cls.name}: {prior_unavailable(cls.prior_name, system)}"

    def use_device(self, device: str) -> "Method":
        self.residual.use_device(device)
        self.train_device = self.residual.train_device
        return self

    def trained_on(self) -> str:
        return self.residual.trained_on()

    def stacking_unavailable_reason(self) -> str | None:
        return f"{self.name} fits its prior, then its residual, one seed at a time"

    # -- the fit ---------------------------------------------------------------
    def _prepare_samples(self, train: Dataset, experiment: str, seed: int, system: System | None) -> None:
        """The prior on ``train``: fixed work, identified before the budget starts (and kept for the fit)."""
        identified_prior(self.prior_name, train, system, seed)

    def _fit(self, train: Dataset, experiment: str, progress: Progress) -> None:
        self.prior = identified_prior(self.prior_name, train, self.system, self.seed)
        self._residual_data = train.replace(tau=train.tau - prior_torque(self.prior, train))
        self.gate = None if self.residual.falls_back_to_zero else TrainingStates(train)
        # the residual starts as a fit of its own would (its seed, its one-time work), on the hybrid's clock
        self.residual.begin_fit(self._residual_data, INDIRECT, self.seed, self.budget, system=self.system)
        self.residual._fit(self._residual_data, INDIRECT, progress)

    def _prepare(self, train: Dataset, experiment: str) -> None:
        """The residual's one-time work (compiling its step) for data of ``train``'s shape, before the budget starts."""
        self.residual.prepare(train, INDIRECT)

    def _post_fit(self, train: Dataset, experiment: str, seconds_left: float) -> None:
        self.residual._post_fit(self._residual_data, INDIRECT, seconds_left)

    def _get_state(self):
        return self.residual._get_state()

    def _set_state(self, state) -> None:
        self.residual._set_state(state)

    # -- predictions -------------------------------------------------------------
    def weight(self, data: Dataset) -> np.ndarray:
        """The residual's weight at each state of ``data``: the gate, or 1 where the residual needs none."""
        if self.gate is None:
            return np.ones(len(data))
        d = self.gate.distance(data)
        return np.exp(-0.5 * (d / self.config.gate_length) ** 2)

    def residual_torque(self, data: Dataset) -> np.ndarray:
        """What the hybrid adds to its prior's torque, weighted."""
        return self.weight(data)[:, None] * self.residual.predict_torque(data)

    def predict_torque(self, data: Dataset) -> np.ndarray:
        return prior_torque(self.prior, data) + self.residual_torque(data)

    def mass_and_bias(self, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The prior's ``M`` and ``c`` plus the residual's, weighted: the gate's
        weight depends on the state alone, so each of the two is asked once a
        state for its own (a residual of the state alone gives its torque at
        each state once, and the gate is looked up once a state)."""
        M, c = self.prior.mass_and_bias(q, qd)
        M_r, c_r = self.residual.mass_and_bias(q, qd)
        zeros = np.zeros_like(q)
        w = self.weight(Dataset(q, qd, zeros, zeros))
        return M + w[:, None, None] * M_r, c + w[:, None] * c_r

    def predict_lagrangian(self, data: Dataset) -> np.ndarray:
        """The prior's L plus the weighted residual's (for a residual that has one)."""
        return self.prior.predict_lagrangian(data) + self.weight(data) * self.residual.predict_lagrangian(data)

    def not_a_lagrangian(self) -> str | None:
        return self.residual.not_a_lagrangian()

    def references(self) -> dict:
        return {"prior": self.prior}

    def saved(self, packer) -> dict:
        """Its prior, its residual and its gate (the training states, scaled), each as saved."""
        gate = None if self.gate is None else {"states": packer.array(self.gate.states),
                                               "scale": packer.array(self.gate.scale)}
        return {"kind": "hybrid", "method": self.name, "hyperparameters": saved_hyperparameters(self),
                "prior": self.prior.saved(packer), "residual": self.residual.saved(packer), "gate": gate}

    def record_details(self) -> dict:
        return {"prior": PRIORS[self.prior_name].words,
                "gated": self.gate is not None, "residual": self.residual.record_details(), "size": self.residual.size()}

    def size(self) -> dict:
        return self.residual.size()


@loader("hybrid")
def _load(tree: dict, unpacker: Unpacker, context: dict) -> Hybrid:
    method = restored(tree, context)
    method.prior = build(tree["prior"], unpacker, context)
    method.residual = build(tree["residual"], unpacker, context)
    gate = tree.get("gate")
    method.gate = None if gate is None else TrainingStates.scaled(unpacker.array(gate["states"]),
                                                                  unpacker.array(gate["scale"]))
    return method


_priors = Kept(PRIOR_CACHE)


def identified_prior(prior: str, train: Dataset, system: System | None, seed: int) -> FittedModel:
    """The prior ``prior`` identified on ``train`` with ``seed`` (:class:`Prior`):
    the same fit for the same samples and seed, so the last :data:`PRIOR_CACHE`
    are kept and reused (a tuned hybrid fits every combination on the same
    folds, each fold's prior identified before the search), and where this
    process shares priors (:func:`share_priors`), one identified by another
    process is read instead of identified again."""
    key = _prior_key(prior, train, system, seed)
    return _priors.get(key, lambda: _shared_or_identified(prior, key, train, system, seed))


def _prior_key(prior: str, train: Dataset, system: System | None, seed: int) -> tuple:
    return prior, None if system is None else system.name, seed, fingerprint(train, STATES + ("tau",))


#: where this process shares the priors it identifies (:func:`share_priors`): a folder, and what names the code
_SHARED: dict = {"folder": None, "code": None}


def share_priors(folder: str | os.PathLike | None, code: Callable[[], str | None] | None = None) -> None:
    """Share the priors this process identifies through ``folder``, as model files
    (:mod:`methods.saving`): a prior that another process identified there, on the
    same samples with the same seed and by the same code (``code()``, a digest of
    the code now; where it gives ``None``, nothing is shared), is read back instead
    of identified again, and one identified here is written there. A run of a
    matrix shares through its output folder (:class:`bench.runner.run.RunJob`), so
    that ``bench select``'s ``loop+gp`` reads the loop's models that the ``loop``
    candidate's fits made (:func:`keep_shared`), instead of running the same rounds
    again. A prior is written only where it loads back with the same torques
    (:func:`~methods.saving.save_model`); ``None`` stops the sharing."""
    _SHARED.update(folder=None if folder is None else Path(folder), code=code)


def _shared_path(key: tuple) -> Path | None:
    folder, code = _SHARED["folder"], _SHARED["code"]
    digest_now = code() if folder is not None and code is not None else None
    if digest_now is None:
        return None
    name = hashlib.sha256(repr((key, digest_now)).encode()).hexdigest()[:32]
    return folder / f"{key[0]}-{name}.npz"


def _shared_or_identified(prior: str, key: tuple, train: Dataset, system: System | None, seed: int) -> FittedModel:
    path = _shared_path(key)
    if path is not None and path.is_file():
        try:
            return load_model(path, system)[0]
        except Exception:  # noqa: BLE001  (a file another process left unreadable: identified here, written anew)
            path.unlink(missing_ok=True)
    model = PRIORS[prior].identify(train, system, seed)
    _write_shared(path, prior, train, system, seed, model)
    return model


def keep_shared(prior: str, train: Dataset, system: System | None, seed: int, model: FittedModel) -> None:
    """Keep ``model`` as the prior ``prior`` identified on ``train`` with ``seed``, where this process shares
    priors (:func:`share_priors`): for a method whose own fit is that identification (the ``loop`` method at
    its full rounds)."""
    key = _prior_key(prior, train, system, seed)
    _priors.get(key, lambda: model)
    _write_shared(_shared_path(key), prior, train, system, seed, model)


def _write_shared(path: Path | None, prior: str, train: Dataset, system: System | None, seed: int,
                  model: FittedModel) -> None:
    if path is None or path.exists():
        return
    header = {"method": prior, "system": None if system is None else system.name, "seed": int(seed)}
    try:
        save_model(model, path, header, train, system)
    except Exception:  # noqa: BLE001  (cannot be saved, or not the same loaded back: not shared; the run goes on)
        pass


#: what a model's torque may read of a data set: every array but the torque itself
STATES = ("q", "qd", "qdd", "sign_qd", "recording", "trajectory", "time")


def fingerprint(data: Dataset, arrays: tuple[str, ...]) -> tuple:
    """What identifies ``data``'s ``arrays`` (:func:`~bench.core.kept.digest`; an array it lacks counts as such)."""
    return digest(*(getattr(data, name) for name in arrays))


#: a prior's torques, each beside the prior, so that the prior's id in the key stays its own while kept
_torques = Kept(TORQUES_KEPT)


def prior_torque(prior: FittedModel, data: Dataset) -> np.ndarray:
    """``prior``'s torque at ``data``'s states, the last :data:`TORQUES_KEPT` kept and given again: a tuned
    hybrid's fold fits share their fold's prior (:func:`identified_prior`) and subtract it from the same
    training samples and add it on the same held-out samples, once for each combination and rung."""
    return _torques.get((id(prior), fingerprint(data, STATES)),
                        lambda: (prior, read_only(np.array(prior.predict_torque(data)))))[1]


def prior_unavailable(prior: str, system: System) -> str:
    """Why the prior ``prior`` cannot be identified on ``system``."""
    return (f"the prior {prior} is SysId identified on an arm's linear form (from its URDF), and {system.name} has "
            f"none")


def compose(name: str) -> type | None:
    """The hybrid named ``name`` (``PRIOR+RESIDUAL``), or ``None`` for a name that
    is no hybrid; a hybrid name that is wrong raises :class:`RegistryError` in one
    line: an unknown prior, an unknown residual, or one that fits no torques."""
    try:
        parsed = MethodName.parse(name)
    except MethodNameError as exc:  # a wrong hybrid's name is refused here; any other is the registry's unknown name
        if exc.hybrid:
            raise RegistryError(str(exc)) from None
        return None
    if not parsed.hybrid or parsed.variant or parsed.tuned:
        return None
    prior, residual = parsed.prior, parsed.method
    if prior not in PRIORS:
        raise RegistryError(f"unknown prior {prior!r} in {name!r}: {naming()}")
    try:
        entry = METHODS.entry(residual)
    except UnknownName as exc:
        raise UnknownName(f"{name}: unknown residual learner: {exc}", exc.name) from None
    reason = entry.obj.not_applicable_reason(INDIRECT)
    if reason:
        raise RegistryError(f"{name}: {residual} cannot learn a residual torque: {reason}")
    base = entry.obj
    config = dataclasses.make_dataclass(
        f"{base.Config.__name__}Hybrid", [("gate_length", Annotated[float, POSITIVE], 1.0)], bases=(base.Config,),
        frozen=True)
    config.__doc__ = (f"{base.name}'s hyperparameters, and ``gate_length``: the scale of the gate that takes a residual "
                      "that does not fall back to zero by itself to zero away from the training states, in training "
                      "standard deviations")
    return type(f"Hybrid_{prior}_{residual}", (Hybrid,), {
        "prior_name": prior, "residual_name": residual, "made_of": parsed.parts, "Config": config, "smoke": dict(base.smoke),
        "uses_device": base.uses_device, "has_lagrangian": base.has_lagrangian, "work": base.work,
        "configurations": dict(base.configurations), "tags": frozenset({"hybrid"}),
        "search_space": {**base.search_space, **({} if base.falls_back_to_zero else {"gate_length": GATE_LENGTHS})},
        "__doc__": f"{prior} prior plus a {residual} residual (see methods.hybrid)",
    })


METHODS.composer = compose
