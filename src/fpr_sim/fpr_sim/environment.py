"""The robot's surroundings, scheduled from the scenario: ground plane, payload, wind, external wrench, board.

All forces are world-frame (ENU) newtons at world points; the plant maps them onto the structure.

- Ground z = h: penalty contact ``N = max(0, k δ − c ż)`` (δ penetration) with stick/slip friction: a tangential
  spring-damper to an anchor point, the anchor sliding so that ``|F_t| ≤ μ N`` (so a resting robot does not creep).
- Board: plane through ``point`` with unit ``normal`` (towards the robot), penalty contact on the platform's
  end-effector point, Coulomb friction regularised below 1 cm/s; the true normal force is reported.
- Wind: air velocity ``w(t)`` = constant + half-sine gusts, linear drag ``c (w − v)`` on the platform centre,
  each leg's middle and each quadrotor.
- Payload: point mass at P, attached/released at scheduled times.
"""

from __future__ import annotations

import math

import numpy as np

from fpr_sim.scenario import BoardConfig, GroundConfig, Scenario

__all__ = ["Environment", "GroundContacts"]


class GroundContacts:
    """Penalty ground contact of k points with stick/slip friction anchors (see the module doc)."""

    def __init__(self, config: GroundConfig, count: int) -> None:
        self.config = config
        self.anchors = np.full((count, 2), np.nan)  # NaN: not in contact

    def forces(self, points: np.ndarray, velocities: np.ndarray) -> np.ndarray:
        """Contact forces (k, 3) [N] on the points (k, 3) [m] moving at (k, 3) [m/s]; anchors held."""
        c = self.config
        depth = c.height - points[:, 2]
        out = np.zeros_like(points)
        touching = depth > 0.0
        if not touching.any() or not c.enabled:
            return out
        normal = np.maximum(c.stiffness * depth - c.damping * velocities[:, 2], 0.0) * touching
        anchors = np.where(np.isnan(self.anchors), points[:, :2], self.anchors)
        tangential = -c.tangential_stiffness * (points[:, :2] - anchors) - c.tangential_damping * velocities[:, :2]
        size = np.linalg.norm(tangential, axis=1)
        limit = c.friction * normal
        scale = np.where(size > limit, limit / np.maximum(size, 1e-12), 1.0)
        out[:, :2] = tangential * scale[:, None] * touching[:, None]
        out[:, 2] = normal
        return out

    def update_anchors(self, points: np.ndarray) -> None:
        """After a step: create anchors on new contacts, slide them when friction saturates, drop them on lift-off."""
        c = self.config
        touching = (c.height - points[:, 2]) > 0.0
        for k in range(len(points)):
            if not touching[k] or not c.enabled:
                self.anchors[k] = np.nan
                continue
            if np.isnan(self.anchors[k, 0]):
                self.anchors[k] = points[k, :2]
                continue
            depth = c.height - points[k, 2]
            limit = c.friction * c.stiffness * depth / c.tangential_stiffness  # max spring stretch [m]
            stretch = points[k, :2] - self.anchors[k]
            size = float(np.hypot(*stretch))
            if size > limit:
                self.anchors[k] = points[k, :2] - stretch * (limit / size)


class Environment:
    """Scheduled disturbances and contacts of one scenario (see the module doc)."""

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        self.n = scenario.n
        self.ground = GroundContacts(scenario.ground, self.n + 1)  # feet of the n quadrotors + platform centre
        self.board: BoardConfig = scenario.board
        normal = np.asarray(self.board.normal, dtype=float)
        self.board_normal = normal / np.linalg.norm(normal)
        self.board_point = np.asarray(self.board.point, dtype=float)
        self.board_end_effector = np.asarray(self.board.end_effector, dtype=float)
        self.wind_constant = np.asarray(scenario.wind.velocity, dtype=float)
        self.has_wind = bool(np.any(self.wind_constant != 0.0) or scenario.wind.gusts)

    def payload_mass(self, t: float) -> float:
        """Total payload attached to P at time ``t`` [kg]."""
        return float(sum(p.mass for p in self.scenario.payloads if p.attach_time <= t < p.release_time))

    def wind_velocity(self, t: float) -> np.ndarray:
        """Air velocity [m/s] (world) at time t: constant + half-sine gusts."""
        w = self.wind_constant.copy()
        for gust in self.scenario.wind.gusts:
            if gust.start <= t <= gust.start + gust.duration and gust.duration > 0.0:
                w += np.asarray(gust.velocity, dtype=float) * math.sin(math.pi * (t - gust.start) / gust.duration)
        return w

    def platform_wrench(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Scheduled external force (world, N) at P and moment (Fp, N m) at time t."""
        force = np.zeros(3)
        moment = np.zeros(3)
        for event in self.scenario.external_wrenches:
            if event.start <= t < event.end:
                force += np.asarray(event.force, dtype=float)
                moment += np.asarray(event.moment, dtype=float)
        return force, moment

    def board_force(self, point: np.ndarray, velocity: np.ndarray) -> tuple[np.ndarray, float]:
        """Board contact force (world, N) on the end-effector at ``point`` moving at ``velocity``; normal force."""
        if not self.board.enabled:
            return np.zeros(3), 0.0
        depth = -float((point - self.board_point) @ self.board_normal)
        if depth <= 0.0:
            return np.zeros(3), 0.0
        normal_speed = float(velocity @ self.board_normal)
        normal = max(0.0, self.board.stiffness * depth - self.board.damping * normal_speed)
        tangential_velocity = velocity - normal_speed * self.board_normal
        speed = float(np.linalg.norm(tangential_velocity))
        friction = -self.board.friction * normal * tangential_velocity / max(speed, 0.01)
        return normal * self.board_normal + friction, normal
