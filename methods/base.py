"""The method contract, owned by the base class.

A method learns a Lagrangian from a :class:`~bench.core.data.Dataset`, directly
(from samples of ``L``) or indirectly (from torques only, through the suite's
Euler–Lagrange transform). The base class owns the protocol:

* hyperparameters are typed keywords, validated at construction against the
  method's ``Config`` dataclass ("did you mean" for unknown names); what the
  user passed is never mutated;
* :meth:`Method.fit` checks the data, seeds ``random``, numpy and torch,
  starts the wall-clock deadline, evaluates the training MSE on a schedule,
  keeps the best state seen, and restores it at the end;
* a method writes only its learning loop, :meth:`Method._fit`, calling
  ``progress.step()`` once per optimisation step or generation::

      def _fit(self, train, experiment, progress):
          while progress.step():
              ...one step...

Each method declares a tiny ``smoke`` configuration next to its real one.
A fitted method is a :class:`~bench.core.models.FittedModel`: it predicts
``L`` and ``tau`` and, where it has one, gives its expression.
"""

from __future__ import annotations

import abc
import contextlib
import dataclasses
import difflib
import gc
import math
import random
import time
import types
import typing
from dataclasses import dataclass
from typing import Annotated, Any, ClassVar

import numpy as np
import torch

from bench.core.budget import Budget
from bench.core.data import EXPERIMENTS, Dataset, check_experiment, mse
from bench.core.dynamics import euler_lagrange
from bench.core.errors import ConfigError, DataError
from bench.core.models import ExpressionModel, FittedModel, LagrangianFunction
from bench.core.registry import Registry
from bench.core.system import SYSTEMS, System
from methods.progress import Progress


# -- hyperparameters --------------------------------------------------------------

@dataclass(frozen=True)
class Range:
    """The values a numeric hyperparameter may take, declared next to its type::

        batch_size: Annotated[int, Range(1)] = 32           # at least 1
        lr: Annotated[float, Range(0, low_open=True)] = 1e-3  # positive
        post_fraction: Annotated[float, Range(0, 1, high_open=True)] = 0.1

    For a tuple, every item must lie in the range.
    """

    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False

    def __contains__(self, value) -> bool:
        if self.low is not None and not (value > self.low if self.low_open else value >= self.low):
            return False
        return self.high is None or (value < self.high if self.high_open else value <= self.high)

    def __str__(self) -> str:
        if self.high is None:
            return f"{'greater than' if self.low_open else 'at least'} {self.low:g}"
        if self.low is None:
            return f"{'less than' if self.high_open else 'at most'} {self.high:g}"
        return f"in {'(' if self.low_open else '['}{self.low:g}, {self.high:g}{')' if self.high_open else ']'}"


#: a positive number
POSITIVE = Range(0, low_open=True)
#: a probability or a fraction
FRACTION = Range(0, 1)

_BOOLEANS = {"true": True, "yes": True, "1": True, "false": False, "no": False, "0": False}


@dataclass(frozen=True)
class MethodConfig:
    """Hyperparameters every method has.

    Attributes
    ----------
    max_steps
        Stop after this many optimisation steps (or generations), even with
        budget left. ``None``: only the budget stops the run. Smoke
        configurations set it, so that a run is deterministic for its seed.
    eval_samples
        Size of the fixed random subset of the training data on which the
        training MSE is measured during the fit, to pick the best state.
    """

    max_steps: Annotated[int, Range(1)] | None = None
    eval_samples: Annotated[int, Range(1)] = 2048


def _check_value(owner: str, name: str, value: Any, hint: Any) -> Any:
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin is Annotated:
        value = _check_value(owner, name, value, args[0])
        for bound in (a for a in args[1:] if isinstance(a, Range)):
            if any(v not in bound for v in (value if isinstance(value, tuple) else (value,))):
                raise ConfigError(f"{owner}: {name} must be {bound}{' (each item)' if isinstance(value, tuple) else ''}, got {value!r}")
        return value
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)]
        if len(inner) == 1:
            return _check_value(owner, name, value, inner[0])
        return value
    if origin is typing.Literal:
        if value not in args:
            raise ConfigError(f"{owner}: {name} must be one of {', '.join(map(repr, args))}, got {value!r}")
        return value
    if origin is tuple or hint is tuple:
        if not isinstance(value, (tuple, list)):
            raise ConfigError(f"{owner}: {name} must be a tuple, got {type(value).__name__}")
        if args and args[-1] is not Ellipsis and len(args) != len(value):
            raise ConfigError(f"{owner}: {name} must have {len(args)} items, got {len(value)}")
        if args:
            items = args[:1] * len(value) if args[-1] is Ellipsis else args
            return tuple(_check_value(owner, name, v, h) for v, h in zip(value, items))
        return tuple(value)
    if hint is bool:
        if isinstance(value, str) and value.strip().lower() in _BOOLEANS:
            return _BOOLEANS[value.strip().lower()]
        if isinstance(value, (int, np.integer)) and value in (0, 1):
            return bool(value)
        if not isinstance(value, bool):
            raise ConfigError(f"{owner}: {name} must be true or false (or yes/no, 1/0), got {value!r}")
        return value
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise ConfigError(f"{owner}: {name} must be an integer, got {value!r}")
        return int(value)
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) or not math.isfinite(value):
            raise ConfigError(f"{owner}: {name} must be a finite number, got {value!r}")
        return float(value)
    if hint is str and not isinstance(value, str):
        raise ConfigError(f"{owner}: {name} must be a string, got {value!r}")
    return value


def build_config(config_cls: type, overrides: dict, owner: str):
    """Validate ``overrides`` against ``config_cls`` and return a new config.

    Unknown names get a "did you mean"; values are type-checked against the
    dataclass annotations, ranges included (:class:`Range`), and so are the
    defaults. ``overrides`` itself is not modified.
    """
    fields = {f.name: f for f in dataclasses.fields(config_cls)}
    hints = typing.get_type_hints(config_cls, include_extras=True)
    clean = {}
    for key, value in overrides.items():
        if key not in fields:
            close = difflib.get_close_matches(key, list(fields), n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise ConfigError(f"{owner}: unknown hyperparameter {key!r}{hint} (known: {', '.join(sorted(fields))})")
        clean[key] = _check_value(owner, key, value, hints[key])
    for key in fields.keys() - clean.keys():
        if fields[key].default is not dataclasses.MISSING:
            _check_value(owner, key, fields[key].default, hints[key])
    config = config_cls(**clean)
    if hasattr(config, "validate"):
        config.validate()
    return config


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


def as_budget(budget_s: "float | Budget | None", steps: int | None = None) -> Budget:
    """A fit's budget from :meth:`Method.fit`'s arguments: seconds, a
    :class:`~bench.core.budget.Budget`, or ``steps`` of work."""
    if isinstance(budget_s, Budget):
        if steps is not None:
            raise ConfigError("give a Budget or steps, not both")
        return budget_s
    if steps is not None:
        if budget_s is not None:
            raise ConfigError("give budget_s (seconds) or steps (work), not both")
        return Budget(steps=steps)
    if budget_s is None or not (budget_s > 0):
        raise ConfigError(f"budget_s must be positive, got {budget_s}")
    return Budget(seconds=float(budget_s))


class Method(FittedModel):
    """Base class of every learning method. See the module docstring.

    A method writes :meth:`_fit`, :meth:`_get_state`, :meth:`_set_state` and
    the predictions of :class:`~bench.core.models.FittedModel`.
    """

    name: ClassVar[str] = "unnamed"
    tags: ClassVar[frozenset[str]] = frozenset()
    Config: ClassVar[type] = MethodConfig
    #: overrides of ``Config`` for a tiny CI run; each method declares its own
    smoke: ClassVar[dict] = {"max_steps": 5}
    #: the experiments the method applies to
    experiments: ClassVar[tuple[str, ...]] = EXPERIMENTS
    #: whether ``fit(..., warm_start=True)`` can continue from the current state
    supports_warm_start: ClassVar[bool] = False

    def __init__(self, **hyperparameters):
        self.config = build_config(self.Config, dict(hyperparameters), self.name)
        self.experiment: str | None = None
        self.warm_start = False
        self.seed: int | None = None
        self.dof: int | None = None
        self.system = None
        self.fit_info: dict = {}

    # -- class-level facts ---------------------------------------------------
    @classmethod
    def unavailable_reason(cls) -> str | None:
        """``None`` when the method can run here; otherwise why it cannot."""
        return None

    @classmethod
    def not_applicable_reason(cls, experiment: str, system: System | None = None) -> str | None:
        """Why the method cannot run ``experiment`` (on ``system``, where one is
        given); ``None`` when it can."""
        if experiment not in cls.experiments:
            return f"{cls.name} does not apply to the {experiment} experiment"
        return None

    @classmethod
    def smoke_config(cls) -> dict:
        return dict(cls.smoke)

    def hyperparameters(self) -> dict:
        return dataclasses.asdict(self.config)

    # -- the protocol ----------------------------------------------------------
    def fit(self, train: Dataset, experiment: str, seed: int, budget_s: "float | Budget | None" = None, *,
            steps: int | None = None, warm_start: bool = False, system: System | None = None) -> "Method":
        """Learn from ``train`` within ``budget_s`` seconds of wall-clock
        time, or within ``steps`` steps of the method's work (gradient steps,
        generations; see :mod:`bench.core.budget`).

        ``budget_s`` may also be a :class:`~bench.core.budget.Budget`: a
        work budget, or a time-budgeted fit's schedule to replay. Under a
        work budget the fit has no wall-clock deadline.

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
        budget = as_budget(budget_s, steps)
        if warm_start and not self.supports_warm_start:
            raise ConfigError(f"{self.name} cannot continue a fit (warm_start)")
        if warm_start and self.experiment is None:
            raise ConfigError(f"{self.name}: warm_start needs an earlier fit to continue")
        if warm_start and (experiment != self.experiment or train.dof != self.dof):
            raise ConfigError(f"{self.name}: warm_start continues a {self.experiment} fit of {self.dof} DoF; "
                              f"got {experiment} data of {train.dof} DoF")
        self.warm_start = warm_start
        check_experiment(experiment)
        reason = self.not_applicable_reason(experiment, system if system is not None else self._resolve_system(train))
        if reason:
            raise ConfigError(reason)
        if len(train) == 0:
            raise DataError(f"{train.source}: no samples to fit")
        train.target(experiment)  # raises a DataError naming what is missing
        prepare_seconds = self.prepare(train, experiment)
        t0 = time.perf_counter()
        self.experiment, self.seed, self.dof = experiment, int(seed), train.dof
        self.system = system if system is not None else self._resolve_system(train)
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
        with gc_frozen():
            self._fit(train, experiment, progress)
        progress.finish()
        if progress.best_state is not None:
            self._set_state(progress.best_state)
        self._post_fit(train, experiment, budget.fit_seconds - (time.perf_counter() - t0))
        self.fit_info = {
            "steps": self._work_done(progress),
            "best_step": progress.best_step,
            "stop_reason": progress.stop_reason or "loop ended",
            "fit_seconds": time.perf_counter() - t0,
            "prepare_seconds": prepare_seconds,
            "evaluations": progress.evaluations,
            "eval_seconds": progress.eval_seconds,
            "eval_samples": n_eval,
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
        self._prepare(train, experiment)
        self._prepared = key
        return round(time.perf_counter() - t0, 3)

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

    def variants(self) -> dict[str, "FittedModel | str"]:
        """Further fitted models derived from this one (for example a refined
        equation), each reported by the harness as ``<method>+<variant>``.

        A variant that could not be made is given as a string saying why; it
        is recorded as failed, so that every seed stays counted.
        """
        return {}

    def record_details(self) -> dict:
        """Method-specific facts for the run's record (JSON-serialisable)."""
        return {}

    # -- derived -----------------------------------------------------------------
    def predict(self, data: Dataset, experiment: str | None = None) -> np.ndarray:
        """The prediction in the experiment's own target (L or tau), by default the fitted one's."""
        return super().predict(data, experiment or self.experiment)


# -- torch methods that learn L(q, qd) by mini-batch gradient descent ------------------

@dataclass(frozen=True)
class TorchConfig(MethodConfig):
    """Hyperparameters shared by mini-batch torch methods.

    Attributes
    ----------
    lr
        Adam learning rate.
    betas
        Adam's moment coefficients.
    batch_size
        Mini-batch size; batches are drawn without replacement, reshuffled
        every epoch.
    dtype
        ``"float64"`` or ``"float32"``.
    """

    lr: Annotated[float, POSITIVE] = 1e-3
    betas: Annotated[tuple[float, float], Range(0, 1, high_open=True)] = (0.9, 0.999)
    batch_size: Annotated[int, Range(1)] = 32
    dtype: typing.Literal["float64", "float32"] = "float64"


class TorchLagrangianMethod(Method, LagrangianFunction):
    """A method whose model is a ``torch.nn.Module`` mapping ``(q, qd) -> L``.

    The loop is mini-batch Adam on the direct loss ``MSE(L_hat, L)`` or the
    indirect loss ``MSE(g(L_hat), tau)``; subclasses write :meth:`build_model`
    and optionally :meth:`make_scheduler` and :meth:`extra_loss`.
    """

    Config: ClassVar[type] = TorchConfig
    supports_warm_start: ClassVar[bool] = True
    model: torch.nn.Module

    @abc.abstractmethod
    def build_model(self, train: Dataset) -> torch.nn.Module:
        """The network, for data of ``train``'s shape."""

    def make_scheduler(self, optimizer: torch.optim.Optimizer):
        """Return an object with ``step(loss: float)``, or ``None``."""
        return None

    def extra_loss(self) -> torch.Tensor | float:
        return 0.0

    @property
    def dtype(self) -> torch.dtype:
        return getattr(torch, self.config.dtype)

    def lagrangian(self, q: torch.Tensor, qd: torch.Tensor) -> torch.Tensor:
        return self.model(q, qd)

    def batch_loss(self, batch: dict[str, torch.Tensor], experiment: str) -> torch.Tensor:
        if experiment == "direct":
            pred, target = self.lagrangian(batch["q"], batch["qd"]), batch["L"]
        else:
            pred = euler_lagrange(self.lagrangian, batch["q"], batch["qd"], batch["qdd"], create_graph=True)
            target = batch["tau"]
        return torch.mean((pred - target) ** 2) + self.extra_loss()

    def _fit(self, train: Dataset, experiment: str, progress: Progress) -> None:
        if not self.warm_start:
            self.model = self.build_model(train).to(self.dtype)
            self._optimizer = torch.optim.Adam(
                self.model.parameters(), lr=self.config.lr, betas=self.config.betas,
                **({"fused": True} if _fused_adam_ok(self.dtype) else {}),
            )
            self._scheduler = self.make_scheduler(self._optimizer)
        optimizer, scheduler = self._optimizer, self._scheduler
        tensors = train.tensors(self.dtype)
        generator = torch.Generator().manual_seed(self.seed)
        n, bs = len(train), min(self.config.batch_size, len(train))
        order, cursor = torch.randperm(n, generator=generator), 0
        while progress.step():
            if cursor + bs > n:
                order, cursor = torch.randperm(n, generator=generator), 0
            idx = order[cursor:cursor + bs]
            cursor += bs
            batch = {k: v[idx] for k, v in tensors.items()}
            loss = self.batch_loss(batch, experiment)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            if scheduler is not None:
                scheduler.step(loss.item())

    def _get_state(self):
        return {k: v.detach().clone() for k, v in self.model.state_dict().items()}

    def _set_state(self, state) -> None:
        self.model.load_state_dict(state)


def _fused_adam_ok(dtype: torch.dtype) -> bool:
    # fused Adam on CPU exists from torch 2.4 and is ~3x faster for a 5x300 MLP
    major, minor = (int(x) for x in torch.__version__.split(".")[:2])
    return (major, minor) >= (2, 4) and dtype in (torch.float32, torch.float64)


METHODS: Registry[type[Method]] = Registry("method")


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

    def predict_lagrangian(self, data):
        return self.model.predict_lagrangian(data)

    def predict_torque(self, data):
        return self.model.predict_torque(data)

