"""A large geared 6-joint industrial arm, for the selection benchmark's geared cases
(:mod:`bench.studies.selection_benchmark`, arm ``geared``).

Its rigid bodies are the UR5's (``systems/data/ur5_robot.urdf.gz``, BSD) scaled to an arm of about 2 m
reach and 200 kg: every length :data:`LENGTH` times, every mass :data:`MASS` times, each inertia
``MASS * LENGTH**2`` times, and joint ranges and speeds an industrial arm has (:data:`LIMITS`). What its
drives add is what identifies such an arm (Khalil & Dombre 2002; Swevers et al. 2007): the rotors' inertia
through gears of ratio 150 to 270 (:data:`ROTOR_INERTIA`, ``N^2`` times the rotor's), heavy viscous and
Coulomb friction, the gears' load-dependent friction, and a counterbalance on the shoulder that is not a
rigid body's torque (a spring and a torque of period half a turn, :func:`effects`); the torque is the
motor's times the gear ratio, with the noise of a motor current (:data:`NOISE`). :func:`write_urdf` writes the arm's URDF
(``systems/data/geared_arm.urdf.gz``, which ``tests/studies/test_geared_arm.py`` checks against it).
"""

from __future__ import annotations

import gzip
import re
from pathlib import Path

import numpy as np

#: the scale of every length and every mass against the UR5's
LENGTH, MASS = 2.5, 12.0
#: each joint's range (rad) and speed limit (rad/s), an industrial arm's
LIMITS = ((-2.96, 2.96, 2.0), (-2.4, 0.6, 2.0), (-2.2, 2.2, 2.0), (-3.0, 3.0, 3.0), (-2.0, 2.0, 3.0),
          (-3.0, 3.0, 3.5))
#: each joint's rotor inertia seen at the joint (kg m^2), ``N^2 J_rotor`` with ``N`` from 270 to 150
ROTOR_INERTIA = (9.0, 9.0, 4.0, 1.2, 1.0, 0.5)
#: the torque noise, a fraction of each joint's torque standard deviation: a motor current's
NOISE = 0.05
#: the URDF the arm is declared by
URDF = Path(__file__).resolve().parents[2] / "systems" / "data" / "geared_arm.urdf.gz"
SOURCE = URDF.with_name("ur5_robot.urdf.gz")

_NUMBER = r"-?[0-9.eE+-]+"


def _scaled(match: re.Match, factor: float) -> str:
    return f'{match.group(1)}="{float(match.group(2)) * factor:.12g}"'


def urdf_text() -> str:
    """The arm's URDF: the UR5's, scaled (lengths, masses, inertias) and limited (:data:`LIMITS`)."""
    text = gzip.decompress(SOURCE.read_bytes()).decode()
    text = re.sub(r"<visual>.*?</visual>|<collision>.*?</collision>", "", text, flags=re.S)
    text = re.sub(r"<mesh [^>]*/>", "", text)
    text = re.sub(r'(<mass value)="(' + _NUMBER + ')"', lambda m: _scaled(m, MASS), text)
    text = re.sub(r'(i[xyz]{2})="(' + _NUMBER + ')"', lambda m: _scaled(m, MASS * LENGTH ** 2), text)
    text = re.sub(r'xyz="(' + _NUMBER + ') (' + _NUMBER + ') (' + _NUMBER + ')"',
                  lambda m: 'xyz="' + " ".join(f"{float(v) * LENGTH:.12g}" for v in m.groups()) + '"', text)
    joints = iter(LIMITS)

    def limit(m: re.Match) -> str:
        lo, hi, speed = next(joints)
        return f'<limit effort="5000.0" lower="{lo}" upper="{hi}" velocity="{speed}"/>'

    text = re.sub(r"<limit [^>]*/>", limit, text, count=len(LIMITS))
    text = text.replace('<robot name="ur5"', '<robot name="geared_arm"')
    header = ("<!-- A large geared 6-joint arm: the UR5 of ur_description (BSD, LICENSE.ur5) with every length "
              f"{LENGTH:g} times and every mass {MASS:g} times its own, the inertias scaled with them and the "
              "joints' ranges and speeds an industrial arm's; written by bench/studies/geared_arm.py -->\n")
    return text.replace("?>\n", "?>\n" + header, 1)


def write_urdf(path: Path = URDF) -> Path:
    """Write :func:`urdf_text`, gzipped without a time stamp, to ``path``."""
    path.write_bytes(gzip.compress(urdf_text().encode(), mtime=0))
    return path


def _values(rng: np.random.Generator, base: tuple[float, ...], spread: float = 0.2) -> str:
    return ",".join(f"{b * rng.uniform(1 - spread, 1 + spread):.4g}" for b in base)


def effects(dof: int, rng: np.random.Generator) -> list[str]:
    """What the drives add, drawn about a geared arm's values: rotor inertia (:data:`ROTOR_INERTIA`), viscous
    friction of 40 to 150 N m s and Coulomb friction of 15 to 120 N m on the large joints, less on the wrist,
    a gear's load-dependent friction (a Coulomb level of 5 to 10 % of the torque it carries, which the field's
    standard model lacks), and the shoulder's counterbalance, a spring and a torque of period half a turn of
    400 to 700 N m."""
    assert dof == len(ROTOR_INERTIA)
    return [f"armature={_values(rng, ROTOR_INERTIA)}",
            f"viscous_friction={_values(rng, (150.0, 150.0, 80.0, 40.0, 30.0, 20.0))}",
            f"coulomb_friction={_values(rng, (120.0, 120.0, 60.0, 25.0, 20.0, 15.0))}",
            f"load_friction={_values(rng, (0.1, 0.1, 0.08, 0.06, 0.06, 0.05))}",
            f"spring=0,{rng.uniform(300, 500):.4g},0,0,0,0",
            f"periodic_torque=2:{rng.uniform(400, 700):.4g},2,{rng.uniform(-1, 1):.3g}"]
