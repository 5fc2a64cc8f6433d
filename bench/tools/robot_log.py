"""Write a simulated robot's logs: what a real robot's software records,
for trying ``bench convert --columns`` and the residual loop on data whose
truth is known.

Each recording follows an excitation trajectory of the kind identification
uses (Swevers, Ganseman, Tukel, De Schutter & Van Brussel 1997): per joint a
finite Fourier series of :data:`HARMONICS` harmonics of a base frequency,
with random coefficients, so that ``q``, ``qd`` and ``qdd`` are exact and
smooth. Each joint's amplitude keeps it within :data:`REACH` of the system's
own range of positions and of velocities. The torque is the system's (:meth:`System.torque
<bench.physics.system.System.torque>`) plus the undeclared effects
(:func:`bench.physics.undeclared.add_effects`) plus Gaussian noise of a
fraction of each joint's torque standard deviation (:func:`bench.core.data.add_noise`),
sampled at ``rate_hz``. The log has a time column and, per joint, position,
velocity and torque columns under the names a robot's software uses
(``joint1_position``, ``joint1_velocity``, ``joint1_effort``); accelerations
are not logged. Usage::

    python -m bench robot-log --system panda --recordings 6 --seconds 30 \\
        --effects viscous_friction=... coulomb_friction=... offset=... --noise 0.03 \\
        [--torque-delay 0.005] --out logs/

It prints the ``bench convert --columns`` mapping for the logs it wrote.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch

from bench.core.arguments import noise_level, nonnegative, positive, positive_int, seed
from bench.core.data import Dataset, add_noise
from bench.core.errors import ConfigError
from bench.core.fileio import atomic_write
from bench.physics.undeclared import add_effects, parse_effects
from systems import get_system

#: harmonics of each joint's Fourier series
HARMONICS = 5
#: the share of the system's half-range of positions and velocities a trajectory may reach
REACH = 0.8


def fourier_trajectory(dof: int, time: np.ndarray, base_hz: float, rng: np.random.Generator):
    """``q, qd, qdd`` (each ``(n, dof)``) of a unit-amplitude finite Fourier
    series per joint: ``q_j = sum_l (a_jl sin(l w t) - b_jl cos(l w t)) / (l w)``
    with ``w = 2 pi base_hz`` and ``a, b ~ N(0, 1)``, scaled so that
    ``max |q_j| = 1``."""
    w = 2 * math.pi * base_hz
    ls = np.arange(1, HARMONICS + 1)
    a, b = rng.normal(size=(dof, HARMONICS)), rng.normal(size=(dof, HARMONICS))
    phase = np.outer(time, ls * w)  # (n, L)
    q = (np.sin(phase) @ (a / (ls * w)).T) - (np.cos(phase) @ (b / (ls * w)).T)
    qd = np.cos(phase) @ a.T + np.sin(phase) @ b.T
    qdd = -(np.sin(phase) @ (a * ls * w).T) + np.cos(phase) @ (b * ls * w).T
    scale = np.abs(q).max(axis=0)
    return q / scale, qd / scale, qdd / scale


def simulate(system_name: str, seconds: float, rate_hz: float, base_hz: float, effects: list[str], noise: float,
             seed: int, torque_delay: float = 0.0, noise_seed: int | None = None) -> tuple[np.ndarray, Dataset]:
    """One recording: its time stamps and its samples (``q, qd, qdd`` exact,
    the torque with the effects and the noise). ``seed`` draws the trajectory
    and, unless ``noise_seed`` is given (a repeat of one trajectory with noise
    of its own), the noise. With ``torque_delay`` the
    torque logged at ``t`` is the one at ``t - torque_delay`` (its effects
    and noise included): a sensor's or a filter's delay, exact because the
    trajectory is a Fourier series."""
    system = get_system(system_name)
    if not system.simulated:
        raise ConfigError(f"{system_name} is measured; a log can be simulated for a simulated system only")
    fx = parse_effects(effects, system.dof)
    time = np.arange(int(round(seconds * rate_hz))) / rate_hz
    rng = np.random.default_rng(seed)
    n = len(time)
    # the logged states' times, then the torque's: one series, one scale
    q, qd, qdd = fourier_trajectory(system.dof, np.concatenate([time, time - torque_delay]), base_hz, rng)
    (q_lo, q_hi), (v_lo, v_hi) = (system.domain.bounds(k, system.dof) for k in ("q", "qd"))
    # each joint's amplitude: within REACH of its range of positions, and of velocities
    amplitude = REACH * np.minimum((q_hi - q_lo) / 2, (v_hi - v_lo) / 2 / np.abs(qd).max(axis=0))
    q, qd, qdd = (q_lo + q_hi) / 2 + amplitude * q, amplitude * qd, amplitude * qdd
    seen = [np.ascontiguousarray(x[n:]) for x in (q, qd, qdd)]  # where the arm was when its torque was logged
    tau, L = system.torque(*(torch.from_numpy(x) for x in seen))
    data = Dataset(*seen, tau.numpy(), L.numpy(), system.name, f"simulated log of {system.name}")
    data = add_effects(data, fx, system)
    data = add_noise(data, "indirect", noise, seed if noise_seed is None else noise_seed) if noise else data
    if torque_delay:
        data = data.replace(q=q[:n], qd=qd[:n], qdd=qdd[:n], L=None,
                            source=f"{data.source}, its torque {torque_delay:g} s behind its state")
    return time, data


def columns(dof: int) -> str:
    """The ``bench convert --columns`` mapping of the logs this writes."""
    return ",".join(["time=time"] + [f"{k}_{j}=joint{j}_{name}" for j in range(1, dof + 1)
                                     for k, name in (("q", "position"), ("qd", "velocity"), ("tau", "effort"))])


def write_log(path: Path, time: np.ndarray, data: Dataset) -> None:
    import pandas as pd

    frame = {"time": time}
    for j in range(data.dof):
        frame[f"joint{j + 1}_position"] = data.q[:, j]
        frame[f"joint{j + 1}_velocity"] = data.qd[:, j]
        frame[f"joint{j + 1}_effort"] = data.tau[:, j]
    atomic_write(path, lambda f: pd.DataFrame(frame).to_csv(f, index=False, float_format="%.17g"))


#: the subcommand's one-line help


def add_arguments(parser) -> None:
    parser.add_argument("--system", required=True, help="a simulated system")
    parser.add_argument("--recordings", type=positive_int, default=6, help="recordings to write (default 6)")
    parser.add_argument("--seconds", type=positive, default=30.0, help="seconds per recording (default 30)")
    parser.add_argument("--rate-hz", type=positive, default=500.0, help="samples per second (default 500)")
    parser.add_argument("--base-hz", type=positive, default=0.1,
                        help=f"the Fourier series' base frequency; {HARMONICS} harmonics (default 0.1)")
    parser.add_argument("--effects", nargs="+", default=[], metavar="NAME=...",
                        help="undeclared effects, as bench data --effects takes them")
    parser.add_argument("--noise", type=noise_level, default=0.0,
                        help="Gaussian noise on the torque, a fraction of each joint's torque std (default 0)")
    parser.add_argument("--seed", type=seed, default=0, help="recording k uses seed + k (default 0)")
    parser.add_argument("--torque-delay", type=nonnegative, default=0.0, metavar="SECONDS",
                        help="log each torque this many seconds after the state it belongs to (a sensor's or "
                             "filter's delay; default 0)")
    parser.add_argument("--out", type=Path, required=True, help="the folder to write recording_<k>.csv into")


def main(args) -> int:
    dof = None
    for k in range(args.recordings):
        time, data = simulate(args.system, args.seconds, args.rate_hz, args.base_hz, args.effects, args.noise, args.seed + k,
                              args.torque_delay)
        args.out.mkdir(parents=True, exist_ok=True)  # once the system and the effects are known to be good
        path = args.out / f"recording_{k}.csv"
        write_log(path, time, data)
        dof = data.dof
        print(f"wrote {path} ({len(time)} samples, {args.seconds:g} s at {args.rate_hz:g} Hz)", flush=True)
    print(f"convert with: python -m bench convert --columns {columns(dof)} --distinct --out OUT.csv "
          f"{args.out}/recording_*.csv")
    return 0
