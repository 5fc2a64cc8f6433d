"""What defines one run of the matrix: :class:`RunSpec` and the matrix of
specs (:func:`build_specs`). A spec's code, the files its run's result
depends on, is :mod:`bench.runner.sources`'s.
"""

from __future__ import annotations

import argparse
import dataclasses
import re
from dataclasses import dataclass, field
from typing import Iterable

from bench.core.arguments import positive_int
from bench.core.budget import Budget, Schedule
from bench.runner.sources import RUNS_IN, code_hash

#: The ten seeds of every table, written once.
SEEDS: tuple[int, ...] = (0, 1, 2, 3, 4, 5, 6, 7, 8, 9)


def seed_count(text: str) -> int:
    """The command-line type of a number of the fixed seeds: 1 to ``len(SEEDS)``."""
    value = positive_int(text)
    if value > len(SEEDS):
        raise argparse.ArgumentTypeError(f"at most {len(SEEDS)} (the tables' fixed seeds), got {value}")
    return value
#: Test data for seed ``s`` is generated with seed ``s + TEST_SEED_OFFSET``.
TEST_SEED_OFFSET = 1000
#: The paper's data sizes.
N_TRAIN, N_TEST = 32000, 10000


#: the configurations a run id does not name
UNNAMED = ("default", "smoke")


def run_id(system: str, method: str, experiment: str, seed: int, noise: float = 0.0, tuned: bool = False,
           profile: str = "default") -> str:
    """``system__method__experiment__seedN``, with ``__noiseX`` when the targets are noisy,
    ``__profile-NAME`` when the method runs in a named configuration of its own (two of one method are
    two runs; :data:`UNNAMED`'s are not named: the defaults, and the smoke test's small copy of them) and
    ``__tuned`` when the run chose its hyperparameters (:mod:`bench.evaluation.tuning`)."""
    return (f"{system}__{method}__{experiment}__seed{seed}" + (f"__noise{noise:g}" if noise else "")
            + (f"__profile-{profile}" if profile not in UNNAMED else "") + ("__tuned" if tuned else ""))


_RUN_ID = re.compile(r"^(?P<system>\w+?)__(?P<method>[\w+]+?)__(?P<experiment>direct|indirect)__seed(?P<seed>\d+)"
                     r"(?:__noise(?P<noise>[0-9.e+-]+?))?(?:__profile-(?P<profile>[\w.-]+?))?(?P<tuned>__tuned)?$")


def parse_run_id(rid: str) -> dict | None:
    """The ``system``, ``method``, ``experiment``, ``seed`` and ``noise`` of a
    run id (:func:`run_id`), or ``None`` where ``rid`` is not one."""
    m = _RUN_ID.match(rid)
    if m is None:
        return None
    try:
        noise = float(m["noise"]) if m["noise"] else 0.0
    except ValueError:
        return None
    return {"system": m["system"], "method": m["method"], "experiment": m["experiment"], "seed": int(m["seed"]),
            "noise": noise, "profile": m["profile"] or "default", "tuned": m["tuned"] is not None}


@dataclass(frozen=True)
class RunSpec:
    """Everything that defines one run.

    Attributes
    ----------
    profile
        The method's configuration by name: ``"default"``, ``"smoke"`` (its
        tiny CI configuration) or one it names itself
        (:meth:`methods.base.Method.configuration`; ``--config``).
    hyperparameters
        Overrides on top of the profile.
    train_path, test_path
        CSV files in the suite's format; when ``train_path`` is ``None`` the
        data is generated with ``n_train`` samples from ``seed`` and
        ``n_test`` samples from ``seed + TEST_SEED_OFFSET``.
    domain_half_width
        Sample q, qd, qdd from U(-w, w) instead of the system's default.
    noise
        Gaussian noise added to the training targets, as a fraction of each
        target column's standard deviation (:func:`bench.core.data.add_noise`);
        the test targets stay clean.
    rollout
        Measure the rollout error (:mod:`bench.evaluation.rollout`) of simulated systems.
    plugins
        Python files or modules to import before resolving names, for methods
        and systems registered outside the suite.
    split
        Which of a measured system's splits (:attr:`~bench.physics.system.System.splits`)
        its data come from; ``None``: its default.
    device
        Where a torch method trains: ``cpu`` or ``cuda`` (resolved from
        ``--device``, :mod:`bench.core.devices`); other methods run on the CPU.
    tune
        Choose the method's hyperparameters from its search space on the
        training data, within the run's budget (:mod:`bench.evaluation.tuning`).
    folds
        The validation protocol of a tuned run (:func:`bench.core.protocols.folds`:
        ``time``, ``regions``, ``knndm`` or ``knndm:LOG``); ``None``: ``time``.
    save
        Write the fitted model to this model file (:mod:`methods.saving`);
        ``None``: do not.
    budget_s, steps, schedule
        The budget (:mod:`bench.core.budget`): ``budget_s`` seconds of
        wall-clock time; or, with ``steps``, that many steps of the method's
        work, ``budget_s`` then being a ceiling past which the run is killed
        (``None``: none); with ``schedule`` as well, the replay of a
        time-budgeted run (:class:`~bench.core.budget.Schedule` as JSON).
    """

    system: str
    method: str
    experiment: str
    seed: int
    budget_s: float | None
    profile: str = "default"
    hyperparameters: dict = field(default_factory=dict)
    n_train: int = N_TRAIN
    n_test: int = N_TEST
    train_path: str | None = None
    test_path: str | None = None
    domain_half_width: float | None = None
    plugins: tuple[str, ...] = ()
    threads: int = 1
    rollout: bool = True
    noise: float = 0.0
    steps: int | None = None
    schedule: dict | None = None
    split: str | None = None
    device: str = "cpu"
    tune: bool = False
    save: str | None = None
    folds: str | None = None

    def __post_init__(self):
        _ = self.budget  # a spec without a valid budget is refused where it is made (ConfigError)

    @property
    def run_id(self) -> str:
        return run_id(self.system, self.method, self.experiment, self.seed, self.noise, self.tune, self.profile)

    def code(self, runs_in: tuple[str, ...] = RUNS_IN) -> dict | None:
        """The record's ``code``: the files the run's result depends on, and their hash
        (:func:`bench.runner.sources.code_hash`; ``runs_in``: the modules that run it)."""
        return code_hash(self.method, self.system, self.plugins, runs_in)

    @property
    def budget(self) -> Budget:
        if self.schedule is not None:
            return Budget.replaying(Schedule.from_json(self.schedule), self.budget_s)
        return Budget(seconds=self.budget_s, steps=self.steps)

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["plugins"] = list(self.plugins)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "RunSpec":
        d = dict(d)
        d["plugins"] = tuple(d.get("plugins", ()))
        d.setdefault("tune", False)
        d.setdefault("save", None)
        d.setdefault("folds", None)
        return cls(**d)


def build_specs(
    systems: Iterable[str],
    methods: Iterable[str],
    experiments: Iterable[str],
    seeds: Iterable[int],
    budget_s: float | None,
    noises: Iterable[float] = (0.0,),
    **common,
) -> list[RunSpec]:
    """The matrix systems x methods x experiments x noise levels x seeds
    (``steps=N`` in ``common`` for a work budget, ``budget_s`` then its ceiling)."""
    noises = list(noises)
    return [
        RunSpec(system=s, method=m, experiment=e, seed=k, budget_s=budget_s, noise=float(z), **common)
        for s in systems for m in methods for e in experiments for z in noises for k in seeds
    ]
