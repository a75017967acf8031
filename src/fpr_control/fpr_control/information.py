"""Information vectors ζ_j, their ages, and the decentralized state reconstruction (thesis §4.2.3, §4.3.2-4.3.3).

- ζ_i = [θ_i, Fp v_i, Fp q_i, f^d_t,i] (4.31), (4.36): leg angle [rad], UAV velocity in F_Fp [m/s], UAV attitude
  in F_Fp ([w,x,y,z]) and last commanded thrust [N]. :class:`InformationTable` keeps the newest per UAV with
  its receive time; a peer is fresh when its age ≤ info_timeout (DESIGN.md §4).
- State reconstruction on UAV i: ``q = [0_3, Fp q_p, θ_l]`` (4.24) with Fp q_p = quat(Ry(ϑ_p) Rx(ϕ_p)) from the
  own estimate, ν = J(q)† [Fp v_1; ...; Fp v_n] (FKM (2.21)) in F_Fp.
- C: the others' θ_j, Fp v_j come from their ζ_j. NC: they are replaced by the desired values (4.32):
  θ_j = θ^d_j and Fp v^d = J(q) ν^d.
- Thrust vectors for the observer (4.37): Fp f_j = Fp R_j [0, 0, f^d_t,j].

Bounded inputs (issue 12), in :meth:`InformationTable.update`, with the defaults of :class:`InfoPlausibility`:

- plausibility: a ζ_j is refused if its leg angle is outside [7°, 90°], if |Fp v_j| > 10 m/s or if f^d_t,j > 50 N.
  7° is the 10° joint stop less 3° for the estimate's noise and the stops' compliance. The upper bound is
  the model's domain (0, 90°] (:func:`fpr_model.kinematics.jacobian_at`), inside the 92° stop. It is also
  refused if it jumps from the last ACCEPTED ζ_j of the same uav_id by more than is physically possible in the
  Δt between their receptions: |Δθ_j| > 20 rad/s · Δt + 5°, the angle between the attitudes > 20 rad/s · Δt + 10°,
  or |ΔFp v_j| > 50 m/s² · Δt + 1 m/s. The slack terms cover the estimates' noise and messages delivered
  together. The bound grows with Δt, so a genuine change persisting for about 0.2 s is accepted again. A refused
  ζ_j counts as missing: its age grows and the NC fallback on stale information applies. The node logs one
  rate-limited line, and one line when ζ_j is accepted again.
- one publisher per uav_id: Jazzy's rclpy gives no publisher GID in ``MessageInfo`` (its keys are
  source_timestamp, received_timestamp, publication_sequence_number and reception_sequence_number). Each
  publisher is therefore told apart by its DDS publication sequence number, which every writer counts up by one
  per message from 1. The first stream of uav_id j accepted is j's publisher. A message continues that stream if
  s_last < s ≤ s_last + 16 + 1000 Hz · Δt (losses and relays forwarding several ids are allowed; a restart, or a
  second writer, breaks the pattern). Any other message claiming j is an intruder's: it is refused, and
  announced once per intruder stream. When the established stream has been silent for ``publisher_timeout``
  (1 s), the next stream takes over (announced). This covers a restarted controller. Its own uav_id, read
  directly on the topic it publishes on (``own_writer_direct``): the controller counts its own publications k,
  and only sequence numbers in (k − 50, k] are its own echo. Everything else claiming its id is a forged echo and
  is refused entirely, with no takeover. Through a relay (``info_input_topic``), its own id is treated like the
  peers'. Without sequence numbers (None), the stream checks are skipped.
No rclpy here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from fpr_model._math import norm_floats
from fpr_model._validation import all_finite
from fpr_model.kinematics import JacobianAt, jacobian_at
from fpr_model.parameters import FprParameters
from fpr_model.rotations import euler_zyx_to_quat, quat_angle, rotation_entries


@dataclass
class PeerInfo:
    """ζ_j of UAV j (1-based id)."""

    uav_id: int
    leg_angle: float
    velocity: np.ndarray  # Fp v_j [m/s]
    attitude: np.ndarray  # Fp q_j [w, x, y, z]
    thrust: float  # f^d_t,j [N]

    def problem(self) -> str | None:
        """Why this vector is unusable (non-finite, zero quaternion, negative thrust), or None."""
        if not all_finite(self.leg_angle, self.thrust, self.velocity, self.attitude):
            return "contains NaN or inf"
        if not 0.5 < norm_floats(self.attitude) < 1.5:
            return "attitude is not a unit quaternion"
        if self.thrust < 0.0:
            return "negative thrust"
        return None


@dataclass
class LocalEstimate:
    """What the own pose estimator gives (fpr_msgs/LocalState), rad, m/s."""

    leg_angle: float
    platform_roll: float  # Fp ϕ_p
    platform_pitch: float  # Fp ϑ_p
    attitude: np.ndarray  # Fp q_i [w, x, y, z]
    velocity: np.ndarray  # Fp v_i [m/s]
    relative_yaw: float  # pψ_i
    uav_yaw: float  # 0iψ_i (own IMU)
    valid: bool = True

    def is_finite(self) -> bool:
        return all_finite(self.leg_angle, self.platform_roll, self.platform_pitch, self.relative_yaw, self.uav_yaw,
                          self.attitude, self.velocity) and norm_floats(self.attitude) > 0.5


@dataclass(frozen=True)
class InfoPlausibility:
    """Plausibility bounds of a received ζ_j and the publisher-stream rule (module doc). rad, m/s, N, s."""

    leg_angle_min: float = math.radians(7.0)  #: [rad] joint stop 10° − 3°
    leg_angle_max: float = math.radians(90.0)  #: [rad] the model's domain (0, π/2], inside the 92° stop
    max_speed: float = 10.0  #: |Fp v_j| [m/s]
    max_thrust: float = 50.0  #: f^d_t,j [N] (Table C.1 vehicles: f_max ≈ 40 N at 12.6 V)
    max_leg_rate: float = 20.0  #: [rad/s] jump bound of θ_j
    max_angular_rate: float = 20.0  #: [rad/s] jump bound of Fp q_j
    max_acceleration: float = 50.0  #: [m/s²] jump bound of Fp v_j
    leg_jump_slack: float = math.radians(5.0)  #: [rad]
    attitude_jump_slack: float = math.radians(10.0)  #: [rad]
    velocity_jump_slack: float = 1.0  #: [m/s]
    publisher_timeout: float = 1.0  #: [s] an established publisher silent this long may be replaced
    sequence_window: int = 16  #: publication sequence numbers a stream may skip at once
    max_publication_rate: float = 1000.0  #: [Hz] plus this many per second of silence
    own_echo_window: int = 50  #: own echo: sequence numbers in (k − this, k], k = own publications

    def __post_init__(self) -> None:
        if not 0.0 <= self.leg_angle_min < self.leg_angle_max <= math.pi:
            raise ValueError("need 0 <= leg_angle_min < leg_angle_max <= pi")
        values = (self.max_speed, self.max_thrust, self.max_leg_rate, self.max_angular_rate, self.max_acceleration,
                  self.publisher_timeout, self.max_publication_rate)
        if not all(math.isfinite(v) and v > 0.0 for v in values):
            raise ValueError("info plausibility bounds must be finite and > 0")
        if min(self.leg_jump_slack, self.attitude_jump_slack, self.velocity_jump_slack) < 0.0:
            raise ValueError("jump slacks must be >= 0")
        if self.sequence_window < 1 or self.own_echo_window < 1:
            raise ValueError("sequence_window and own_echo_window must be >= 1")


@dataclass
class _Stream:
    """One publisher's stream of ζ_j: last publication sequence number and receive time [s]."""

    sequence: int
    time: float


class InformationTable:
    """Newest ζ_j per UAV j ≠ own, with receive times (controller clock, s).

    With ``require_own_echo`` the own ζ_i must also come back on the shared topic within the timeout: a UAV
    whose vectors do not reach the topic (silenced) then falls back to NC together with the others, who see
    its ζ_i age."""

    def __init__(self, n: int, own_id: int, timeout: float, require_own_echo: bool = True,
                 plausibility: InfoPlausibility | None = None, own_writer_direct: bool = False) -> None:
        if not 1 <= own_id <= n:
            raise ValueError(f"uav_id {own_id} outside 1..{n}")
        self.n = n
        self.own_id = own_id
        self.timeout = timeout
        self.require_own_echo = require_own_echo
        self.plausibility = plausibility if plausibility is not None else InfoPlausibility()
        #: the own ζ_i is read back from the topic this controller writes on (its echo carries its own writer's
        #: sequence numbers); False through a relay
        self.own_writer_direct = own_writer_direct
        self.own_publications = 0  #: ζ_i this controller has published (its writer's last sequence number)
        self._infos: dict[int, PeerInfo] = {}
        self._times: dict[int, float] = {}
        self._own_echo_time = -math.inf
        self._accepted: dict[int, tuple[PeerInfo, float]] = {}  #: last accepted ζ_j and its time (jump check)
        self._refused: dict[int, int] = {}  #: consecutive implausible ζ_j per uav_id (announced on return)
        self._streams: dict[int, _Stream] = {}  #: established publisher stream per uav_id
        self._intruders: dict[int, list[_Stream]] = {}
        self.intruder_messages = 0  #: ζ refused as another publisher's
        self._announcements: list[str] = []
        self._returns: list[str] = []

    def take_announcements(self) -> list[str]:
        """One-off lines to log once each: a new intruder stream, a publisher takeover."""
        out, self._announcements = self._announcements, []
        return out

    def take_returns(self) -> list[str]:
        """"ζ_j accepted again after N refused" lines (the node rate-limits them like the refusals)."""
        out, self._returns = self._returns, []
        return out

    def note_own_publication(self) -> None:
        """The controller published one ζ_i (its writer's sequence number is now :attr:`own_publications`)."""
        self.own_publications += 1

    # ---- one publisher per uav_id (module doc) ------------------------------------------------------
    def _continues(self, stream: _Stream, sequence: int, now: float) -> bool:
        p = self.plausibility
        allowed = p.sequence_window + math.ceil(p.max_publication_rate * max(now - stream.time, 0.0))
        return stream.sequence < sequence <= stream.sequence + allowed

    def _from_publisher(self, uav_id: int, sequence: int | None, now: float) -> bool:
        """True if this message is from uav_id's established publisher (establishing or replacing it when
        allowed); False for an intruder's (announced once per intruder stream)."""
        if sequence is None:
            return True
        p = self.plausibility
        if uav_id == self.own_id and self.own_writer_direct:
            k = self.own_publications
            if k - p.own_echo_window < sequence <= k:
                return True
            return self._intruder(uav_id, sequence, now, "a forged echo of this controller's own zeta "
                                  f"(sequence {sequence}, own publications {k}): refused entirely")
        stream = self._streams.get(uav_id)
        if stream is None:
            self._streams[uav_id] = _Stream(sequence, now)
            return True
        if self._continues(stream, sequence, now):
            stream.sequence, stream.time = sequence, now
            return True
        silent = now - stream.time
        if silent >= p.publisher_timeout:
            self._streams[uav_id] = _Stream(sequence, now)
            self._intruders.pop(uav_id, None)
            self._announcements.append(f"zeta_{uav_id}: a new publisher (sequence {sequence}) takes over, the "
                                       f"previous one silent for {silent:.2f} s")
            return True
        return self._intruder(uav_id, sequence, now, "a second publisher claims it (sequence "
                              f"{sequence}, the established one's last {stream.sequence}): refused")

    def _intruder(self, uav_id: int, sequence: int, now: float, text: str) -> bool:
        self.intruder_messages += 1
        streams = [s for s in self._intruders.get(uav_id, []) if now - s.time < 10.0][-8:]
        self._intruders[uav_id] = streams
        for s in streams:
            if self._continues(s, sequence, now):
                s.sequence, s.time = sequence, now
                return False
        streams.append(_Stream(sequence, now))
        self._announcements.append(f"zeta_{uav_id}: {text}")
        return False

    # ---- plausibility ------------------------------------------------------------------------------
    def implausible(self, info: PeerInfo, receive_time: float) -> str | None:
        """Why ζ_j is physically implausible (alone, or as a jump from the last accepted ζ_j), or None."""
        p = self.plausibility
        if not p.leg_angle_min <= info.leg_angle <= p.leg_angle_max:
            return (f"leg angle {math.degrees(info.leg_angle):.1f} deg outside [{math.degrees(p.leg_angle_min):.0f}, "
                    f"{math.degrees(p.leg_angle_max):.0f}] deg")
        speed = norm_floats(info.velocity)
        if speed > p.max_speed:
            return f"speed {speed:.3g} m/s above {p.max_speed:g} m/s"
        if info.thrust > p.max_thrust:
            return f"thrust {info.thrust:.3g} N above {p.max_thrust:g} N"
        last = self._accepted.get(info.uav_id)
        if last is None:
            return None
        previous, then = last
        dt = max(receive_time - then, 0.0)
        jump = abs(info.leg_angle - previous.leg_angle)
        if jump > p.max_leg_rate * dt + p.leg_jump_slack:
            return f"leg angle jumps {math.degrees(jump):.1f} deg in {dt:.3f} s"
        try:
            turn = quat_angle(info.attitude, previous.attitude)
        except ValueError:
            return "attitude is a zero quaternion"
        if turn > p.max_angular_rate * dt + p.attitude_jump_slack:
            return f"attitude turns {math.degrees(turn):.1f} deg in {dt:.3f} s"
        change = norm_floats(info.velocity - previous.velocity)
        if change > p.max_acceleration * dt + p.velocity_jump_slack:
            return f"velocity jumps {change:.3g} m/s in {dt:.3f} s"
        return None

    def update(self, info: PeerInfo, receive_time: float, sequence: int | None = None,
               valid: bool = True) -> str | None:
        """Store ζ_j received at ``receive_time`` [s] with the publisher's ``sequence`` number (None: unknown).
        Returns the rejection reason (the entry is then not refreshed: it counts as missing) or None. None is also
        returned for a refused intruder's message (announced once through :meth:`take_announcements`) and for
        ``valid`` False (the sender says its estimate is stale: missing, silently); such messages are not stored.
        """
        if not 1 <= info.uav_id <= self.n:
            return f"uav_id {info.uav_id} outside 1..{self.n}"
        if not self._from_publisher(info.uav_id, sequence, receive_time) or not valid:
            return None
        problem = info.problem() or self.implausible(info, receive_time)
        if problem is not None:
            self._refused[info.uav_id] = self._refused.get(info.uav_id, 0) + 1
            return f"zeta_{info.uav_id} {problem}: counted as missing"
        refused = self._refused.pop(info.uav_id, 0)
        if refused:
            self._returns.append(f"zeta_{info.uav_id} accepted again after {refused} refused")
        self._accepted[info.uav_id] = (info, receive_time)
        if info.uav_id == self.own_id:
            self._own_echo_time = receive_time  # our own vector, echoed by the shared topic
            return None
        self._infos[info.uav_id] = info
        self._times[info.uav_id] = receive_time
        return None

    def ages(self, now: float) -> np.ndarray:
        """Age [s] of the newest ζ_j per UAV (index j − 1), own entry 0, never received = inf."""
        ages = np.full(self.n, math.inf)
        ages[self.own_id - 1] = 0.0
        for j, t in self._times.items():
            ages[j - 1] = max(now - t, 0.0)
        return ages

    def own_echo_age(self, now: float) -> float:
        """Age [s] of the last own ζ_i received back from the shared topic (inf: never)."""
        return max(now - self._own_echo_time, 0.0)

    def all_fresh(self, now: float) -> bool:
        """Every peer's ζ_j (and, with ``require_own_echo``, the own echo) is at most ``timeout`` s old (the
        :meth:`ages` of all peers ≤ timeout; a peer never received has age inf)."""
        if self.require_own_echo and self.own_echo_age(now) > self.timeout:
            return False
        return len(self._times) == self.n - 1 and all(max(now - t, 0.0) <= self.timeout
                                                      for t in self._times.values())

    def get(self, uav_id: int) -> PeerInfo | None:
        return self._infos.get(uav_id)


def flat_platform_quat(roll: float, pitch: float) -> np.ndarray:
    """Fp q_p of R = Ry(ϑ) Rx(ϕ) (thesis §4.3.1), [w, x, y, z]."""
    return euler_zyx_to_quat(roll, pitch, 0.0)


def thrust_vector(attitude: np.ndarray, thrust: float) -> np.ndarray:
    """Fp f_j = Fp R_j [0, 0, f_t,j] (4.37) [N], R_j of the normalised attitude quaternion (A.60)."""
    w, x, y, z = np.asarray(attitude, dtype=float).tolist()
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    r = rotation_entries(w / norm, x / norm, y / norm, z / norm)
    return np.array([r[2] * thrust, r[5] * thrust, r[8] * thrust])


@dataclass
class ReconstructedState:
    """q (7+n), ν (6+n) in F_Fp, the UAV velocities used (n, 3) and J(q) with J^† (the FKM's, for the rest of
    the control step)."""

    q: np.ndarray
    nu: np.ndarray
    uav_velocities: np.ndarray
    jacobian: JacobianAt


def reconstruct_state(params: FprParameters, own_id: int, local: LocalEstimate,
                      peers: dict[int, PeerInfo] | None, desired_leg_angles: np.ndarray | None = None,
                      desired_nu: np.ndarray | None = None) -> ReconstructedState:
    """(4.24) + FKM (2.21). ``peers`` None -> NC substitution (4.32) using ``desired_leg_angles`` and
    ``desired_nu`` (both required then). Raises ValueError / SingularConfigurationError on bad geometry."""
    n = params.n
    own = own_id - 1
    leg_angles = np.empty(n)
    if peers is None:
        if desired_leg_angles is None or desired_nu is None:
            raise ValueError("NC reconstruction needs the desired leg angles and velocity")
        leg_angles[:] = desired_leg_angles
    else:
        for j in range(1, n + 1):
            if j != own_id:
                leg_angles[j - 1] = peers[j].leg_angle
    leg_angles[own] = local.leg_angle
    q = np.concatenate([np.zeros(3), flat_platform_quat(local.platform_roll, local.platform_pitch), leg_angles])
    jacobian = jacobian_at(params, q)  # leg angles checked in (0, π/2]; cond(J) at the FKM
    velocities = np.empty((n, 3))
    if peers is None:
        velocities[:] = (jacobian.matrix @ desired_nu).reshape(n, 3)  # (4.32)
    else:
        for j in range(1, n + 1):
            if j != own_id:
                velocities[j - 1] = peers[j].velocity
    velocities[own] = local.velocity
    nu = jacobian.velocity(velocities.reshape(-1))  # FKM (2.21); every velocity was checked finite on receipt
    return ReconstructedState(q, nu, velocities, jacobian)
