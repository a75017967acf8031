"""The URDF of the FPR: well-formed for any n, and its kinematic chain puts each quadrotor where the IGM does."""

import math
import xml.etree.ElementTree as ElementTree

import numpy as np
import pytest
from fpr_model.geometry import inverse_geometric_model, make_configuration
from fpr_model.parameters import default_parameters
from fpr_model.robot_description import robot_description
from fpr_model.rotations import quat_to_rotmat


def _rpy_matrix(roll, pitch, yaw):
    cr, sr, cp, sp, cy, sy = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw), \
        math.sin(yaw)
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx           # URDF: fixed-axis roll, pitch, yaw


def _floats(text):
    return [float(v) for v in text.split()]


@pytest.mark.parametrize("n", [3, 4, 6])
def test_urdf_chain_matches_the_inverse_geometric_model(n):
    params = default_parameters(n)
    root = ElementTree.fromstring(robot_description(params))
    links = {link.get("name") for link in root.iter("link")}
    assert links == {"platform", *[f"leg{k}" for k in range(1, n + 1)],
                     *[f"uav{k}/base_link" for k in range(1, n + 1)]}
    joints = {joint.get("name"): joint for joint in root.iter("joint")}
    assert len(joints) == 2 * n
    leg_angles = np.radians(np.linspace(40.0, 70.0, n))
    quat = np.array([0.96, 0.1, -0.2, 0.15])
    quat /= np.linalg.norm(quat)
    position = np.array([0.3, -0.2, 1.5])
    expected = inverse_geometric_model(params, make_configuration(position, quat, leg_angles))
    platform_rotation = quat_to_rotmat(quat)
    for k in range(1, n + 1):
        leg = joints[f"leg{k}_joint"]
        assert leg.get("type") == "revolute" and leg.find("axis").get("xyz") == "0 0 1"
        origin = leg.find("origin")
        theta = leg_angles[k - 1]
        leg_rotation = _rpy_matrix(*_floats(origin.get("rpy"))) @ _rpy_matrix(0.0, 0.0, theta)
        tip_in_leg = np.array(_floats(joints[f"uav{k}_joint"].find("origin").get("xyz")))
        assert joints[f"uav{k}_joint"].get("type") == "floating"
        tip = position + platform_rotation @ (np.array(_floats(origin.get("xyz"))) + leg_rotation @ tip_in_leg)
        np.testing.assert_allclose(tip, expected[k - 1], atol=1e-7)


def test_masses_are_the_model_masses():
    params = default_parameters(3)
    root = ElementTree.fromstring(robot_description(params))
    masses = {link.get("name"): float(link.find("inertial/mass").get("value")) for link in root.iter("link")}
    assert sum(masses.values()) == pytest.approx(params.total_mass, rel=1e-5)


def test_bad_arguments_are_refused():
    params = default_parameters(3)
    with pytest.raises(ValueError, match="prefix"):
        robot_description(params, prefix="a b")
    with pytest.raises(ValueError, match="leg_limits"):
        robot_description(params, leg_limits=(1.0, 0.5))
