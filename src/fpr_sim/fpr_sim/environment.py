"""The robot's surroundings, scheduled from the scenario: ground plane, payload, wind, external wrench, board.

All forces are world-frame (ENU) newtons at world points; the plant maps them onto the structure.

- Ground z = h: penalty contact ``N = max(0, k δ − c ż)`` (δ penetration) with stick/slip friction: a tangential
  spring-damper to an anchor point, the anchor sliding so that ``|F_t| ≤ μ N`` (so a resting robot does not creep).
- Board: plane through ``point`` with unit ``normal`` (towards the robot), penalty contact on the platform's
  end-effector point while it is over the board's rectangle (``size`` along ``edge`` and ``normal × edge``,
  unbounded by default), Coulomb friction regularised below 1 cm/s; the true normal force is reported.
- Wind: air velocity = uniform part ``w(t)`` (constant + half-sine gusts) + the jet of a wind generator
  (:class:`FanJet`, evaluated at each body point, switched on / ramped / off on its schedule), linear drag
  ``c (w − v)`` on the platform centre, each leg's middle and each quadrotor.
- Payload: point masses at P, attached/released at scheduled times, or picked up when P comes near a hanging
  load (:meth:`Environment.payload_mass`, scenario ``payloads``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fpr_sim.scenario import BoardConfig, FanConfig, GroundConfig, PayloadEvent, Scenario

__all__ = ["FAN_SEED_STREAM", "Environment", "FanJet", "GroundContacts", "PayloadChange", "board_axes"]

#: the fan turbulence draws from ``SeedSequence([scenario.seed, FAN_SEED_STREAM])`` (the cameras use 7)
FAN_SEED_STREAM = 11
_LN2 = math.log(2.0)


def board_axes(board: BoardConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit normal n, and the in-plane unit axes u (``edge`` projected onto the plane) and v = n × u of a board."""
    normal = np.asarray(board.normal, dtype=float)
    normal = normal / np.linalg.norm(normal)
    edge = np.asarray(board.edge, dtype=float)
    u = edge - (edge @ normal) * normal
    u = u / np.linalg.norm(u)
    return normal, u, np.cross(normal, u)


class FanJet:
    """The air velocity of a wind generator (scenario ``wind.fan``, :class:`~fpr_sim.scenario.FanConfig`):
    a round free jet with seeded turbulence.

    Mean flow. With x the distance from the outlet along the unit axis e and r the distance from the axis, the
    self-similar round jet (Pope, *Turbulent Flows*, 2000, §5.1 and Table 5.1, after Hussein, Capp & George,
    J. Fluid Mech. 258, 1994) has a centre-line speed decaying as ``U_c/U_0 = B·D/x`` with B ≈ 5.8, and a
    Gaussian lateral profile ``U/U_c = exp(−ln 2 · r²/b²)`` whose half-width (U = U_c/2) grows linearly,
    ``b = S·x`` with S ≈ 0.094 (Panchapakesan & Lumley 1993: 0.096 and B 6.1 — the constants are scenario
    fields). Near the outlet the jet keeps its outlet speed in a potential core of about 5-6 D: here
    ``U_c = U_0·min(1, B·D/x)`` and ``b = max(D/2, S·x)`` (continuous; the core ends at x = B·D ≈ 5.8 D, the
    width starts growing at x = D/(2S) ≈ 5.3 D). Nothing flows behind the outlet plane (x ≤ 0); the jet's small
    entrainment (radial) velocity is neglected, the mean air velocity is U·e. U_0 is set so that the mean speed
    at the reference point is ``speed`` (what an anemometer there reads).

    Turbulence. ``v' = I·U(x, r)·ξ(t)`` on each world axis: ξ a unit-variance first-order Gauss-Markov process
    (exact discretisation ``ξ_{k+1} = a ξ_k + √(1 − a²) w_k``, ``a = exp(−Δt/τ)``, w_k ~ N(0, 1), started from its
    stationary law), i.e. the first-order spectrum of the Dryden longitudinal gust model (MIL-HDBK-1797,
    τ = L/U) used here on all three axes. One ξ for the whole robot (the robot, ~1.5 m across, is of the order
    of the integral length scale). Intensity I: 15 % by default — measured axial intensities of round jets are
    ≈ 0.25 on the axis of the self-similar far field (Hussein et al. 1994; radial ≈ 0.19), lower in the
    developing near field (x < 8 D) where a robot a few metres from a large fan hovers; fan outlets (rotating
    blades) add 5-15 %. τ: 0.1 s by default, the integral length scale (of the order of the half-width, 0.3-0.5 m)
    over the mean speed (4-7 m/s). Samples are on the grid of the physics step ``dt``: the turbulence at time t
    is the sample of step ``round(t/dt)``, a pure function of the seed and the step (queries must not go back
    in time; an earlier time gets the latest sample).

    Schedule (``start_time``, ``ramp_time``, ``end_time``): the mean velocity and the turbulence are both scaled by
    :meth:`speed_factor` s(t) ∈ [0, 1] (0 before the start and from the end on, a linear spin-up over
    ``ramp_time``), so the fluctuation stays ``I·s(t)·U(x, r)``: zero while the fan is off. ξ(t) itself runs on
    regardless (the same seeded sequence whatever the schedule).
    """

    def __init__(self, config: FanConfig, seed: int, dt: float, reference_point) -> None:
        self.config = config
        axis = np.asarray(config.direction, dtype=float)
        axis = axis / np.linalg.norm(axis)
        reference = np.asarray(reference_point if config.reference_point is None else config.reference_point,
                               dtype=float)
        origin = (reference - config.distance * axis if config.position is None
                  else np.asarray(config.position, dtype=float))
        self.axis = tuple(axis.tolist())  #: unit jet axis e, world
        self.origin = tuple(origin.tolist())  #: outlet centre [m], world
        self.reference_point = tuple(reference.tolist())  #: where the mean speed is ``speed`` [m], world
        self._core = config.decay_constant * config.diameter  # B·D [m]
        self._half_width = 0.5 * config.diameter  # [m]
        self._spreading = config.spreading_rate
        self.outlet_speed = 1.0  # U_0 [m/s]: set below from the reference point
        shape = self._steady_speed(self.reference_point)
        if not shape > 1e-3:
            raise ValueError(f"wind.fan: the reference point {self.reference_point} is not in the jet (relative "
                             f"speed {shape:.2g} of the outlet's; outlet {self.origin}, axis {self.axis})")
        self.outlet_speed = float(config.speed) / shape
        self.start_time = float(config.start_time)  #: [s] the fan switches on
        self.ramp_time = float(config.ramp_time)  #: [s] linear spin-up (0: a step)
        self.end_time = float(config.end_time)  #: [s] the fan stops (inf: never)
        self.intensity = float(config.turbulence_intensity)
        self.dt = float(dt)
        self._a = math.exp(-self.dt / config.turbulence_time_constant)
        self._b = math.sqrt(1.0 - self._a * self._a)
        self._rng = np.random.default_rng(np.random.SeedSequence([int(seed), FAN_SEED_STREAM]))
        self._xi = self._rng.standard_normal(3).tolist() if self.intensity > 0.0 else [0.0, 0.0, 0.0]
        self._index = 0
        self._draws: list[list[float]] = []

    def speed_factor(self, t: float) -> float:
        """s(t) [-]: the fraction of the full mean speed (and of the turbulence) blowing at time ``t`` [s]: 0 before
        ``start_time`` and from ``end_time`` on, ``min(1, (t − start_time) / ramp_time)`` in between (1 without
        a ramp)."""
        if not self.start_time <= t < self.end_time:
            return 0.0
        if self.ramp_time > 0.0:
            return min(1.0, (t - self.start_time) / self.ramp_time)
        return 1.0

    def mean_speed(self, point, t: float | None = None) -> float:
        """U(x, r) [m/s] at a world point [m] (the mean air velocity there is U times the axis), at time ``t`` [s]
        (× :meth:`speed_factor`) or, with ``t`` None, at full speed (the fan's steady profile)."""
        scale = 1.0 if t is None else self.speed_factor(t)
        if scale == 0.0:
            return 0.0
        return scale * self._steady_speed(point)

    def _steady_speed(self, point) -> float:
        ox, oy, oz = self.origin
        ax, ay, az = self.axis
        dx, dy, dz = point[0] - ox, point[1] - oy, point[2] - oz
        x = dx * ax + dy * ay + dz * az
        if not x > 0.0:
            return 0.0
        r2 = max(dx * dx + dy * dy + dz * dz - x * x, 0.0)
        b = max(self._half_width, self._spreading * x)
        return self.outlet_speed * min(1.0, self._core / x) * math.exp(-_LN2 * r2 / (b * b))

    def turbulence(self, t: float) -> tuple[float, float, float]:
        """ξ(t), the unit-variance Gauss-Markov sample of physics step round(t/dt) (see the class doc)."""
        index = int(round(t / self.dt))
        if self.intensity > 0.0:
            a, b = self._a, self._b
            xi = self._xi
            while self._index < index:
                if not self._draws:
                    self._draws = self._rng.standard_normal((1024, 3)).tolist()[::-1]
                w0, w1, w2 = self._draws.pop()
                xi = [a * xi[0] + b * w0, a * xi[1] + b * w1, a * xi[2] + b * w2]
                self._index += 1
            self._xi = xi
        else:
            self._index = max(self._index, index)
        return self._xi[0], self._xi[1], self._xi[2]

    def velocities(self, t: float, points) -> list[tuple[float, float, float]]:
        """Air velocity [m/s] (world) of the jet at time t at each world point [m] (mean + turbulence, both
        scaled by :meth:`speed_factor`)."""
        scale = self.speed_factor(t)
        if scale == 0.0:  # off: still air (ξ is drawn lazily, so skipping it keeps the seeded sequence)
            return [(0.0, 0.0, 0.0)] * len(points)
        x0, x1, x2 = self.turbulence(t)
        ax, ay, az = self.axis
        i = self.intensity
        c0, c1, c2 = ax + i * x0, ay + i * x1, az + i * x2
        ox, oy, oz = self.origin
        core, half_width, spreading = self._core, self._half_width, self._spreading
        outlet = self.outlet_speed * scale
        out = []
        for px, py, pz in points:  # mean_speed, inlined (the 1 kHz loop)
            dx, dy, dz = px - ox, py - oy, pz - oz
            x = dx * ax + dy * ay + dz * az
            if not x > 0.0:
                out.append((0.0, 0.0, 0.0))
                continue
            r2 = max(dx * dx + dy * dy + dz * dz - x * x, 0.0)
            b = max(half_width, spreading * x)
            u = outlet * min(1.0, core / x) * math.exp(-_LN2 * r2 / (b * b))
            out.append((u * c0, u * c1, u * c2))
        return out


@dataclass(frozen=True)
class PayloadChange:
    """A payload attached to or released from P (:attr:`Environment.payload_changes`, in time order)."""

    time: float  #: [s] the step (start) at which it changed
    index: int  #: its index in ``scenario.payloads``
    attached: bool  #: True: attached (picked up), False: released
    mass: float  #: [kg]
    pickup: bool  #: a pick-up payload (``pickup_position`` set), else timed
    distance: float  #: [m] |P − pickup_position| when a pick-up payload attached, else NaN


class _PayloadSchedule:
    """The attach / release logic of :class:`~fpr_sim.scenario.PayloadEvent` (see its doc)."""

    __slots__ = ("attach_time", "hold_time", "mass", "pickup", "radius2", "release_time")

    def __init__(self, event: PayloadEvent) -> None:
        self.mass = float(event.mass)
        self.attach_time = float(event.attach_time)
        self.release_time = float(event.release_time)
        self.hold_time = float(event.hold_time) if event.hold_time > 0.0 else math.inf
        self.pickup = None if event.pickup_position is None else tuple(float(v) for v in event.pickup_position)
        self.radius2 = float(event.pickup_radius) ** 2


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
        self.board_normal, self.board_u, self.board_v = board_axes(self.board)
        self.board_point = np.asarray(self.board.point, dtype=float)
        self.board_end_effector = np.asarray(self.board.end_effector, dtype=float)
        self.board_half_size = tuple(0.5 * float(s) for s in self.board.size)  #: half side lengths [m] (inf)
        self._board_normal = tuple(self.board_normal.tolist())
        self._board_point = tuple(self.board_point.tolist())
        self._board_u = tuple(self.board_u.tolist())
        self._board_v = tuple(self.board_v.tolist())
        self._board_bounded = not all(math.isinf(h) for h in self.board_half_size)
        self.wind_constant = np.asarray(scenario.wind.velocity, dtype=float)
        self._uniform = None if scenario.wind.gusts else tuple(self.wind_constant.tolist())  # constant: cached
        #: the wind generator's jet (:meth:`attach_fan`, called by the plant once it knows the initial state)
        self.fan: FanJet | None = None
        self.has_wind = bool(np.any(self.wind_constant != 0.0) or scenario.wind.gusts or scenario.wind.fan.enabled)
        self._payloads = [_PayloadSchedule(p) for p in scenario.payloads]
        #: [s] per payload: when a pick-up payload attached (NaN: not (yet) picked up, or a timed payload)
        self.pickup_times: list[float] = [math.nan] * len(self._payloads)
        self._attached = [False] * len(self._payloads)
        #: every attach and release so far, in time order (seen by :meth:`payload_mass`; the simulator logs them)
        self.payload_changes: list[PayloadChange] = []

    def attach_fan(self, default_reference_point, dt: float) -> FanJet | None:
        """Build the fan's jet when ``wind.fan`` is enabled: ``default_reference_point`` [m] (world) is used when
        the scenario gives none (the plant passes the quadrotors' initial centroid), ``dt`` [s] is the physics
        step (the turbulence grid)."""
        fan = self.scenario.wind.fan
        self.fan = FanJet(fan, self.scenario.seed, dt, default_reference_point) if fan.enabled else None
        return self.fan

    def payload_mass(self, t: float, position=None) -> float:
        """Total payload attached to P at time ``t`` [s] with the platform centre P at ``position`` [m] (world)
        [kg]; the plant calls it at the start of every step, in time order.

        Timed payloads: attached on ``[attach_time, min(release_time, attach_time + hold_time))`` (a pure function
        of t). Pick-up payloads (``pickup_position`` set): the first call with ``attach_time <= t <
        release_time`` and P within ``pickup_radius`` of ``pickup_position`` attaches it (``pickup_times``); it
        stays until ``release_time`` or ``hold_time`` after the pick-up and never attaches again. ``position``
        None: no pick-up can happen at this call. Transitions are appended to :attr:`payload_changes`."""
        total = 0.0
        for k, p in enumerate(self._payloads):
            if p.pickup is None:
                start = p.attach_time
            else:
                start = self.pickup_times[k]
                if start != start and position is not None and p.attach_time <= t < p.release_time:
                    dx, dy, dz = position[0] - p.pickup[0], position[1] - p.pickup[1], position[2] - p.pickup[2]
                    if dx * dx + dy * dy + dz * dz <= p.radius2:
                        start = self.pickup_times[k] = t
            attached = start <= t < p.release_time and t < start + p.hold_time  # False while start is NaN
            if attached != self._attached[k]:
                self._attached[k] = attached
                distance = math.nan
                if attached and p.pickup is not None:
                    distance = math.dist(position, p.pickup)
                self.payload_changes.append(PayloadChange(float(t), k, attached, p.mass, p.pickup is not None,
                                                          distance))
            if attached:
                total += p.mass
        return total

    def wind_velocity(self, t: float) -> np.ndarray:
        """Air velocity [m/s] (world) at time t: constant + half-sine gusts."""
        w = self.wind_constant.copy()
        for gust in self.scenario.wind.gusts:
            if gust.start <= t <= gust.start + gust.duration and gust.duration > 0.0:
                w += np.asarray(gust.velocity, dtype=float) * math.sin(math.pi * (t - gust.start) / gust.duration)
        return w

    def air_velocities(self, t: float, points) -> list[float]:
        """Air velocity [m/s] (world) at time t at each world point [m] (k, 3): the uniform wind plus the fan's jet,
        flattened as [w_0x, w_0y, w_0z, w_1x, ...] (3k floats)."""
        w0, w1, w2 = self._uniform if self._uniform is not None else self.wind_velocity(t).tolist()
        if self.fan is None:
            return [w0, w1, w2] * len(points)
        out = []
        for f0, f1, f2 in self.fan.velocities(t, points):
            out += (w0 + f0, w1 + f1, w2 + f2)
        return out

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
        offset = point - self.board_point
        depth = -float(offset @ self.board_normal)
        if depth <= 0.0 or depth > self.board.contact_depth:  # in front of the face, or behind the board
            return np.zeros(3), 0.0
        if not (abs(float(offset @ self.board_u)) <= self.board_half_size[0]
                and abs(float(offset @ self.board_v)) <= self.board_half_size[1]):
            return np.zeros(3), 0.0  # beside the board
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
        o0, o1, o2 = point[0] - b0, point[1] - b1, point[2] - b2
        depth = -(o0 * n0 + o1 * n1 + o2 * n2)
        if depth <= 0.0 or depth > board.contact_depth:  # in front of the face, or behind the board
            return (0.0, 0.0, 0.0), 0.0
        if self._board_bounded:
            u0, u1, u2 = self._board_u
            v0, v1, v2 = self._board_v
            half_u, half_v = self.board_half_size
            if not (abs(o0 * u0 + o1 * u1 + o2 * u2) <= half_u and abs(o0 * v0 + o1 * v1 + o2 * v2) <= half_v):
                return (0.0, 0.0, 0.0), 0.0  # beside the board
        v0, v1, v2 = velocity
        normal_speed = v0 * n0 + v1 * n1 + v2 * n2
        normal = max(0.0, board.stiffness * depth - board.damping * normal_speed)
        t0, t1, t2 = v0 - normal_speed * n0, v1 - normal_speed * n1, v2 - normal_speed * n2
        scale = -board.friction * normal / max(math.sqrt(t0 * t0 + t1 * t1 + t2 * t2), 0.01)
        return (normal * n0 + scale * t0, normal * n1 + scale * t1, normal * n2 + scale * t2), normal
