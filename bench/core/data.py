"""The suite's one data format.

In memory, a :class:`Dataset` holds float64 arrays ``q, qd, qdd, tau`` of shape
``(n, dof)`` and, where it is known, the Lagrangian ``L`` of shape ``(n,)``.

On disk it is a CSV file (:mod:`bench.core.csv_format`, which says what its
columns are). Measured data come in recordings, and neighbouring samples of
one recording are near copies; a robot also repeats an excitation
trajectory, and a recording of the same trajectory again is a near copy of
the first. So whatever is validated on held-out data holds out whole
*trajectories*, every recording of one trajectory together
(:meth:`Dataset.trajectories`). Generated samples are independent and have
no recordings.

Generated data is a pure function of ``(system, n, seed)`` (and of the
system's parameters and domain) and is cached as ``.npz`` under
``$SYRENETS_BENCH_CACHE`` (default ``~/.cache/syrenets-bench``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bench.core.errors import DataError
from bench.core.experiment import Experiment
from bench.core.fileio import atomic_write
#: bump when the generator changes what it produces for the same key
GENERATOR_VERSION = 1


#: the arrays of a sample that are its state: what a model predicts from
STATES = ("q", "qd", "qdd")


@dataclass(frozen=True, eq=False)
class Dataset:
    """Samples of a Lagrangian system.

    Attributes
    ----------
    q, qd, qdd, tau
        float64 arrays of shape ``(n, dof)``.
    L
        float64 array of shape ``(n,)`` or ``None`` when unknown (measured data).
    system
        The registered system name the data belongs to, if any.
    source
        Where it came from: a file path or a generator description.
    recording
        Array of shape ``(n,)`` of text labels: the recording each sample
        comes from, or ``None`` for independent samples.
    trajectory
        Array of shape ``(n,)`` of text labels: the trajectory each sample's
        recording follows, or ``None`` where every recording is a trajectory
        of its own (see the module docstring).
    time
        Array of shape ``(n,)``: each sample's time in its recording, s, or
        ``None`` where not known.
    sign_qd
        Array of shape ``(n, dof)``: the sign of each velocity as the
        torque's filter saw it (see the module docstring), or ``None`` where
        the torque was not filtered (then ``sign(qd)``).
    """

    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray
    L: np.ndarray | None = None
    system: str | None = None
    source: str = "memory"
    meta: dict = field(default_factory=dict)
    recording: np.ndarray | None = None
    sign_qd: np.ndarray | None = None
    trajectory: np.ndarray | None = None
    time: np.ndarray | None = None

    def __post_init__(self):
        shapes = {a.shape for a in (self.q, self.qd, self.qdd, self.tau)}
        if len(shapes) != 1 or self.q.ndim != 2:
            raise DataError(f"{self.source}: q, qd, qdd, tau must share one (n, dof) shape, got {sorted(shapes)}")
        if self.L is not None and self.L.shape != (self.q.shape[0],):
            raise DataError(f"{self.source}: L must have shape ({self.q.shape[0]},), got {self.L.shape}")
        for name in ("recording", "trajectory"):
            if getattr(self, name) is not None:
                labels = np.asarray(getattr(self, name), dtype=str)
                if labels.shape != (self.q.shape[0],):
                    raise DataError(f"{self.source}: {name} must have shape ({self.q.shape[0]},), got {labels.shape}")
                object.__setattr__(self, name, labels)
        if self.trajectory is not None and self.recording is None:
            raise DataError(f"{self.source}: trajectory labels need recording labels beside them")
        if self.time is not None:
            times = np.asarray(self.time, dtype=np.float64)
            if times.shape != (self.q.shape[0],):
                raise DataError(f"{self.source}: time must have shape ({self.q.shape[0]},), got {times.shape}")
            object.__setattr__(self, "time", times)
        if self.sign_qd is not None and self.sign_qd.shape != self.q.shape:
            raise DataError(f"{self.source}: sign_qd must have the shape of q, {self.q.shape}, got {self.sign_qd.shape}")

    def __len__(self) -> int:
        return self.q.shape[0]

    @property
    def dof(self) -> int:
        return self.q.shape[1]

    def target(self, experiment: "str | Experiment") -> np.ndarray:
        """The experiment's target (:attr:`Experiment.target`): ``L`` (direct, shape (n,)) or ``tau`` (indirect)."""
        self.check_target(experiment)
        return getattr(self, Experiment.of(experiment).target)

    def check_target(self, experiment: "str | Experiment") -> None:
        """Raise :class:`DataError` where the data lack the experiment's target, reading none of its values
        (so a sealed test split, :mod:`bench.core.sealed`, can be checked too)."""
        experiment = Experiment.of(experiment)
        if object.__getattribute__(self, experiment.target) is None:
            raise DataError(f"{self.source}: the {experiment} experiment needs column '{experiment.target}', "
                            f"which this data lacks")

    def subset(self, index) -> "Dataset":
        return Dataset(
            self.q[index], self.qd[index], self.qdd[index], self.tau[index],
            None if self.L is None else self.L[index], self.system, self.source, dict(self.meta),
            None if self.recording is None else self.recording[index],
            None if self.sign_qd is None else self.sign_qd[index],
            None if self.trajectory is None else self.trajectory[index],
            None if self.time is None else self.time[index],
        )

    def replace(self, **changes) -> "Dataset":
        """A copy with the given fields changed (the rest, recordings included, kept)."""
        return dataclasses.replace(self, **changes)

    def with_torque(self, tau: np.ndarray) -> "Dataset":
        """A plain copy of these states (labels and times kept) with the torques ``tau`` and no ``L``: the
        torques a model predicts at them, read without reading this data's own targets (a sealed test
        split's, :mod:`bench.core.sealed`)."""
        kept = {f.name: getattr(self, f.name) for f in dataclasses.fields(Dataset) if f.name not in ("tau", "L")}
        return Dataset(**kept, tau=tau, L=None)

    def velocity_sign(self) -> np.ndarray:
        """``(n, dof)``: :attr:`sign_qd` where the data carry it, else ``sign(qd)``."""
        return np.sign(self.qd) if self.sign_qd is None else self.sign_qd

    def recordings(self) -> list[str]:
        """The recordings' labels in order of first appearance; ``[]`` for independent samples."""
        return _in_order(self.recording)

    def in_time_order(self) -> list[np.ndarray]:
        """Per recording (in :meth:`recordings`' order), the indices of its
        samples in time order (in stored order where the data carry no time);
        ``[]`` for independent samples."""
        out = []
        for name in self.recordings():
            index = np.flatnonzero(self.recording == name)
            if self.time is not None:
                index = index[np.argsort(self.time[index], kind="stable")]
            out.append(index)
        return out

    def thinned(self, limit: int) -> tuple["Dataset", int]:
        """At most about ``limit`` samples and the step ``k`` taken: every
        ``k``-th sample of each recording in time order (of the samples, where
        there are no recordings), ``k`` the smallest that leaves ``limit`` or
        fewer (and one more a recording); ``(self, 1)`` where there are that few already."""
        step = max(1, math.ceil(len(self) / max(limit, 1)))
        if step == 1:
            return self, 1
        order = self.in_time_order() or [np.arange(len(self))]
        return self.subset(np.sort(np.concatenate([index[::step] for index in order]))), step

    def trajectory_labels(self) -> np.ndarray | None:
        """``(n,)``: the trajectory of each sample, its recording's label where
        every recording is a trajectory of its own; ``None`` for independent samples."""
        return self.recording if self.trajectory is None else self.trajectory

    def trajectories(self) -> list[str]:
        """The trajectories' labels in order of first appearance (recordings of
        one trajectory count once); ``[]`` for independent samples."""
        return _in_order(self.trajectory_labels())

    def tensors(self, dtype: torch.dtype | None = None, device: torch.device | str | None = None) -> dict[str, torch.Tensor]:
        """``q, qd, qdd, tau`` (and ``L``) as tensors of ``dtype`` (float64 by default) on ``device`` (the CPU by
        default): those of :meth:`readable` (a sealed test split's states only, outside scoring)."""
        import torch  # here: reading and checking a dataset needs no torch

        dtype = torch.float64 if dtype is None else dtype
        return {k: torch.tensor(getattr(self, k), dtype=dtype, device=device) for k in self.readable()}

    def readable(self) -> tuple[str, ...]:
        """The arrays :meth:`tensors` gives: :data:`STATES`, ``tau``, and ``L`` where known."""
        return STATES + ("tau",) + (() if self.L is None else ("L",))

    def evenly(self, count: int) -> np.ndarray:
        """The indices of at most ``count`` samples, evenly spread over the data's order."""
        return np.unique(np.linspace(0, len(self) - 1, min(count, len(self))).astype(int))


def _in_order(labels: np.ndarray | None) -> list[str]:
    if labels is None:
        return []
    unique, first = np.unique(labels, return_index=True)
    return [str(unique[i]) for i in np.argsort(first)]


# -- generation ------------------------------------------------------------------

def cache_dir() -> Path:
    return Path(os.environ.get("SYRENETS_BENCH_CACHE", Path.home() / ".cache" / "syrenets-bench"))


def _cache_key(system, n: int, seed: int) -> str:
    desc = {"v": GENERATOR_VERSION, "n": n, "seed": seed, **system.describe()}
    return hashlib.sha256(json.dumps(desc, sort_keys=True).encode()).hexdigest()[:20]


def generate(system, n: int, seed: int, *, cache: bool = True) -> Dataset:
    """Sample ``n`` states of ``system`` with ``seed``; torques from :mod:`bench.physics.dynamics`.

    ``q``, ``qd`` and ``qdd`` are drawn independently and uniformly from the
    system's domain, in that order, from ``numpy.random.default_rng(seed)``.
    The torque is ``g(L) + system.nonconservative_torque``, in float64.
    """
    if not getattr(system, "simulated", True):
        raise DataError(f"system {system.name!r} is measured; it cannot generate data")
    if n <= 0:
        raise DataError(f"generate: n must be positive, got {n}")
    source = f"generated:{system.name}:n={n}:seed={seed}"
    path = cache_dir() / f"{system.name}-{_cache_key(system, n, seed)}.npz"
    if cache and path.exists():
        with np.load(path) as z:
            return Dataset(z["q"], z["qd"], z["qdd"], z["tau"], z["L"], system.name, source)
    rng = np.random.default_rng(seed)
    dom = system.domain
    q, qd, qdd = (rng.uniform(*dom.bounds(k, system.dof), size=(n, system.dof)) for k in ("q", "qd", "qdd"))
    import torch

    qt, qdt, qddt = (torch.from_numpy(a) for a in (q, qd, qdd))
    tau, L = system.torque(qt, qdt, qddt)
    data = Dataset(q, qd, qdd, tau.numpy(), L.numpy(), system.name, source)
    if cache:
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(path, lambda f: np.savez(f, q=q, qd=qd, qdd=qdd, tau=data.tau, L=data.L), binary=True)
    return data


def add_noise(data: Dataset, experiment: str, level: float, seed: int) -> Dataset:
    """``data`` with Gaussian noise on the experiment's target.

    The noise of each target column (``L``, or each joint's ``tau``) has a
    standard deviation of ``level`` times that column's own standard
    deviation. It is drawn from its own stream of ``seed``, so the samples
    stay those of the clean data.
    """
    experiment = Experiment.of(experiment)
    if not (level >= 0 and math.isfinite(level)):
        raise ValueError(f"noise level must be a finite number >= 0, got {level}")
    rng = np.random.default_rng([seed, 0x6E6F6973])  # "nois"
    target = data.target(experiment)
    # L: one standard deviation over the samples; torques: each joint's own
    scale = level * (target.std(axis=0) if experiment.learns_torque else target.std())
    noisy = target + rng.normal(0.0, 1.0, target.shape) * scale
    meta = {**data.meta, "noise": level}
    return data.replace(**{experiment.target: noisy}, source=f"{data.source} + {level:g} x std noise on {experiment} targets", meta=meta)


# -- helpers -------------------------------------------------------------------------

def mse(prediction: np.ndarray, target: np.ndarray) -> float:
    """Mean squared error over all elements; ``nan`` when any input is not finite."""
    diff = np.asarray(prediction, dtype=np.float64) - np.asarray(target, dtype=np.float64)
    if diff.shape != np.shape(target):
        raise ValueError(f"prediction shape {np.shape(prediction)} != target shape {np.shape(target)}")
    value = float(np.mean(diff * diff))
    return value if math.isfinite(value) else float("nan")
