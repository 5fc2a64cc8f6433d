"""Robot arms from their URDF files, with Pinocchio as the dynamics engine.

A 6- or 7-joint arm's Lagrangian is too large to write out, so these systems
take their dynamics from Pinocchio (Carpentier et al., "The Pinocchio C++
library", SII 2019), the rigid-body library of the robotics field:

* ``tau`` from the recursive Newton–Euler algorithm (``pin.rnea``);
* ``L = T - V`` from its kinetic and potential energies, for the direct
  experiment;
* the true motion of a rollout from its forward dynamics (``pin.aba``);
* for SysId, the torque and energy regressors linear in the 10 inertial
  parameters of each link (``m, m c_x, m c_y, m c_z, I_xx, I_xy, I_yy,
  I_xz, I_yz, I_zz`` about the joint frame), :class:`~bench.physics.system.LinearForm`.

No closed-form Lagrangian exists, so no learned equation can be judged
exact (the tables say "not judged"). Pinocchio is independent of the suite:
``tests/systems/test_urdf.py`` checks the suite's own Euler–Lagrange
transform against its RNEA on the n-link pendulum built in both.

Sampling domain
---------------
Each joint's angle is drawn uniformly inside its limits, less 5 % of the
range at each end; velocities from ``U(-v/2, v/2)`` with ``v`` the joint's
velocity limit; accelerations from ``U(-pi/2, pi/2)`` rad/s^2, the paper's
range. Gravity is ``-g`` along the base's z axis.

Arms
----
* ``panda``: Franka Emika Panda, the 7 arm joints, the two finger joints
  locked (their links ride on link 7);
* ``ur5``: Universal Robots UR5, 6 joints.

Their URDF files come unchanged from ``example-robot-data`` 6.0.0 (the
Panda's from franka_ros' ``franka_description``, Apache-2.0, see
``data/LICENSE.panda``; the UR5's from ROS-Industrial's ``ur_description``,
BSD, packaged by example-robot-data, see ``data/LICENSE.ur5``), gzipped in
``systems/data`` without their meshes, which dynamics does not need.

Another arm
-----------
``python -m bench run --systems urdf:PATH`` loads any URDF (every movable
joint a coordinate); a plugin file registers one with locked joints in one
line::

    SYSTEMS.add("my_arm", "simulated", "arm")(urdf_arm("my_arm.urdf", locked=("gripper_joint",)))
"""

from __future__ import annotations

import functools
import gzip
import hashlib
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar, Sequence

import numpy as np
import torch

from bench.core.data import DataError
from bench.physics.system import Domain, LinearForm
from systems.base import SYSTEMS, System, register_file

DATA_DIR = Path(__file__).parent / "data"
#: each joint's angle stays this fraction of its range inside its limits
LIMIT_MARGIN = 0.05
#: accelerations are drawn from U(-QDD_HALF_WIDTH, QDD_HALF_WIDTH)
QDD_HALF_WIDTH = math.pi / 2
#: the names of the 10 inertial parameters of a link, in Pinocchio's order
INERTIAL = ("m", "mcx", "mcy", "mcz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")


def _pinocchio():
    import pinocchio  # the engine: imported where an arm is built (the shipped arms are built when systems is imported)

    return pinocchio


@functools.lru_cache(maxsize=8)
def _engines(model, parameters: bytes) -> tuple[tuple, tuple]:
    """``(model, data)`` of ``model`` with each link's inertial ``parameters``
    (float64 bytes, 10 a link) plus a point mass at its joint, and of
    ``model`` with those point masses alone (:meth:`UrdfArm.mass_and_bias_at`);
    kept for the last few parameter vectors, since a rollout asks at each step."""
    pin = _pinocchio()
    pi = np.frombuffer(parameters, dtype=np.float64).reshape(-1, 10)
    extra = 1.0 + float(np.max(np.abs(pi[:, 0])))  # every link's mass plus this is at least 1
    out = []
    for own in (pi, np.zeros_like(pi)):
        m = model.copy()
        m.armature[:] = 0.0  # the regressor has no rotor inertia
        for i, p in enumerate(own, start=1):
            m.inertias[i] = pin.Inertia.FromDynamicParameters(p + np.eye(10)[0] * extra)
        out.append((m, m.createData()))
    return out[0], out[1]


#: what a joint that shares its name with a link is called inside the engine
JOINT_SUFFIX = "__joint"


@functools.lru_cache(maxsize=16)
def _distinct(text: str) -> tuple[str, tuple[tuple[str, str], ...]]:
    """The URDF ``text`` with every joint that shares its name with a link renamed ``NAME__joint`` (and the
    mimic tags that name it), and the renames, original first; ``text`` itself where no name is shared.

    Makers' URDFs often name a fixed joint like the link it holds (``left_hand``). Pinocchio gives each a
    frame of that name, and its ``buildReducedModel`` then stops at a name that matches two frames; the
    engine sees distinct names, and the suite's joints keep the URDF's names (:func:`_engine_name`,
    :func:`_urdf_name`)."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise DataError(f"not a URDF (its XML does not parse: {exc})") from None
    links = {link.get("name") for link in root.findall("link")}
    taken = links | {joint.get("name") for joint in root.findall("joint")}
    renames = {}
    for joint in root.findall("joint"):
        name = joint.get("name")
        if name in links:
            new = name + JOINT_SUFFIX
            while new in taken:
                new += "_"
            taken.add(new)
            renames[name] = new
            joint.set("name", new)
    if not renames:
        return text, ()
    for mimic in root.iter("mimic"):
        if mimic.get("joint") in renames:
            mimic.set("joint", renames[mimic.get("joint")])
    return ET.tostring(root, encoding="unicode"), tuple(renames.items())


def _engine_name(text: str, joint: str) -> str:
    """The engine's name of the URDF's joint ``joint`` (:func:`_distinct`)."""
    return dict(_distinct(text)[1]).get(joint, joint)


def _urdf_name(text: str, joint: str) -> str:
    """The URDF's name of the engine's joint ``joint`` (:func:`_distinct`)."""
    return {new: old for old, new in _distinct(text)[1]}.get(joint, joint)


def _full_model(text: str):
    """The Pinocchio model of a URDF text, every joint in it, its joints named as :func:`_distinct` names them;
    a :class:`DataError` where Pinocchio cannot read it."""
    pin = _pinocchio()
    try:
        return pin.buildModelFromXML(_distinct(text)[0])
    except (RuntimeError, ValueError) as exc:
        raise DataError(f"not a URDF Pinocchio can read: {str(exc).strip().splitlines()[0]}") from None


@functools.lru_cache(maxsize=16)
def _model(text: str, locked: tuple[str, ...], g: float, locked_at: tuple[tuple[str, float], ...] = ()):
    """The Pinocchio model of a URDF text, with ``locked`` joints fixed: at their
    neutral position, or at the position ``locked_at`` gives (Pinocchio's
    ``buildReducedModel``)."""
    pin = _pinocchio()
    model = _full_model(text)
    if locked:
        named = {_urdf_name(text, n) for n in model.names}
        unknown = [j for j in locked if j not in named]
        if unknown:
            raise DataError(f"no joint(s) {', '.join(unknown)} in the URDF")
        reference = pin.neutral(model)
        for joint, value in locked_at:
            if joint not in locked:
                raise DataError(f"locked_at names {joint!r}, which is no locked joint of the URDF")
            reference[model.joints[model.getJointId(_engine_name(text, joint))].idx_q] = value
        model = pin.buildReducedModel(model, [model.getJointId(_engine_name(text, j)) for j in locked], reference)
    if model.nq != model.nv:
        raise DataError("the URDF has joints with more than one coordinate (continuous or floating); "
                        "only revolute and prismatic joints are supported")
    model.gravity.linear = np.array([0.0, 0.0, -g])
    return model


def _read(path: Path) -> str:
    opener = gzip.open if path.suffix == ".gz" else open
    try:
        with opener(path, "rt") as f:
            return f.read()
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: cannot read the URDF ({exc})") from None


@dataclass(frozen=True)
class ArmParams:
    """Gravity (m/s^2); the inertial parameters are the URDF's."""

    g: float = 9.81


class UrdfArm(System):
    """A robot arm whose dynamics Pinocchio computes from its URDF; see the module docstring."""

    symbolic = False
    Params = ArmParams
    urdf_text: ClassVar[str] = ""
    urdf_source: ClassVar[str] = ""
    locked_joints: ClassVar[tuple[str, ...]] = ()
    #: the positions the locked joints are held at, where not their neutral one: ``((joint, value), ...)``
    locked_at: ClassVar[tuple[tuple[str, float], ...]] = ()

    @classmethod
    def source_files(cls) -> list[str]:
        return [cls.urdf_source]

    @property
    def model(self):
        return _model(self.urdf_text, self.locked_joints, self.params.g, self.locked_at)

    @functools.cached_property
    def _data(self):
        return self.model.createData()

    def lagrangian_expr(self, q, qd, p):
        raise NotImplementedError(f"{self.name}: an arm from a URDF has no closed-form Lagrangian")

    @property
    def lagrangian_sympy(self):
        return None

    # -- the engine ------------------------------------------------------------------
    def _each(self, fn, *arrays) -> np.ndarray:
        arrays = [np.ascontiguousarray(np.asarray(a, dtype=np.float64)) for a in arrays]
        return np.stack([np.asarray(fn(*row), dtype=np.float64) for row in zip(*arrays)]) if len(arrays[0]) else \
            np.zeros((0,))

    def energies(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """``L = T - V`` at each state, shape ``(n,)``."""
        pin, model, data = _pinocchio(), self.model, self._data

        def one(qi, vi):
            return pin.computeKineticEnergy(model, data, qi, vi) - pin.computePotentialEnergy(model, data, qi)

        return self._each(one, q, qd)

    def inverse_dynamics(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """Pinocchio's RNEA at each state, shape ``(n, dof)``."""
        pin, model, data = _pinocchio(), self.model, self._data
        return self._each(lambda a, b, c: pin.rnea(model, data, a, b, c), q, qd, qdd).reshape(len(q), self.dof)

    def forward_dynamics(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """Pinocchio's ABA, unforced, at each state: shape ``(n, dof)``."""
        pin, model, data = _pinocchio(), self.model, self._data
        tau = np.zeros_like(q)
        return self._each(lambda a, b, c: pin.aba(model, data, a, b, c), q, qd, tau).reshape(len(q), self.dof)

    def lagrangian(self, q: torch.Tensor, qd: torch.Tensor) -> torch.Tensor:
        """``T - V`` from Pinocchio (values only: the engine gives no gradient)."""
        return torch.from_numpy(self.energies(q.detach().double().numpy(), qd.detach().double().numpy())).to(q.dtype)

    def torque(self, q: torch.Tensor, qd: torch.Tensor, qdd: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        a, b, c = (x.detach().double().numpy() for x in (q, qd, qdd))
        tau = self.inverse_dynamics(a, b, c)
        extra = self.nonconservative_torque(q, qd, qdd)
        tau = torch.from_numpy(tau).to(q.dtype)
        return (tau if extra is None else tau + extra), self.lagrangian(q, qd)

    # -- SysId ------------------------------------------------------------------------
    def inertial_parameters(self) -> np.ndarray:
        """The URDF's 10 inertial parameters of each moving link, stacked (Pinocchio's order, :data:`INERTIAL`)."""
        model = self.model
        return np.concatenate([model.inertias[i].toDynamicParameters() for i in range(1, model.njoints)])

    def linear_form(self) -> LinearForm:
        pin, model, data = _pinocchio(), self.model, self._data
        dof = self.dof

        def torque_regressor(q, qd, qdd):
            Y = self._each(lambda a, b, c: pin.computeJointTorqueRegressor(model, data, a, b, c), q, qd, qdd)
            return Y.reshape(len(q), dof, 10 * dof)

        def lagrangian_regressor(q, qd):
            def one(a, b):
                return pin.computeKineticEnergyRegressor(model, data, a, b) - pin.computePotentialEnergyRegressor(model, data, a)

            return self._each(one, q, qd).reshape(len(q), 10 * dof)

        names = tuple(f"{p}_{i}" for i in range(1, dof + 1) for p in INERTIAL)
        urdf = tuple(self.inertial_parameters())
        return LinearForm(names, dof, torque_regressor, lagrangian_regressor, urdf, bodies=dof, prior=urdf,
                          dynamics=self.mass_and_bias_at)

    def mass_and_bias_at(self, parameters: np.ndarray, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``M`` and ``c`` (``tau = M qdd + c``, gravity included) of the arm
        whose links have the inertial ``parameters`` (:meth:`inertial_parameters`'
        layout; the torque regressor's ``Y pi``), by Pinocchio's CRBA and RNEA:
        four passes a state (two models, below) where the regressor at ``dof + 1``
        accelerations takes ``dof + 1`` passes of a larger algorithm. The parameters need not
        be a rigid body's (a fit's base parameters, zero elsewhere), and the
        engine keeps a link as mass, centre and inertia, so each link is given
        one more point mass at its joint, in this model and in a second one
        that has it alone; ``M`` and ``c`` are linear in the parameters, and
        the second model's are subtracted."""
        pin = _pinocchio()
        loaded, alone = _engines(self.model, np.asarray(parameters, dtype=np.float64).tobytes())
        out_M, out_c = np.zeros((len(q), self.dof, self.dof)), np.zeros((len(q), self.dof))
        for k, (qk, vk) in enumerate(zip(np.asarray(q, dtype=np.float64), np.asarray(qd, dtype=np.float64))):
            out_M[k] = pin.crba(*loaded, qk) - pin.crba(*alone, qk)
            out_c[k] = pin.nonLinearEffects(*loaded, qk, vk) - pin.nonLinearEffects(*alone, qk, vk)
        return np.triu(out_M) + np.swapaxes(np.triu(out_M, 1), 1, 2), out_c  # the upper triangle is CRBA's

    # -- description ----------------------------------------------------------------
    def scaled_domain(self, half_width: float) -> Domain:
        """U(-w, w) for velocities and accelerations; angles stay inside their limits."""
        w = float(half_width)
        lo, hi = self.default_domain.bounds("q", self.dof)
        q = tuple((max(a, -w), min(b, w)) if kind == "angle" and max(a, -w) < min(b, w) else (a, b)
                  for kind, a, b in zip(self.kinds, lo, hi))
        return Domain(q=q, qd=(-w, w), qdd=(-w, w))

    def describe(self) -> dict:
        return {**super().describe(), "urdf_sha256": hashlib.sha256(self.urdf_text.encode()).hexdigest(),
                "locked_joints": list(self.locked_joints)}


def physically_consistent(parameters: np.ndarray, tol: float = 1e-12) -> list[str]:
    """What is wrong with stacked 10-parameter links (:data:`INERTIAL`): a
    non-positive mass, or a rotational inertia about the centre of mass that
    is not positive definite or breaks the triangle inequalities. Empty when
    every link is physically consistent."""
    pin = _pinocchio()
    problems = []
    for i, p in enumerate(np.asarray(parameters, dtype=np.float64).reshape(-1, 10), 1):
        if not p[0] > 0:
            problems.append(f"link {i}: mass {p[0]:g} is not positive")
            continue
        inertia = pin.Inertia.FromDynamicParameters(p).inertia  # about the centre of mass
        eig = np.linalg.eigvalsh(inertia)
        if eig[0] <= -tol * max(eig[-1], 1.0):
            problems.append(f"link {i}: inertia about the centre of mass is not positive definite (eigenvalues {eig})")
        elif any(eig[k] > eig[(k + 1) % 3] + eig[(k + 2) % 3] + tol for k in range(3)):
            problems.append(f"link {i}: principal inertias {eig} break the triangle inequality")
    return problems


def urdf_arm(urdf: str | Path, *, locked: Sequence[str] = (), name: str | None = None,
             locked_at: Sequence[tuple[str, float]] = ()) -> type[UrdfArm]:
    """The System class of the arm in the URDF file ``urdf`` (optionally
    gzipped), with the joints ``locked`` fixed at their neutral position or at
    the position ``locked_at`` gives."""
    path = Path(urdf)
    text = _read(path)
    locked, locked_at = tuple(locked), tuple((str(j), float(v)) for j, v in locked_at)
    model = _model(text, locked, ArmParams.g, locked_at)
    joints = [model.joints[i] for i in range(1, model.njoints)]
    kinds = tuple("linear" if "P" in j.shortname().replace("JointModel", "")[:1] else "angle" for j in joints)
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(hi > lo)):
        raise DataError(f"{path}: every joint needs finite position limits with lower < upper")
    margin = LIMIT_MARGIN * (hi - lo)
    velocity = 0.5 * np.asarray(model.velocityLimit, dtype=np.float64)
    if not np.all(velocity > 0):
        raise DataError(f"{path}: every joint needs a positive velocity limit")
    domain = Domain(
        q=tuple((float(a + m), float(b - m)) for a, b, m in zip(lo, hi, margin)),
        qd=tuple((-float(v), float(v)) for v in velocity),
        qdd=(-QDD_HALF_WIDTH, QDD_HALF_WIDTH),
    )
    cls = type(f"Urdf_{re.sub(r'[^0-9a-zA-Z]', '_', name or path.stem)}", (UrdfArm,), {
        "coordinates": tuple(_urdf_name(text, model.names[i]) for i in range(1, model.njoints)),
        "coordinate_kinds": kinds,
        "default_domain": domain,
        "position_limits": tuple((float(a), float(b)) for a, b in zip(lo, hi)),
        "urdf_text": text,
        "urdf_source": str(path),
        "locked_joints": locked,
        "locked_at": locked_at,
        "__module__": __name__,
    })
    return cls


def chain(urdf: str | Path, root: str | None = None, tip: str | None = None,
          joints: Sequence[str] | None = None) -> tuple[list[str], list[str]]:
    """The arm within a larger robot's URDF: the movable joints from the link
    ``root`` to the link ``tip``, root first, or the ``joints`` named (checked
    to form one chain, each the parent of the next); and every other movable
    joint, to lock. A :class:`DataError` naming the file and the link or joint
    where a link or joint is unknown, or the joints do not form a chain."""
    path = Path(urdf)
    text = _read(path)
    model = _full_model(text)
    name = [_urdf_name(text, n) for n in model.names]  # each joint's URDF name, by the engine's index
    movable = name[1:]
    body = _pinocchio().FrameType.BODY
    if joints is not None:
        unknown = [j for j in joints if j not in movable]
        if unknown:
            raise DataError(f"{path}: no joint(s) {', '.join(unknown)} (its joints: {', '.join(movable)})")
        ids = [model.getJointId(_engine_name(text, j)) for j in joints]
        for parent, child in zip(ids, ids[1:]):
            if model.parents[child] != parent:
                raise DataError(f"{path}: the joints do not form a chain: {name[child]} does not follow "
                                f"{name[parent]} (its parent joint is {name[model.parents[child]]})")
        picked = list(joints)
    else:
        def frame_of(link: str, key: str) -> int:
            if not model.existFrame(link, body):
                raise DataError(f"{path}: no link {link!r} ({key})")
            return int(model.getFrameId(link, body))

        top = int(model.frames[frame_of(root, "root")].parentJoint) if root is not None else 0
        bottom = int(model.frames[frame_of(tip, "tip")].parentJoint) if tip is not None else None
        if bottom is None:
            raise DataError(f"{path}: name the arm's tip link (tip) beside its root, or its joints")
        if root is not None:  # the root link on the links' path from the tip to the base
            frame, target = frame_of(tip, "tip"), frame_of(root, "root")
            while frame != target:
                if frame == 0:
                    raise DataError(f"{path}: the links {root!r} (root) and {tip!r} (tip) do not form a chain: "
                                    f"{root!r} is not on the path from the robot's base to {tip!r}")
                frame = int(model.frames[frame].parentFrame)
        picked, at = [], bottom
        while at != top:
            picked.append(name[at])
            at = model.parents[at]
        picked.reverse()
    return picked, [j for j in movable if j not in picked]


def register_urdf(spec: str) -> str:
    """Register the arm of ``urdf:PATH`` (every movable joint a coordinate)
    under ``urdf_<file stem>`` (:func:`systems.base.register_file`); returns that name."""
    def build(path: Path, name: str) -> type[UrdfArm]:
        if not path.is_file():
            raise DataError(f"{path}: no such URDF file")
        return urdf_arm(path)

    return register_file("urdf", spec.split(":", 1)[1], ("simulated", "arm", "urdf"), build,
                         lambda cls: getattr(cls, "urdf_source", None))


@SYSTEMS.add("panda", "simulated", "arm")
class Panda(urdf_arm(DATA_DIR / "panda.urdf.gz", locked=("panda_finger_joint1", "panda_finger_joint2"), name="panda")):
    """Franka Emika Panda, 7 joints, fingers locked."""

    title = "the Panda arm"
    summary = ("Franka Emika Panda, 7 joints (fingers locked), from its URDF through Pinocchio: τ by RNEA, L = T − V "
               "from its energies, rollouts against its forward dynamics; q inside each joint's limits (less 5 % of "
               "the range at each end), q̇ in ±½ the velocity limits, q̈ in ±π/2; no closed-form Lagrangian, so the "
               "Exact row reads \"not judged\"")


@SYSTEMS.add("ur5", "simulated", "arm")
class UR5(urdf_arm(DATA_DIR / "ur5_robot.urdf.gz", name="ur5")):
    """Universal Robots UR5, 6 joints."""

    title = "the UR5 arm"
    summary = "Universal Robots UR5, 6 joints, from its URDF through Pinocchio as `panda` is"
