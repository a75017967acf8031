"""The FPR as a URDF robot description, generated from its parameters for any n (ROS-free).

Kinematic tree (frame names after a ``prefix``, default none: the names of the TF tree fpr_sim publishes, next to
the frames already on the topics, e.g. ``uav<i>/camera_optical`` of the images):

- ``{prefix}platform`` — the platform frame Fp at P (root link; ``world -> {prefix}platform`` is the platform's
  pose, published on /tf, not part of the URDF);
- ``{prefix}leg{i}`` — the leg frame F_li at the revolute-joint centre A_i (i = 1..n), joint ``{prefix}leg{i}_joint``
  (revolute, axis z of F_li, angle θ_i): origin ``A_i = r [cos α_i, sin α_i, 0]`` in Fp, ``pR_li = Rz(α_i) Rx(−π/2)
  Rz(θ_i)`` (2.7)-(2.8) (α_i of (2.7) with erratum E1), i.e. URDF ``rpy = (−π/2, 0, α_i)`` then the joint's Rz(θ_i);
  limits = the legs' mechanical stops;
- ``{prefix}uav{i}/base_link`` — quadrotor i's body frame (FLU) at its CoM B_i = A_i + l·x_li (2.5)-(2.9) (the
  spherical joint's offset d is neglected, as in the model, §2.3.3), joint ``{prefix}uav{i}_joint``: ``floating``
  from the leg tip (URDF has no spherical joint; its orientation comes from /tf).

Geometry is primitive shapes at the prototype's sizes (thesis Appendix B: platform disc of radius r, carbon legs of
length l, 34 cm quadrotor frames with 8" propellers): enough for RViz / Foxglove to draw the robot; inertial tags
carry the model's masses and inertias (Table B.1), so the description is also a faithful mass model.
"""

from __future__ import annotations

import math
from xml.sax.saxutils import quoteattr

import numpy as np

from fpr_model.geometry import leg_anchor_angles
from fpr_model.parameters import FprParameters

__all__ = ["robot_description", "leg_joint_origin"]

#: quadrotor drawing sizes [m]: frame diagonal 0.34 (thesis 34 cm frame), rotor radius 0.1016 (8" propellers)
UAV_ARM = 0.17
ROTOR_RADIUS = 0.1016


def leg_joint_origin(params: FprParameters, i: int) -> tuple[np.ndarray, tuple[float, float, float]]:
    """Origin of leg joint i (0-based) in Fp: position A_i [m] and URDF rpy [rad] of Rz(α_i) Rx(−π/2) (2.7)-(2.8)."""
    alpha = float(leg_anchor_angles(params.n)[i])
    anchor = params.platform_radius * np.array([math.cos(alpha), math.sin(alpha), 0.0])
    return anchor, (-math.pi / 2.0, 0.0, alpha)


def _vec(values) -> str:
    return " ".join(f"{float(v):.9g}" for v in values)


def _inertial(mass: float, com, inertia: np.ndarray) -> str:
    inertia = np.asarray(inertia, dtype=float)
    return (f'    <inertial>\n      <origin xyz="{_vec(com)}" rpy="0 0 0"/>\n      <mass value="{mass:.6g}"/>\n'
            f'      <inertia ixx="{inertia[0, 0]:.6g}" ixy="{inertia[0, 1]:.6g}" ixz="{inertia[0, 2]:.6g}" '
            f'iyy="{inertia[1, 1]:.6g}" iyz="{inertia[1, 2]:.6g}" izz="{inertia[2, 2]:.6g}"/>\n    </inertial>\n')


def _visual(geometry: str, xyz=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0), material: str = "grey") -> str:
    return (f'    <visual>\n      <origin xyz="{_vec(xyz)}" rpy="{_vec(rpy)}"/>\n'
            f'      <geometry>{geometry}</geometry>\n      <material name="{material}"/>\n    </visual>\n')


def robot_description(params: FprParameters, prefix: str = "", name: str = "fpr",
                      leg_limits: tuple[float, float] = (math.radians(10.0), math.radians(92.0)),
                      uav_inertia=(0.011, 0.011, 0.021)) -> str:
    """URDF (XML text) of the FPR ``params`` (see the module doc for frames and joints). ``leg_limits`` [rad]: the
    revolute joints' limits (default: fpr_sim's joint stops); ``uav_inertia`` [kg m²]: diagonal quadrotor inertia
    (FLU; not in Table B.1, fpr_sim's default)."""
    if not isinstance(prefix, str) or any(c.isspace() for c in prefix):
        raise ValueError(f"prefix: expected a frame prefix without spaces, got {prefix!r}")
    lower, upper = leg_limits
    if not (math.isfinite(lower) and math.isfinite(upper) and lower < upper):
        raise ValueError(f"leg_limits: need finite lower < upper [rad], got {leg_limits}")
    parts = [f'<?xml version="1.0"?>\n<robot name={quoteattr(name)}>\n',
             '  <material name="grey"><color rgba="0.6 0.6 0.6 1"/></material>\n',
             '  <material name="carbon"><color rgba="0.15 0.15 0.15 1"/></material>\n',
             '  <material name="rotor"><color rgba="0.2 0.4 0.9 0.6"/></material>\n',
             '  <material name="marker"><color rgba="1 1 1 1"/></material>\n']
    radius = params.platform_radius
    parts.append(f'  <link name="{prefix}platform">\n'
                 + _visual(f'<cylinder radius="{radius:.6g}" length="0.006"/>')
                 + _visual('<box size="0.1 0.1 0.002"/>', xyz=(0.0, 0.0, 0.004), material="marker")
                 + _inertial(params.platform_mass, params.platform_com, params.platform_inertia) + '  </link>\n')
    length = params.leg_length
    for i in range(params.n):
        k = i + 1
        anchor, rpy = leg_joint_origin(params, i)
        parts.append(f'  <link name="{prefix}leg{k}">\n'
                     + _visual(f'<cylinder radius="0.008" length="{length:.6g}"/>', xyz=(length / 2.0, 0.0, 0.0),
                               rpy=(0.0, math.pi / 2.0, 0.0), material="carbon")
                     + _inertial(params.leg_mass, params.leg_com, params.leg_inertia) + '  </link>\n')
        parts.append(f'  <joint name="{prefix}leg{k}_joint" type="revolute">\n'
                     f'    <parent link="{prefix}platform"/>\n    <child link="{prefix}leg{k}"/>\n'
                     f'    <origin xyz="{_vec(anchor)}" rpy="{_vec(rpy)}"/>\n    <axis xyz="0 0 1"/>\n'
                     f'    <limit lower="{lower:.6g}" upper="{upper:.6g}" effort="0" velocity="10"/>\n  </joint>\n')
        rotors = "".join(_visual(f'<cylinder radius="{ROTOR_RADIUS:.6g}" length="0.004"/>',
                                 xyz=(UAV_ARM * math.cos(a), UAV_ARM * math.sin(a), 0.03), material="rotor")
                         for a in (0.0, math.pi / 2.0, math.pi, 3.0 * math.pi / 2.0))
        arms = "".join(_visual(f'<box size="{2.0 * UAV_ARM:.6g} 0.02 0.01"/>', rpy=(0.0, 0.0, a))
                       for a in (0.0, math.pi / 2.0))
        parts.append(f'  <link name="{prefix}uav{k}/base_link">\n' + arms + rotors
                     + _inertial(float(params.uav_masses[i]), (0.0, 0.0, 0.0), np.diag(uav_inertia))
                     + '  </link>\n')
        parts.append(f'  <joint name="{prefix}uav{k}_joint" type="floating">\n'
                     f'    <parent link="{prefix}leg{k}"/>\n    <child link="{prefix}uav{k}/base_link"/>\n'
                     f'    <origin xyz="{length:.9g} 0 0" rpy="0 0 0"/>\n  </joint>\n')
    parts.append('</robot>\n')
    return "".join(parts)
