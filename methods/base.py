"""The method contract, owned by the base class.

A method learns a Lagrangian from a :class:`~bench.core.data.Dataset`, directly
(from samples of ``L``) or indirectly (from torques only, through the suite's
Euler–Lagrange transform). The base class owns the protocol:

* hyperparameters are typed keywords, validated at construction against the
  method's ``Config`` dataclass (:mod:`methods.config`; "did you mean" for
  unknown names); what the user passed is never mutated;
* :meth:`Method.fit` checks the data, seeds ``random``, numpy and torch,
  starts the wall-clock deadline, evaluates the training MSE on a schedule,
  keeps the best state seen, and restores it at the end;
* a method writes only its learning loop, :meth:`Method._fit`, calling
  ``progress.step()`` once per optimisation step or generation::

      def _fit(self, train, experiment, progress):
          while progress.step():
              ...one step...

Each method declares a tiny ``smoke`` configuration next to its real one.
A fitted method is a :class:`~bench.physics.models.FittedModel`: it predicts
``L`` and ``tau`` and, where it has one, gives its expression. Every hook a
method writes or may write, and what uses it, is listed in docs/extending.md.
:mod:`methods.torch_method` is the base of methods whose model is a torch
module; :class:`ExpressionMethod` (here) of those whose model is one expression.
"""

from __future__ import annotations

import abc
import contextlib
import dataclasses
import gc
import json
import random
import time
from typing import Any, ClassVar

import numpy as np
import torch

import methods
from bench.core.budget import Budget
from bench.core.data import Dataset, mse
from bench.core.experiment import EXPERIMENTS, INDIRECT, Experiment
from bench.core.errors import ConfigError, DataError
from bench.physics.models import ExpressionModel, FittedModel, NoVariant
from bench.core.registry import Registry
from bench.physics.system import SYSTEMS, System
from methods.config import MethodConfig, Named, build_config
from methods.progress import Progress


# -- the method base class ------------------------------------------------------------

@contextlib.contextmanager
def gc_frozen():
    """Python's cyclic garbage collector leaves alone the objects that exist
    on entry (imported modules, data, the model) while the block runs.

    A training step creates hundreds of short-lived Python objects (tensor
    wrappers, autograd bookkeeping), which trigger collections; a full
    collection then walks every object of the process, about 216,000 once
    the suite and sympy are imported. Objects made inside the block are
    collected as usual, the older ones again after it. Left alone when
    something else froze objects already.
    """
    if gc.get_freeze_count():
        yield
        return
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)


def as_budget(budget: Budget) -> Budget:
    """:meth:`Method.fit`'s budget, checked: a :class:`~bench.core.budget.Budget` and nothing else."""
    if not isinstance(budget, Budget):
        raise ConfigError(f"a fit's budget is a Budget (Budget(seconds=S) or Budget(steps=N)), got {budget!r}")
    return budget


class Method(FittedModel):
    """Base class of every learning method. See the module docstring.

    A method writes :meth:`_fit`, :meth:`_get_state`, :meth:`_set_state` and
    the predictions of :class:`~bench.physics.models.FittedModel`.
    """

    name: ClassVar[str] = "unnamed"
    #: the method's name on the pages and in tables' prose (:meth:`display_name`); ``""``: its registered name
    title: ClassVar[str] = ""
    #: what the method is, in a sentence or a few: its row of docs/methods_and_systems.md, which ``python -m
    #: bench index`` writes from the registry
    summary: ClassVar[str] = ""
    tags: ClassVar[frozenset[str]] = frozenset()
    Config: ClassVar[type] = MethodConfig
    #: overrides of ``Config`` for a tiny CI run; each method declares its own
    smoke: ClassVar[dict] = {"max_steps": 5}
    #: named configurations beside the defaults (:class:`~methods.config.Named`), chosen by ``--config NAME``
    configurations: ClassVar[dict[str, Named]] = {}
    #: the values a tuned run tries per hyperparameter (``--tune``, :mod:`bench.evaluation.tuning`): at most
    #: 10 combinations in all; none by default
    search_space: ClassVar[dict[str, tuple]] = {}
    #: the steps of its fit where a command bounds a run by work and is given none (``bench residual``'s
    #: default, ``bench select``'s candidates): ``1`` for a fit that is one solve; ``None`` where the method has no
    #: such count, and such a command bounds it by seconds
    work: ClassVar[int | None] = None
    #: the experiments the method applies to
    experiments: ClassVar[tuple[str, ...]] = EXPERIMENTS
    #: why it does not apply to the others, for the tables' notes (``""``: that it does not)
    not_applicable: ClassVar[str] = ""
    #: whether ``fit(..., warm_start=True)`` can continue from the current state
    supports_warm_start: ClassVar[bool] = False
    #: whether the method trains on the device a run names (``--device``, :mod:`bench.core.devices`):
    #: the torch methods; the others always run on the CPU
    uses_device: ClassVar[bool] = False
    #: whether several seeds' fits can train as one stacked model (:mod:`methods.stacking`)
    stackable: ClassVar[bool] = False
    #: whether the fitted model's torque falls back to zero far from the training states by itself
    #: (a Gaussian process with a zero mean); a hybrid gates a residual that does not (:mod:`methods.hybrid`)
    falls_back_to_zero: ClassVar[bool] = False
    #: whether the fitted model has a Lagrangian (a model of the torque alone, a GP, has none: its
    #: :meth:`predict_lagrangian` is ``nan``)
    has_lagrangian: ClassVar[bool] = True

    def __init__(self, **hyperparameters):
        self.config = build_config(self.Config, dict(hyperparameters), self.name)
        self.experiment = None
        self.warm_start = False
        self.seed: int | None = None
        self.dof: int | None = None
        self.system = None
        self.fit_info: dict = {}
        self.train_device = "cpu"

    @property
    def experiment(self) -> Experiment | None:
        """The experiment of the last fit (an :class:`~bench.core.experiment.Experiment`,
        whatever its name was given as), ``None`` before one."""
        return self._experiment

    @experiment.setter
    def experiment(self, value: "str | Experiment | None") -> None:
        self._experiment = None if value is None else Experiment.of(value)

    def use_device(self, device: str) -> "Method":
        """Train on ``device`` (``cpu`` or ``cuda``, :func:`bench.core.devices.resolve`)
        from the next fit on, where the method :attr:`uses_device`; else stay on the CPU."""
        self.train_device = device if self.uses_device else "cpu"
        return self

    def stacking_unavailable_reason(self) -> str | None:
        """``None`` where several seeds' fits of this configuration can train as
        one stacked model (:mod:`methods.stacking`); otherwise why not."""
        return None if self.stackable else f"{self.name} is not a stackable method"

    @classmethod
    def prepare_stacked(cls, methods: list, datasets: list, experiment: str) -> None:
        """One-time work of a stacked fit of ``methods`` on ``datasets``, before
        their budgets start (compiling its step); none by default."""

    @classmethod
    def train_stacked(cls, methods: list, starts: list, datasets: list, experiment: str, slots: list) -> None:
        """The loop of a stacked fit (:func:`methods.stacking.fit_stacked`): ``methods``
        after their :meth:`begin_fit` (``starts``), each seed's own random draws
        inside its :class:`~methods.stacking.RngSlot`; a stackable method writes it."""
        raise NotImplementedError(f"{cls.name} has no stacked loop")

    def trained_on(self) -> str:
        """The device the last fit trained on, as its record names it: :attr:`train_device`,
        unless the fit had nothing to train there (a method overrides this)."""
        return self.train_device

    # -- class-level facts ---------------------------------------------------
    @classmethod
    def display_name(cls) -> str:
        """The method's name on the pages: its :attr:`title`, else its registered name."""
        return cls.title or cls.name

    @classmethod
    def unavailable_reason(cls) -> str | None:
        """``None`` when the method can run here; otherwise why it cannot."""
        return None

    @classmethod
    def not_applicable_reason(cls, experiment: str, system: System | None = None) -> str | None:
        """Why the method cannot run ``experiment`` (on ``system``, where one is
        given); ``None`` when it can."""
        if experiment not in cls.experiments:
            return cls.not_applicable or f"{cls.name} does not apply to the {experiment} experiment"
        return None

    @classmethod
    def code_objects(cls) -> tuple:
        """The classes and functions whose source files, with the suite's modules they import, are the code of
        the method's runs (:func:`bench.runner.sources.code_files`): the class itself by default. A method that
        looks other code up by name at run time names it here (a hybrid names its residual and its prior)."""
        return (cls,)

    @classmethod
    def refused_on(cls, system: System) -> str | None:
        """Why a command line refuses the method on ``system`` outright (exit 2,
        nothing run) rather than recording a run that does not apply; ``None``
        by default. A hybrid whose prior the system cannot give is refused."""
        return None

    @classmethod
    def smoke_config(cls) -> dict:
        return dict(cls.smoke)

    @classmethod
    def configuration_names(cls) -> list[str]:
        """``default``, ``smoke`` and the method's own named configurations."""
        return ["default", "smoke", *cls.configurations]

    @classmethod
    def configuration(cls, name: str) -> dict:
        """The hyperparameters of the configuration ``name`` (``{}`` for the defaults);
        a :class:`ConfigError` naming the ones there are otherwise."""
        if name == "default":
            return {}
        if name == "smoke":
            return cls.smoke_config()
        if name not in cls.configurations:
            raise ConfigError(f"{cls.name} has no configuration {name!r}; it offers {', '.join(cls.configuration_names())}")
        return dict(cls.configurations[name].values)

    def hyperparameters(self) -> dict:
        return dataclasses.asdict(self.config)

    # -- the protocol ----------------------------------------------------------
    def fit(self, train: Dataset, experiment: str, seed: int, budget: Budget, *, warm_start: bool = False,
            system: System | None = None) -> "Method":
        """Learn from ``train`` within ``budget`` (:mod:`bench.core.budget`):
        ``Budget(seconds=S)`` of wall-clock time, ``Budget(steps=N)`` steps of
        the method's work (gradient steps, generations), or a time-budgeted
        fit's schedule to replay. Under a work budget the fit has no
        wall-clock deadline.

        Keeps and restores the state with the lowest training MSE seen.
        Fills :attr:`fit_info` with the steps done, the best-so-far curve of
        training MSE over wall-clock time, why the loop stopped, and the
        :class:`~bench.core.budget.Schedule` that replays it.

        One-time work that does not depend on the budget (compiling for the
        data's shapes, :meth:`prepare`) is done first and not counted in it.

        ``warm_start=True`` continues from the state of the previous fit (its
        parameters and optimiser state), for methods with
        :attr:`supports_warm_start`, on new data of the same shape: what a
        learner does when its training stream changes.

        ``system`` is the system the data belong to, for methods that read its
        declared form; by default the registered system named by ``train.system``.
        """
        started = self.begin_fit(train, experiment, seed, budget, warm_start=warm_start, system=system)
        with gc_frozen():
            self._fit(train, self.experiment, started.progress)
        return self.end_fit(started, train)

    def begin_fit(self, train: Dataset, experiment: str, seed: int, budget: Budget, *, warm_start: bool = False,
                  system: System | None = None, prepare: bool = True) -> "FitStart":
        """What :meth:`fit` does before the method's loop: check the data, do
        the one-time work (:meth:`prepare`; ``prepare=False`` where the loop that
        runs elsewhere does not use it), seed the generators, draw the evaluation
        subset and start the budget's :class:`Progress`. With :meth:`end_fit`
        after the loop, a fit whose loop runs elsewhere (several seeds' networks
        trained as one, :mod:`methods.stacking`) is the same as :meth:`fit`."""
        budget = as_budget(budget)
        experiment = Experiment.of(experiment)
        if warm_start and not self.supports_warm_start:
            raise ConfigError(f"{self.name} cannot continue a fit (warm_start)")
        if warm_start and self.experiment is None:
            raise ConfigError(f"{self.name}: warm_start needs an earlier fit to continue")
        if warm_start and (experiment != self.experiment or train.dof != self.dof):
            raise ConfigError(f"{self.name}: warm_start continues a {self.experiment} fit of {self.dof} DoF; "
                              f"got {experiment} data of {train.dof} DoF")
        self.warm_start = warm_start
        system = system if system is not None else self._resolve_system(train)
        reason = self.not_applicable_reason(experiment, system)
        if reason:
            raise ConfigError(reason)
        if len(train) == 0:
            raise DataError(f"{train.source}: no samples to fit")
        train.target(experiment)  # raises a DataError naming what is missing
        prepare_seconds = self.prepare(train, experiment) if prepare else 0.0
        prepare_seconds += self.prepare_samples(train, experiment, seed, system)
        t0 = time.perf_counter()
        self.experiment, self.seed, self.dof = experiment, int(seed), train.dof
        self.system = system
        self.budget = budget
        seed_everything(self.seed)

        rng = np.random.default_rng(self.seed)
        n_eval = min(len(train), self.config.eval_samples)
        eval_set = train.subset(np.sort(rng.choice(len(train), n_eval, replace=False)))
        eval_target = eval_set.target(experiment)
        limits = [n for n in (self.config.max_steps, budget.steps if budget.schedule is None else None) if n is not None]
        progress = Progress(
            budget.fit_seconds - (time.perf_counter() - t0),
            evaluate=lambda: mse(self.predict(eval_set, experiment), eval_target),
            snapshot=self._get_state,
            max_steps=min(limits, default=None),
            schedule=budget.schedule,
        )
        return FitStart(progress, budget, t0, prepare_seconds, n_eval)

    def end_fit(self, started: "FitStart", train: Dataset) -> "Method":
        """What :meth:`fit` does after the method's loop: restore the best
        state, the work after it (:meth:`_post_fit`) and :attr:`fit_info`
        (``loop_seconds``: of ``fit_seconds``, those before the final evaluation
        and the work after the loop)."""
        progress, budget, t0 = started.progress, started.budget, started.t0
        loop_seconds = time.perf_counter() - t0
        progress.finish()
        if progress.best_state is not None:
            self._set_state(progress.best_state)
        self._post_fit(train, self.experiment, budget.fit_seconds - (time.perf_counter() - t0))
        self.fit_info = {
            "steps": self._work_done(progress),
            "best_step": progress.best_step,
            "stop_reason": progress.stop_reason or "loop ended",
            "fit_seconds": time.perf_counter() - t0,
            "loop_seconds": round(loop_seconds, 4),
            "prepare_seconds": started.prepare_seconds,
            "evaluations": progress.evaluations,
            "eval_seconds": progress.eval_seconds,
            "eval_samples": started.n_eval,
            "curve": progress.curve,
            "schedule": self._replay_schedule(progress),
        }
        return self

    def prepare(self, train: Dataset, experiment: str) -> float:
        """One-time work for data of ``train``'s shape that must not eat into
        a fit's budget (compiling the training step for its shapes); done
        once per process, also when called again; returns the seconds it
        took. :meth:`fit` calls it before its budget starts; the runner
        calls it first, in a phase of its own, so that the fit's time limit
        does not cover it."""
        key = (experiment, train.dof)
        if getattr(self, "_prepared", None) == key:
            return 0.0
        t0 = time.perf_counter()
        self._prepare(train, Experiment.of(experiment))
        self._prepared = key
        return round(time.perf_counter() - t0, 3)

    def prepare_samples(self, train: Dataset, experiment: str, seed: int, system: System | None = None) -> float:
        """Work on ``train``'s samples that does not depend on the budget (a
        hybrid's prior, identified with fixed work), done before the budget
        starts and kept for the fit; returns the seconds it took. :meth:`fit`
        calls it before its budget starts; the runner and a tuned search call
        it first, in the phase of the one-time work, so that the fit's time
        limit does not cover it."""
        t0 = time.perf_counter()
        self._prepare_samples(train, Experiment.of(experiment), int(seed),
                              system if system is not None else self._resolve_system(train))
        return round(time.perf_counter() - t0, 3)

    def _prepare_samples(self, train: Dataset, experiment: str, seed: int, system: System | None) -> None:
        """:meth:`prepare_samples`'s work; none by default."""

    def _replay_schedule(self, progress: Progress) -> dict:
        """The record's replay entry: the fit's :class:`Schedule`, or why it cannot be replayed."""
        reason = self.replay_unavailable_reason()
        if reason:
            return {"unavailable": reason}
        return progress.schedule().to_json() | {"steps": self._work_done(progress)}

    @staticmethod
    def _resolve_system(train: Dataset) -> System | None:
        if train.system is None or train.system not in SYSTEMS:
            return None
        return SYSTEMS[train.system]()

    # -- hooks a method writes ------------------------------------------------
    @abc.abstractmethod
    def _fit(self, train: Dataset, experiment: str, progress: Progress) -> None:
        """The learning loop: one ``progress.step()`` per step (see the module docstring)."""

    @abc.abstractmethod
    def _get_state(self) -> Any:
        """A copy of the current state, to be restored later."""

    @abc.abstractmethod
    def _set_state(self, state: Any) -> None:
        """Restore a state from :meth:`_get_state`."""

    def _post_fit(self, train: Dataset, experiment: str, seconds_left: float) -> None:
        """Work after the best state is restored, within what is left of the
        budget (``math.inf`` under a work budget)."""

    def _prepare(self, train: Dataset, experiment: str) -> None:
        """One-time work before the budget starts (see :meth:`prepare`)."""

    def _work_done(self, progress: Progress) -> int:
        """The work the fit did, in the units a work budget counts: the
        steps of its loop, unless the method counts its work itself (a
        library's generations run inside one step)."""
        return progress.steps

    @classmethod
    def replay_unavailable_reason(cls) -> str | None:
        """Why a time-budgeted fit of this method cannot be replayed from the
        work it did (``None``: it can, see :mod:`bench.core.budget`)."""
        return None

    def variants(self) -> dict[str, "FittedModel | NoVariant"]:
        """Further fitted models derived from this one (for example a refined
        equation), each reported by the harness as ``<method>@<variant>`` (:mod:`bench.core.names`).

        A variant that could not be made is a :class:`~bench.physics.models.NoVariant`
        saying why, with its outcome (out of budget, not applicable, failed);
        every seed stays counted.
        """
        return {}

    def size(self) -> dict:
        """How much the fitted model learned, in its own terms (parameters, terms,
        inducing points); empty by default."""
        return {}

    def references(self) -> dict[str, FittedModel]:
        """Fitted models the method is made of that a run scores beside it on the
        test data (a hybrid's prior); none by default."""
        return {}

    def record_details(self) -> dict:
        """Method-specific facts for the run's record (JSON-serialisable)."""
        return {}

    # -- derived -----------------------------------------------------------------
    def predict(self, data: Dataset, experiment: str | None = None) -> np.ndarray:
        """The prediction in the experiment's own target (L or tau), by default the fitted one's."""
        return super().predict(data, experiment or self.experiment)


@dataclasses.dataclass
class FitStart:
    """A fit begun by :meth:`Method.begin_fit`: its progress and budget, when
    its budget started, the seconds of one-time work before it and the size
    of its evaluation subset."""

    progress: Progress
    budget: Budget
    t0: float
    prepare_seconds: float
    n_eval: int


#: the methods, by name; methods registered outside this package are declared in the group's entry points
METHODS: Registry[type[Method]] = Registry("method", group="syrenets_bench.methods")
METHODS.built_in = methods.register_built_in


def saved_hyperparameters(method) -> dict:
    """A method's hyperparameters as JSON (tuples as lists)."""
    return json_safe(method.hyperparameters())


def json_safe(value):
    """``value`` as JSON holds it (tuples as lists)."""
    return json.loads(json.dumps(value))


def restored(tree: dict, context: dict):
    """The method a saved tree names, built with its hyperparameters, for ``context``'s system and joints."""
    hyperparameters = {k: tuple(v) if isinstance(v, list) else v for k, v in tree["hyperparameters"].items()}
    method = METHODS[tree["method"]](**hyperparameters)
    method.dof, method.system, method.experiment = int(context["dof"]), context.get("system"), INDIRECT
    method.seed = 0  # a network is built, then given its saved weights
    return method


class ExpressionMethod(Method):
    """A method whose fitted state is one :class:`ExpressionModel`.

    A subclass sets ``self.model`` in its loop; state, predictions and the
    expression follow from it.
    """

    model: ExpressionModel

    def _get_state(self):
        return self.model

    def _set_state(self, state):
        self.model = state

    def expression(self):
        return self.model.expr

    def saved(self, packer):
        """Its expression (:meth:`~bench.physics.models.ExpressionModel.saved`)."""
        return self.model.saved(packer)

    def predict_lagrangian(self, data):
        return self.model.predict_lagrangian(data)

    def predict_torque(self, data):
        return self.model.predict_torque(data)

