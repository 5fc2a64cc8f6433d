"""The cases of the benchmark of undeclared effects
(:mod:`bench.studies.residual_acceptance`), in two sets.

* The **development set** (:data:`DEVELOPMENT`, data seeds
  :data:`DEVELOPMENT_SEEDS`): each case's effects at fixed values. These are
  the seeds and values the tests and the loop's rules may use, and have used.
* The **evaluation set** (:data:`EVALUATION`, data seeds
  :data:`EVALUATION_SEEDS`): the same cases, each effect's values drawn for
  each seed from the ranges each case states (:func:`effects`), so that no
  test and no choice of a rule has seen them. Nothing under ``tests/`` reads
  this set; a test checks that.

A case's effects are written as ``bench data --effects`` takes them.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass
from typing import Callable

import numpy as np

DEVELOPMENT, EVALUATION = "development", "evaluation"
SETS = (DEVELOPMENT, EVALUATION)

#: the development set's data seeds
DEVELOPMENT_SEEDS = (0, 1, 2)
#: the evaluation set's data seeds: the training samples' seed, the test samples' (plus 1000), the
#: noise's and the effect values' draw
EVALUATION_SEEDS = (7341, 8219, 9137)

#: the development set: each case's effects at fixed values
DEVELOPMENT_CASES = {
    "viscous_friction": ["viscous_friction=0.8,0.5"],
    "coulomb_friction": ["coulomb_friction=1.5,0.7"],
    # on one joint: with armatures on both joints the double pendulum's SysId form is not identifiable
    # from torques (six unknowns m1, m2, l1, l2, Ia1, Ia2 map to five coefficients of L)
    "armature": ["armature=0.3,0"],
    "spring": ["spring=2.0,1.0"],
    "offset": ["offset=0.5,-0.3"],
    "elbow_spring": ["coupled_spring=1-2:3.0"],
    "elbow_damper": ["coupled_damper=1-2:0.6"],
    "stribeck": ["stribeck_friction=1:1.0,2.0,0.5,0.3"],
    "coulomb_viscous": ["viscous_friction=0.8,0.5", "coulomb_friction=1.5,0.7"],
    # a low-pass filter's rounding of Coulomb friction, at a velocity well below the data's
    "smooth_coulomb": ["smooth_coulomb=1:1.5,0.02,0;2:0.7,0.02,0"],
    "offset_spring": ["offset_spring=2:2.0,0.3"],
    "tip_payload": ["tip_payload=0.5"],
    "gravity_tilt": ["gravity_tilt=0.05"],
    # a torque sensor that reads 4 % low on joint 2
    "torque_gain": ["torque_gain=1,0.96"],
    # cogging, or a drive's ripple: six periods a revolution of joint 1
    "periodic_torque": ["periodic_torque=1:0.3,6,0.5"],
    # a gear whose Coulomb level grows with its load: 10 % of joint 1's torque
    "load_friction": ["load_friction=0.1,0"],
    # chosen pairs: a sensor's gain and offset on one joint; a gain beside friction; ripple beside a spring;
    # a load-dependent Coulomb level beside a constant one
    "gain_offset": ["torque_gain=1,1.05", "offset=0,0.2"],
    "gain_viscous": ["torque_gain=1,0.96", "viscous_friction=0.8,0.5"],
    "periodic_spring": ["periodic_torque=1:0.3,6,0.5", "spring=0,1.0"],
    "load_coulomb": ["load_friction=0.1,0", "coulomb_friction=0.5,0"],
    "clean": [],
}


@dataclass(frozen=True)
class Drawn:
    """An evaluation case: its ranges as the page states them, and the draw."""

    ranges: str
    draw: Callable[[np.random.Generator], list[str]]


def _u(rng: np.random.Generator, low: float, high: float) -> str:
    return f"{rng.uniform(low, high):.4g}"


def _signed(rng: np.random.Generator, low: float, high: float) -> str:
    """A magnitude in ``[low, high]`` with a random sign."""
    return f"{rng.choice((-1.0, 1.0)) * rng.uniform(low, high):.4g}"


def _gain(rng: np.random.Generator) -> str:
    """A gain off 1 by 2 to 7 %, low or high."""
    return f"{1.0 + rng.choice((-1.0, 1.0)) * rng.uniform(0.02, 0.07):.4g}"


#: the evaluation set: each case's ranges; values uniform in them unless said otherwise
EVALUATION_CASES = {
    "viscous_friction": Drawn("b in [0.2, 1.2] on each joint",
                              lambda r: [f"viscous_friction={_u(r, 0.2, 1.2)},{_u(r, 0.2, 1.2)}"]),
    "coulomb_friction": Drawn("F_c in [0.3, 2.0] on each joint",
                              lambda r: [f"coulomb_friction={_u(r, 0.3, 2.0)},{_u(r, 0.3, 2.0)}"]),
    "armature": Drawn("I in [0.1, 0.5] on joint 1", lambda r: [f"armature={_u(r, 0.1, 0.5)},0"]),
    "spring": Drawn("k in [0.5, 3.0] on each joint", lambda r: [f"spring={_u(r, 0.5, 3.0)},{_u(r, 0.5, 3.0)}"]),
    "offset": Drawn("tau_0 of 0.1 to 0.8 in size, either sign, on each joint",
                    lambda r: [f"offset={_signed(r, 0.1, 0.8)},{_signed(r, 0.1, 0.8)}"]),
    "elbow_spring": Drawn("k in [1.0, 5.0] between joints 1 and 2", lambda r: [f"coupled_spring=1-2:{_u(r, 1.0, 5.0)}"]),
    "elbow_damper": Drawn("b in [0.2, 1.0] between joints 1 and 2", lambda r: [f"coupled_damper=1-2:{_u(r, 0.2, 1.0)}"]),
    "stribeck": Drawn("on joint 1: F_c in [0.5, 1.5], F_s = F_c plus [0.5, 1.5], v_s in [0.2, 0.8], b in [0.1, 0.6]",
                      lambda r: (lambda fc: [f"stribeck_friction=1:{fc:.4g},{fc + r.uniform(0.5, 1.5):.4g},"
                                             f"{_u(r, 0.2, 0.8)},{_u(r, 0.1, 0.6)}"])(r.uniform(0.5, 1.5))),
    "coulomb_viscous": Drawn("b in [0.2, 1.2] and F_c in [0.3, 2.0] on each joint",
                             lambda r: [f"viscous_friction={_u(r, 0.2, 1.2)},{_u(r, 0.2, 1.2)}",
                                        f"coulomb_friction={_u(r, 0.3, 2.0)},{_u(r, 0.3, 2.0)}"]),
    "smooth_coulomb": Drawn("F_c in [0.5, 2.0] and v_s in [0.01, 0.04] on each joint",
                            lambda r: [f"smooth_coulomb=1:{_u(r, 0.5, 2.0)},{_u(r, 0.01, 0.04)},0;"
                                       f"2:{_u(r, 0.5, 2.0)},{_u(r, 0.01, 0.04)},0"]),
    "offset_spring": Drawn("on joint 2: k in [1.0, 3.0], q0 of 0.1 to 0.5 in size, either sign",
                           lambda r: [f"offset_spring=2:{_u(r, 1.0, 3.0)},{_signed(r, 0.1, 0.5)}"]),
    "tip_payload": Drawn("m in [0.2, 1.0]", lambda r: [f"tip_payload={_u(r, 0.2, 1.0)}"]),
    "gravity_tilt": Drawn("an angle in [0.02, 0.1]", lambda r: [f"gravity_tilt={_u(r, 0.02, 0.1)}"]),
    "torque_gain": Drawn("joint 2's gain off 1 by 2 to 7 %, low or high", lambda r: [f"torque_gain=1,{_gain(r)}"]),
    "periodic_torque": Drawn("on joint 1: A in [0.15, 0.5], N a whole number from 3 to 8, phi of 0.3 to 2.8 in "
                             "size, either sign",
                             lambda r: [f"periodic_torque=1:{_u(r, 0.15, 0.5)},{int(r.integers(3, 9))},"
                                        f"{_signed(r, 0.3, 2.8)}"]),
    "load_friction": Drawn("mu in [0.05, 0.2] on joint 1", lambda r: [f"load_friction={_u(r, 0.05, 0.2)},0"]),
    "gain_offset": Drawn("joint 2's gain off 1 by 2 to 7 %, and its offset of 0.1 to 0.4 in size, either sign",
                         lambda r: [f"torque_gain=1,{_gain(r)}", f"offset=0,{_signed(r, 0.1, 0.4)}"]),
    "gain_viscous": Drawn("joint 2's gain off 1 by 2 to 7 %, and b in [0.2, 1.2] on each joint",
                          lambda r: [f"torque_gain=1,{_gain(r)}", f"viscous_friction={_u(r, 0.2, 1.2)},{_u(r, 0.2, 1.2)}"]),
    "periodic_spring": Drawn("the periodic torque's ranges on joint 1, and k in [0.5, 2.0] on joint 2",
                             lambda r: [f"periodic_torque=1:{_u(r, 0.15, 0.5)},{int(r.integers(3, 9))},"
                                        f"{_signed(r, 0.3, 2.8)}", f"spring=0,{_u(r, 0.5, 2.0)}"]),
    "load_coulomb": Drawn("on joint 1: mu in [0.05, 0.2] and F_c in [0.3, 1.0]",
                          lambda r: [f"load_friction={_u(r, 0.05, 0.2)},0", f"coulomb_friction={_u(r, 0.3, 1.0)},0"]),
    "clean": Drawn("no effect", lambda r: []),
}

#: the cases, in the page's order
CASES = tuple(DEVELOPMENT_CASES)


def effects(which: str, case: str, seed: int) -> list[str]:
    """The effects of ``case`` in the set ``which`` for data seed ``seed``: the
    development set's fixed values, or the evaluation set's draw for that seed
    and case (from its own stream, so that no case's draw depends on another's)."""
    if which == DEVELOPMENT:
        return list(DEVELOPMENT_CASES[case])
    rng = np.random.default_rng([seed, zlib.crc32(case.encode())])
    return EVALUATION_CASES[case].draw(rng)
