"""The suite's one data format.

In memory, a :class:`Dataset` holds float64 arrays ``q, qd, qdd, tau`` of shape
``(n, dof)`` and, where it is known, the Lagrangian ``L`` of shape ``(n,)``.

On disk it is a CSV file with the columns::

    q_1..q_n, qd_1..qd_n, qdd_1..qdd_n, tau_1..tau_n[, L][, trajectory[, recording]][, time][, sign_qd_1..sign_qd_n]

``trajectory`` and ``recording`` are optional labels (any non-empty text).
Measured data come in recordings, and neighbouring samples of one recording
are near copies; a robot also repeats an excitation trajectory, and a
recording of the same trajectory again is a near copy of the first. So
whatever is validated on held-out data holds out whole *trajectories*, every
recording of one trajectory together (:meth:`Dataset.trajectories`):

* ``trajectory`` alone names each sample's recording, which is then a
  trajectory of its own (the DFKI recordings, DeLaN's characters);
* ``trajectory`` with ``recording`` names the trajectory a recording
  follows and the recording itself (the KUKA's runs 1 and 2 repeat one
  trajectory);
* ``recording`` alone is refused: recordings whose trajectories are not
  named cannot be held out honestly.

Generated samples are independent and have none of these.

``time`` is optional: each sample's time in its recording, in seconds. The
driven rollouts of measured data (:mod:`bench.evaluation.driven`) need it.

``sign_qd_i`` is optional too: the sign of joint i's velocity as the
torque's low-pass saw it. Where a recording's torque was filtered
(:func:`bench.core.recordings.preprocess`), Coulomb friction's jump at
``qd = 0`` reaches the samples rounded off over the filter's span, and a
model whose friction column is ``sign(qd)`` fits that rounding with a
steeper viscous slope. The converter therefore puts ``sign(qd)`` through the
same filter at the full rate (parallel filtering) and writes it here; every
term's torque that contains ``sign(qd_i)`` uses it
(:meth:`Dataset.velocity_sign`). Without these columns it is ``sign(qd)``.

Further columns (time stamps, labels) are allowed and ignored. The same
format serves generated and measured data, so any method can be given
measured data.

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
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from bench.core.errors import ConfigError, DataError
from bench.core.fileio import atomic_write

EXPERIMENTS = ("direct", "indirect")
#: bump when the generator changes what it produces for the same key
GENERATOR_VERSION = 1


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

    def target(self, experiment: str) -> np.ndarray:
        """The experiment's target: ``L`` (direct, shape (n,)) or ``tau`` (indirect)."""
        check_experiment(experiment)
        if experiment == "direct":
            if self.L is None:
                raise DataError(f"{self.source}: the direct experiment needs column 'L', which this data lacks")
            return self.L
        return self.tau

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

    def trajectory_labels(self) -> np.ndarray | None:
        """``(n,)``: the trajectory of each sample, its recording's label where
        every recording is a trajectory of its own; ``None`` for independent samples."""
        return self.recording if self.trajectory is None else self.trajectory

    def trajectories(self) -> list[str]:
        """The trajectories' labels in order of first appearance (recordings of
        one trajectory count once); ``[]`` for independent samples."""
        return _in_order(self.trajectory_labels())

    def tensors(self, dtype: torch.dtype = torch.float64, device: torch.device | str | None = None) -> dict[str, torch.Tensor]:
        """``q, qd, qdd, tau`` (and ``L``) as tensors of ``dtype`` on ``device`` (the CPU by default)."""
        out = {k: torch.tensor(getattr(self, k), dtype=dtype, device=device) for k in ("q", "qd", "qdd", "tau")}
        if self.L is not None:
            out["L"] = torch.tensor(self.L, dtype=dtype, device=device)
        return out


def _in_order(labels: np.ndarray | None) -> list[str]:
    if labels is None:
        return []
    unique, first = np.unique(labels, return_index=True)
    return [str(unique[i]) for i in np.argsort(first)]


def check_experiment(experiment: str) -> None:
    if experiment not in EXPERIMENTS:
        raise ConfigError(f"unknown experiment {experiment!r}; choose one of {', '.join(EXPERIMENTS)}")


# -- generation ------------------------------------------------------------------

def cache_dir() -> Path:
    return Path(os.environ.get("SYRENETS_BENCH_CACHE", Path.home() / ".cache" / "syrenets-bench"))


def _cache_key(system, n: int, seed: int) -> str:
    desc = {"v": GENERATOR_VERSION, "n": n, "seed": seed, **system.describe()}
    return hashlib.sha256(json.dumps(desc, sort_keys=True).encode()).hexdigest()[:20]


def generate(system, n: int, seed: int, *, cache: bool = True) -> Dataset:
    """Sample ``n`` states of ``system`` with ``seed``; torques from :mod:`bench.core.dynamics`.

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
    qt, qdt, qddt = (torch.from_numpy(a) for a in (q, qd, qdd))
    tau, L = system.torque(qt, qdt, qddt)
    data = Dataset(q, qd, qdd, tau.numpy(), L.numpy(), system.name, source)
    if cache:
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(path, lambda f: np.savez(f, q=q, qd=qd, qdd=qdd, tau=data.tau, L=data.L), binary=True)
    return data


# -- CSV ---------------------------------------------------------------------------

_COLUMN = re.compile(r"^(q|qd|qdd|tau)_(\d+)$")
#: the optional column naming each sample's trajectory (alone: its recording, a trajectory of its own)
TRAJECTORY = "trajectory"
#: the optional column naming each sample's recording, beside :data:`TRAJECTORY`
RECORDING = "recording"
#: the optional column of each sample's time in its recording, s
TIME = "time"
#: the optional columns ``sign_qd_1..sign_qd_n`` (:attr:`Dataset.sign_qd`)
SIGN = "sign_qd"


def columns(dof: int, with_L: bool) -> list[str]:
    cols = [f"{k}_{i}" for k in ("q", "qd", "qdd", "tau") for i in range(1, dof + 1)]
    return cols + (["L"] if with_L else [])


def write_csv(data: Dataset, path: str | os.PathLike) -> None:
    """Write ``data`` in the suite's CSV format, atomically (no partial file)."""
    import pandas as pd

    arrays = {}
    for k in ("q", "qd", "qdd", "tau"):
        for i in range(data.dof):
            arrays[f"{k}_{i + 1}"] = getattr(data, k)[:, i]
    if data.L is not None:
        arrays["L"] = data.L
    if data.recording is not None:
        arrays[TRAJECTORY] = data.trajectory_labels()
        if data.trajectory is not None:
            arrays[RECORDING] = data.recording
    if data.time is not None:
        arrays[TIME] = data.time
    if data.sign_qd is not None:
        for i in range(data.dof):
            arrays[f"{SIGN}_{i + 1}"] = data.sign_qd[:, i]
    frame = pd.DataFrame(arrays)
    atomic_write(Path(path), lambda f: frame.to_csv(f, index=False, float_format="%.17g"))


#: the separators besides the comma that a CSV file may use, tried where its header has no comma
OTHER_SEPARATORS = (";", "\t")


def read_frame(path: Path, nrows: int | None = None):
    """A CSV file (optionally compressed) as a DataFrame with at least one row
    and distinct column names (its first ``nrows`` rows only, where given);
    :class:`DataError` naming the file otherwise. A file whose header is one
    name holding semicolons or tabs is read with that separator (a spreadsheet's
    export in a locale whose decimal mark is the comma)."""
    import pandas as pd

    path = Path(path)
    if path.is_dir():
        raise DataError(f"{path}: is a folder, not a file")
    if not path.is_file():
        raise DataError(f"{path}: no such file")
    try:
        header = pd.read_csv(path, header=None, nrows=1, dtype=str, keep_default_na=False)
        sep = ","
        if header.shape[1] == 1 and len(header):
            sep = next((s for s in OTHER_SEPARATORS if s in str(header.iloc[0, 0])), ",")
            if sep != ",":
                header = pd.read_csv(path, header=None, nrows=1, dtype=str, keep_default_na=False, sep=sep)
        frame = pd.read_csv(path, nrows=nrows, sep=sep)
    except pd.errors.EmptyDataError:
        raise DataError(f"{path}: the file is empty") from None
    except (pd.errors.ParserError, UnicodeDecodeError, ValueError, EOFError, OSError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise DataError(f"{path}: not a readable CSV file ({first})") from None
    names = [str(v).strip() for v in header.iloc[0]] if len(header) else []
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise DataError(f"{path}: column name(s) {', '.join(map(repr, repeated))} appear more than once")
    if len(frame) == 0:
        raise DataError(f"{path}: the file has a header but no rows")
    return frame


#: the largest magnitude a value read from a file may have: its square stays finite,
#: so that least squares on it cannot overflow
MAX_ABS_VALUE = float(np.sqrt(np.finfo(np.float64).max))


def numeric_column(frame, col: str, path: Path) -> np.ndarray:
    """Column ``col`` as float64; :class:`DataError` naming the file, column and
    data row of the first non-numeric, NaN, empty or infinite value, or of a
    value whose square would overflow (above :data:`MAX_ABS_VALUE`)."""
    import pandas as pd

    values = pd.to_numeric(frame[col], errors="coerce").to_numpy(dtype=np.float64)
    bad_text = np.isnan(values) & frame[col].notna().to_numpy()
    if bad_text.any():
        row = int(np.flatnonzero(bad_text)[0])
        raise DataError(f"{path}: column {col} has a non-numeric value {frame[col].iloc[row]!r} in data row {row + 1}")
    bad = ~np.isfinite(values)
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        what = "NaN or empty" if np.isnan(values[row]) else "inf"
        raise DataError(f"{path}: column {col} has a {what} value in data row {row + 1}")
    huge = np.abs(values) > MAX_ABS_VALUE
    if huge.any():
        row = int(np.flatnonzero(huge)[0])
        raise DataError(f"{path}: column {col} has a value too large to compute with ({values[row]:g}, above "
                        f"{MAX_ABS_VALUE:.3g}) in data row {row + 1}")
    return values


def read_csv(path: str | os.PathLike, *, dof: int | None = None, system: str | None = None) -> Dataset:
    """Load a CSV in the suite's format, checking it thoroughly.

    Raises :class:`DataError` with a one-line message naming the file and the
    problem for: an unreadable or empty file, missing columns, a number of
    degrees of freedom other than ``dof``, non-numeric, NaN or infinite values.
    """
    path = Path(path)
    frame = read_frame(path)

    found: dict[str, set[int]] = {k: set() for k in ("q", "qd", "qdd", "tau")}
    for col in frame.columns:
        m = _COLUMN.match(str(col).strip())
        if m:
            found[m.group(1)].add(int(m.group(2)))
    file_dof = max((max(v) for v in found.values() if v), default=0)
    if file_dof == 0:
        raise DataError(f"{path}: no q_1 column; expected columns {', '.join(columns(dof or 1, False))}")
    if dof is not None and file_dof != dof:
        who = f"system {system!r}" if system else "the model"
        raise DataError(f"{path}: the file has {file_dof} degrees of freedom (q_1..q_{file_dof}) but {who} has {dof}")
    need = columns(file_dof, False)
    missing = [c for c in need if c not in frame.columns]
    if missing:
        raise DataError(f"{path}: missing column(s) {', '.join(missing)}")

    def numeric(col: str) -> np.ndarray:
        return numeric_column(frame, col, path)

    arrays = {k: np.stack([numeric(f"{k}_{i}") for i in range(1, file_dof + 1)], axis=1) for k in found}
    L = numeric("L") if "L" in frame.columns else None
    trajectory = label_column(frame, TRAJECTORY, path) if TRAJECTORY in frame.columns else None
    recording = label_column(frame, RECORDING, path) if RECORDING in frame.columns else None
    if recording is None:  # the trajectory column alone: each recording a trajectory of its own
        recording, trajectory = trajectory, None
    elif trajectory is None:
        raise DataError(f"{path}: recordings {', '.join(_in_order(recording)[:4])} (column {RECORDING}) name no "
                        f"trajectory (column {TRAJECTORY}): say which trajectory each follows, e.g. with "
                        f"bench convert --trajectory NAME")
    else:
        _check_nesting(recording, trajectory, path)
    time = numeric("time") if TIME in frame.columns else None
    signs = [f"{SIGN}_{i}" for i in range(1, file_dof + 1)]
    present = [c for c in signs if c in frame.columns]
    if present and len(present) < len(signs):
        raise DataError(f"{path}: has {', '.join(present)} but not {', '.join(c for c in signs if c not in present)} "
                        f"(the filtered velocity signs come for every joint or for none)")
    sign_qd = np.stack([numeric(c) for c in signs], axis=1) if present else None
    return Dataset(arrays["q"], arrays["qd"], arrays["qdd"], arrays["tau"], L, system, str(path), recording=recording,
                   sign_qd=sign_qd, trajectory=trajectory, time=time)


def _check_nesting(recording: np.ndarray, trajectory: np.ndarray, path: Path) -> None:
    """Each recording follows one trajectory; :class:`DataError` naming the first that follows two."""
    pairs = np.unique(np.stack([recording, trajectory], axis=1), axis=0)
    names, counts = np.unique(pairs[:, 0], return_counts=True)
    if np.any(counts > 1):
        name = str(names[counts > 1][0])
        both = sorted(str(t) for r, t in pairs if r == name)
        raise DataError(f"{path}: recording {name!r} is labelled with two trajectories ({', '.join(both)}) in column "
                        f"{TRAJECTORY}; a recording follows one trajectory")


def label_column(frame, col: str, path: Path) -> np.ndarray:
    """Column ``col`` as text labels; :class:`DataError` naming the file, column
    and data row of the first empty value."""
    raw = frame[col]
    empty = raw.isna().to_numpy() | (raw.astype(str).str.strip() == "").to_numpy()
    if empty.any():
        row = int(np.flatnonzero(empty)[0])
        raise DataError(f"{path}: column {col} has an empty value in data row {row + 1}")
    return raw.astype(str).str.strip().to_numpy(dtype=str)


def add_noise(data: Dataset, experiment: str, level: float, seed: int) -> Dataset:
    """``data`` with Gaussian noise on the experiment's target.

    The noise of each target column (``L``, or each joint's ``tau``) has a
    standard deviation of ``level`` times that column's own standard
    deviation. It is drawn from its own stream of ``seed``, so the samples
    stay those of the clean data.
    """
    check_experiment(experiment)
    if not (level >= 0 and math.isfinite(level)):
        raise ValueError(f"noise level must be a finite number >= 0, got {level}")
    rng = np.random.default_rng([seed, 0x6E6F6973])  # "nois"
    L, tau = data.L, data.tau
    if experiment == "direct":
        target = data.target(experiment)
        L = target + rng.normal(0.0, level * target.std(), target.shape)
    else:
        tau = tau + rng.normal(0.0, 1.0, tau.shape) * (level * tau.std(axis=0))
    meta = {**data.meta, "noise": level}
    return data.replace(tau=tau, L=L, source=f"{data.source} + {level:g} x std noise on {experiment} targets", meta=meta)


# -- helpers -------------------------------------------------------------------------

def mse(prediction: np.ndarray, target: np.ndarray) -> float:
    """Mean squared error over all elements; ``nan`` when any input is not finite."""
    diff = np.asarray(prediction, dtype=np.float64) - np.asarray(target, dtype=np.float64)
    if diff.shape != np.shape(target):
        raise ValueError(f"prediction shape {np.shape(prediction)} != target shape {np.shape(target)}")
    value = float(np.mean(diff * diff))
    return value if math.isfinite(value) else float("nan")
