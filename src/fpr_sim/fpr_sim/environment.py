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

    def point_force(self, anchor: list[float], px: float, py: float, pz: float, vx: float, vy: float,
                    vz: float) -> tuple[float, float, float]:
        """:meth:`forces` of ONE point on plain floats (the 1 kHz loop): ``anchor`` [x, y] (NaN: none)."""
        c = self.config
        depth = c.height - pz
        if not depth > 0.0 or not c.enabled:
            return 0.0, 0.0, 0.0
        normal = max(c.stiffness * depth - c.damping * vz, 0.0)
        ax, ay = anchor
        if ax != ax:  # NaN: the contact starts here
            ax, ay = px, py
        tx = -c.tangential_stiffness * (px - ax) - c.tangential_damping * vx
        ty = -c.tangential_stiffness * (py - ay) - c.tangential_damping * vy
        size = math.hypot(tx, ty)
        limit = c.friction * normal
        if size > limit:
            scale = limit / max(size, 1e-12)
            tx *= scale
            ty *= scale
        return tx, ty, normal

    def update_anchors(self, points) -> None:
        """After a step: create anchors on new contacts, slide them when friction saturates, drop them on lift-off.

        ``points`` (k, 3) [m], array or list of [x, y, z]."""
        c = self.config
        anchors = self.anchors
        for k, (px, py, pz) in enumerate(points.tolist() if isinstance(points, np.ndarray) else points):
            depth = c.height - pz
            if not depth > 0.0 or not c.enabled:
                anchors[k] = np.nan
                continue
            ax, ay = anchors[k].tolist()
            if ax != ax:
                anchors[k] = (px, py)
                continue
            limit = c.friction * c.stiffness * depth / c.tangential_stiffness  # max spring stretch [m]
            sx, sy = px - ax, py - ay
            size = math.hypot(sx, sy)
            if size > limit:
                anchors[k] = (px - sx * (limit / size), py - sy * (limit / size))


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
        self._board_normal = tuple(self.board_normal.tolist())
        self._board_point = tuple(self.board_point.tolist())
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

    def board_force_scalar(self, point: tuple[float, float, float],
                           velocity: tuple[float, float, float]) -> tuple[tuple[float, float, float], float]:
        """:meth:`board_force` on plain floats (the 1 kHz loop): (force (world, N), normal force [N])."""
        board = self.board
        if not board.enabled:
            return (0.0, 0.0, 0.0), 0.0
        n0, n1, n2 = self._board_normal
        b0, b1, b2 = self._board_point
        depth = -((point[0] - b0) * n0 + (point[1] - b1) * n1 + (point[2] - b2) * n2)
        if depth <= 0.0:
            return (0.0, 0.0, 0.0), 0.0
        v0, v1, v2 = velocity
        normal_speed = v0 * n0 + v1 * n1 + v2 * n2
        normal = max(0.0, board.stiffness * depth - board.damping * normal_speed)
        t0, t1, t2 = v0 - normal_speed * n0, v1 - normal_speed * n1, v2 - normal_speed * n2
        scale = -board.friction * normal / max(math.sqrt(t0 * t0 + t1 * t1 + t2 * t2), 0.01)
        return (normal * n0 + scale * t0, normal * n1 + scale * t1, normal * n2 + scale * t2), normal
