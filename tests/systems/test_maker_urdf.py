"""A URDF as robot makers ship it: joints named like the links they hold,
meshes that are not there, ``<transmission>`` and ``<gazebo>`` tags, and
continuous, floating and planar joints outside the arm's chain. The arm loads
by ``root``/``tip``, its torques are a hand-cleaned copy's, and it is fitted."""

from __future__ import annotations

import numpy as np
import pytest

from bench.core.data import DataError, generate, mse
from methods import METHODS
from systems.urdf_arm import chain, urdf_arm
from bench.core.budget import Budget


def _link(name: str, mass: float, mesh: bool) -> str:
    visual = f'<visual><geometry><mesh filename="package://maker/meshes/{name}.stl"/></geometry></visual>' if mesh else ""
    return (f'<link name="{name}"><inertial><origin xyz="0.01 0 0.1"/><mass value="{mass}"/>'
            f'<inertia ixx="0.01" ixy="0.001" ixz="0" iyy="0.02" iyz="0" izz="0.015"/></inertial>{visual}</link>')


def _joint(name: str, kind: str, parent: str, child: str, axis: str = "0 0 1") -> str:
    limit = {"revolute": '<limit lower="-2" upper="2" effort="10" velocity="2"/>',
             "continuous": '<limit effort="10" velocity="2"/>'}.get(kind, "")
    axis = f'<axis xyz="{axis}"/>' if kind not in ("fixed", "floating") else ""
    return (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="0 0.05 0.2" rpy="0.1 0 0"/>{axis}{limit}</joint>')


def maker_urdf(quirks: bool) -> str:
    """A three-joint arm (``base`` to ``hand``) with a finger, a camera and a cart beside it; with ``quirks`` as a
    maker ships it, without them as one would clean it by hand (joints renamed, the joints outside the chain
    made revolute or fixed, no meshes, transmissions or Gazebo tags)."""
    name = (lambda quirky, clean: quirky) if quirks else (lambda quirky, clean: clean)
    parts = ['<?xml version="1.0"?>', '<robot name="maker">']
    parts += [_link(n, m, quirks) for n, m in (("base", 2.0), ("link1", 1.2), ("link2", 1.0), ("link3", 0.8),
                                                ("hand", 0.5), ("finger", 0.1), ("camera", 0.2), ("cart", 0.3))]
    parts += [_joint("j1", "revolute", "base", "link1"),
              _joint(name("link2", "j2"), "revolute", "link1", "link2", "0 1 0"),  # a movable joint named like a link
              _joint("j3", "revolute", "link2", "link3", "1 0 0"),
              _joint(name("hand", "hand_joint"), "fixed", "link3", "hand"),
              _joint(name("finger", "finger_joint"), name("continuous", "revolute"), "hand", "finger"),
              _joint(name("camera", "camera_joint"), name("floating", "fixed"), "base", "camera"),
              _joint(name("cart", "cart_joint"), name("planar", "fixed"), "base", "cart")]
    if quirks:
        parts += ['<transmission name="t1"><type>transmission_interface/SimpleTransmission</type>'
                  '<joint name="j1"><hardwareInterface>EffortJointInterface</hardwareInterface></joint>'
                  '<actuator name="m1"><mechanicalReduction>100</mechanicalReduction></actuator></transmission>',
                  '<gazebo reference="link1"><material>Gazebo/Grey</material></gazebo>',
                  '<gazebo><plugin name="control" filename="libcontrol.so"/></gazebo>']
    return "\n".join(parts + ["</robot>"])


@pytest.fixture(scope="module")
def arms(tmp_path_factory):
    folder = tmp_path_factory.mktemp("maker")
    out = {}
    for quirks in (True, False):
        path = folder / f"{'maker' if quirks else 'cleaned'}.urdf"
        path.write_text(maker_urdf(quirks))
        picked, locked = chain(path, root="base", tip="hand")
        out[quirks] = (picked, locked, urdf_arm(path, locked=locked)())
    return out


def test_a_makers_urdf_loads_by_root_and_tip_with_its_own_joint_names(arms):
    picked, locked, arm = arms[True]
    assert picked == ["j1", "link2", "j3"] and sorted(locked) == ["camera", "cart", "finger"]
    assert arm.coordinates == ("j1", "link2", "j3")
    assert arms[False][2].coordinates == ("j1", "j2", "j3")


def test_its_torques_are_the_hand_cleaned_copys(arms):
    rng = np.random.default_rng(0)
    q, qd, qdd = rng.uniform(-1.5, 1.5, (3, 200, 3))
    maker, cleaned = arms[True][2].inverse_dynamics(q, qd, qdd), arms[False][2].inverse_dynamics(q, qd, qdd)
    assert np.abs(cleaned).max() > 1.0
    np.testing.assert_allclose(maker, cleaned, rtol=0, atol=1e-10 * np.abs(cleaned).max())


def test_a_makers_arm_is_fitted(arms):
    arm = arms[True][2]
    train, test = generate(arm, 400, 0), generate(arm, 200, 1)
    model = METHODS["sysid"](**METHODS["sysid"].configuration("standard")).fit(train, "indirect", 0, budget=Budget(steps=1),
                                                                              system=arm)
    assert mse(model.predict_torque(test), test.tau) < 1e-8 * float(np.mean(test.tau ** 2))


def test_the_joints_of_a_makers_urdf_are_found_by_their_names(tmp_path):
    path = tmp_path / "maker.urdf"
    path.write_text(maker_urdf(True))
    assert chain(path, joints=["j1", "link2", "j3"]) == (["j1", "link2", "j3"], ["camera", "cart", "finger"])
    with pytest.raises(DataError, match="no joint"):
        chain(path, joints=["j1", "link2__joint"])  # the engine's name is not the URDF's


def test_a_urdf_that_does_not_parse_is_refused_in_one_line(tmp_path):
    path = tmp_path / "broken.urdf"
    path.write_text(maker_urdf(True).replace("</robot>", ""))
    with pytest.raises(DataError, match="does not parse") as caught:
        chain(path, root="base", tip="hand")
    assert len(str(caught.value).splitlines()) == 1
