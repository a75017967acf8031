"""Swarm guard (ROS-free, explicit time): when must this UAV leave its normal law for the swarm's emergency
response, and when may it rejoin (issue 12; the response itself is :mod:`fpr_px4_bridge.offboard`'s EMERGENCY
state, the design in src/fpr_px4_bridge/README.md, "Emergency response").

One guard per bridge. Causes (:class:`Cause`), judged only while this UAV flies (OFFBOARD or already in the
emergency), each with where it comes from:

OWN (this UAV is the one in trouble; said in its UavStatus so that the peers follow):
- ``setpoints``: the own controller's setpoints stale (> ``setpoint_timeout``): the controller died or hangs;
- ``estimate``: the own controller reports no valid local state (``ControllerStatus.local_state_valid`` false)
  for ``estimate_deadline``, or its status stopped for that long, after it had one: the pose estimator died or is
  blind (an estimator that has not delivered yet is the start-up, not a fault: the controller holds meanwhile);
- ``envelope`` (latched until landed: no rejoin): the UAV's height above its take-off point (PX4's local
  position) above ``max_height``; its horizontal distance from the take-off point above ``max_distance`` (a
  geofence like PX4's GF_MAX_HOR_DIST: a drifting estimate or a stuck stick must not fly the robot out of its
  flight area; set it to the area's size); its climb rate above ``max_climb_rate`` for ``envelope_time``; its tilt above
  ``max_tilt`` for ``envelope_time`` (PX4's attitude-failure detector FD_FAIL_R / FD_FAIL_P 60° with
  FD_FAIL_R_TTRI / FD_FAIL_P_TTRI 0.3 s, here as a trigger of the swarm's descent, not a flight termination);
  the **platform's** tilt, as the own controller's state has it (``ControllerStatus.platform_tilt``), above
  ``max_platform_tilt_deg`` for ``envelope_time``: the structure is out of control although every UAV may still be
  upright (an unstable law or observer: in the hardware profile an impedance + SOWO flight rolled the platform to
  50-80° and climbed 2.4 m for 8 s before a UAV's own tilt reached 60°). The default 45° is 1.5× the largest
  platform tilt an operator may command (the controller's ``command_max_tilt_deg`` 30°). A NaN tilt (no state)
  neither starts nor ends the count: a lost estimate is the ``estimate`` cause.

PEER (another UAV is lost; this one follows):
- a peer's UavStatus says it is in an emergency of its OWN (a peer's emergency that is itself only a PEER one is
  not followed: no echo, so the swarm can clear once the root cause clears);
- a peer's bridge reports FAILSAFE, KILLED or DISCONNECTED (its PX4 silent) while this UAV flies (DISCONNECTED only
  once that bridge had its link up: before, it is still starting — a hover start saw a peer's first status, sent
  before its first HEARTBEAT, as a lost PX4, and the rejoin that followed made the real fault 10 s later a
  "repeated" one that landed two UAVs while the third held: 37° of tilt);
- a peer's UavStatus older than ``peer_status_deadline`` while its ζ still arrives: its bridge died;
- a peer with neither UavStatus nor ζ for ``peer_silence_deadline``: the peer, or the link to it, is lost. This
  deadline is deliberately longer than the outages the NC fallback (4.32) is there to ride out (thesis §4.3.2;
  the comm_loss experiment drops every ζ for 3 s and must keep flying).

A peer counts only once it has been heard from (a graph still starting has no peers yet). The guard only
reports; :meth:`SwarmGuard.evaluate` returns the present :class:`Verdict`.

Together (the structure holds only if the UAVs change their law together; fault matrix, bridge restarted after
2 s): a peer landing in its emergency response (its PX4 in AUTO.LAND) makes every UAV in the emergency land at
once (``Verdict.peer_landing``: one UAV holding while two landed tilted the platform to 50°); a UAV rejoins only
when every peer with a fresh status is ready to fly OFFBOARD or flies it (``Verdict.waiting``, from
UavStatus.ready: a restarted bridge warms its stream up first; two UAVs flying the law 0.5 s before the third
pulled the legs up at 33°/s and lost an estimator's track), and a UAV joining the flying swarm (a restarted
bridge's WARMUP) waits while a peer is in the emergency response (``Verdict.swarm_emergency``), so the UAVs
switch to OFFBOARD within a status period of each other.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from enum import Enum

__all__ = ["Cause", "PeerState", "SwarmGuard", "SwarmGuardConfig", "Verdict"]

#: UavStatus.STATE_* values a peer reports when it is lost for the swarm
_PEER_LOST_STATES = {0: "DISCONNECTED (its PX4 is silent)", 6: "KILLED", 7: "FAILSAFE"}
#: UavStatus.STATE_* values in which a peer's PX4 in AUTO.LAND means the swarm lands (FAILSAFE, EMERGENCY)
_PEER_LANDING_STATES = (7, 8)
_STATE_DISCONNECTED = 0
_STATE_OFFBOARD = 4
_STATE_EMERGENCY = 8


class Cause(Enum):
    NONE = "none"
    SETPOINTS = "setpoints"
    ESTIMATE = "estimate"
    ENVELOPE = "envelope"
    PX4 = "px4"  #: PX4 left OFFBOARD on its own (its failsafe): judged by the state machine, not the guard
    PEER = "peer"
    #: an emergency again soon after a rejoin (a flapping cause): judged by the state machine; latched, own, so the
    #: whole swarm lands instead of cycling Hold / OFFBOARD
    REPEATED = "repeated"


@dataclass(frozen=True)
class SwarmGuardConfig:
    enabled: bool = True
    uav_id: int = 1
    estimate_deadline: float = 0.15      #: [s] own controller without a valid local state this long -> OWN
    peer_status_deadline: float = 0.5    #: [s] a peer's UavStatus this old while its ζ arrives -> PEER
    peer_silence_deadline: float = 5.0   #: [s] neither UavStatus nor ζ from a peer this long -> PEER
    max_height: float = 10.0             #: [m] above the take-off point (PX4 local position) -> ENVELOPE
    max_distance: float = 20.0           #: [m] horizontally from the take-off point (PX4 local position) -> ENVELOPE
    max_climb_rate: float = 2.0          #: [m/s] upwards, for envelope_time -> ENVELOPE
    max_tilt_deg: float = 60.0           #: [°] UAV tilt for envelope_time (PX4 FD_FAIL_R / FD_FAIL_P) -> ENVELOPE
    #: [°] platform tilt (own controller's state) for envelope_time -> ENVELOPE (1.5× command_max_tilt_deg 30°)
    max_platform_tilt_deg: float = 45.0
    envelope_time: float = 0.3           #: [s] (PX4 FD_FAIL_R_TTRI / FD_FAIL_P_TTRI)

    def __post_init__(self) -> None:
        for name in ("estimate_deadline", "peer_status_deadline", "peer_silence_deadline", "max_height",
                     "max_distance", "max_climb_rate", "envelope_time"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"swarm guard: {name} must be finite and > 0, got {value}")
        for name in ("max_tilt_deg", "max_platform_tilt_deg"):
            value = getattr(self, name)
            if not 0.0 < value < 180.0:  # NaN fails too
                raise ValueError(f"swarm guard: {name} must be in (0, 180), got {value}")


@dataclass(frozen=True)
class Verdict:
    cause: Cause
    reason: str = ""     #: one line, for the log and UavStatus.emergency_reason
    latched: bool = False  #: no rejoin (envelope): the swarm lands
    #: a peer lands in the emergency response (its PX4 in AUTO.LAND): land now with it, whatever the hold time
    peer_landing: str = ""
    #: rejoin together: a peer is not ready to fly OFFBOARD yet (e.g. its bridge restarts): wait for it
    waiting: str = ""
    #: a peer is in the emergency response: a UAV joining the flying swarm (WARMUP) waits for it
    swarm_emergency: str = ""

    @property
    def emergency(self) -> bool:
        return self.cause is not Cause.NONE

    @property
    def own(self) -> bool:
        return self.cause in (Cause.SETPOINTS, Cause.ESTIMATE, Cause.ENVELOPE, Cause.PX4, Cause.REPEATED)


@dataclass
class PeerState:
    status_time: float | None = None
    info_time: float | None = None
    state: int = 1
    emergency_own: bool = False
    reason: str = ""
    mode_name: str = ""  #: its PX4's mode, as its bridge reports it ("AUTO.LAND", ...)
    ready: bool = False  #: it could fly OFFBOARD at once (UavStatus.ready)
    emergency_landing: bool = False  #: its emergency response lands (UavStatus.emergency_landing)
    linked: bool = False  #: it has reported its PX4 link up once (before, DISCONNECTED is its start-up)


class SwarmGuard:
    """See the module doc. Feed it with the ``on_*`` methods (times [s] on the node clock), then ask
    :meth:`evaluate`."""

    def __init__(self, config: SwarmGuardConfig) -> None:
        self.config = config
        self.peers: dict[int, PeerState] = {}
        self._estimate_valid_time: float | None = None  #: last own controller status with a valid local state
        self._own_status_time = -math.inf  #: last own controller status, valid or not
        self._height: float | None = None
        self._takeoff_height: float | None = None
        self._horizontal: tuple[float, float] | None = None  #: [m] PX4's local north, east
        self._takeoff_horizontal: tuple[float, float] | None = None
        self._climb_since: float | None = None
        self._tilt_since: float | None = None
        self._platform_tilt_since: float | None = None  #: [s] the own controller's platform tilt above the envelope
        self._latched: Verdict | None = None

    # ---- inputs ----------------------------------------------------------------------------------------------
    def _peer(self, uav_id: int) -> PeerState | None:
        if int(uav_id) == self.config.uav_id or not 1 <= int(uav_id) <= 255:
            return None
        return self.peers.setdefault(int(uav_id), PeerState())

    def on_peer_status(self, uav_id: int, state: int, emergency_own: bool, reason: str, now: float,
                       mode_name: str = "", ready: bool = False, emergency_landing: bool = False) -> None:
        peer = self._peer(uav_id)
        if peer is not None:
            peer.status_time, peer.state, peer.emergency_own, peer.reason = now, int(state), bool(emergency_own), \
                str(reason)
            peer.mode_name, peer.ready, peer.emergency_landing = str(mode_name), bool(ready), bool(emergency_landing)
            peer.linked = peer.linked or int(state) != _STATE_DISCONNECTED

    def on_info(self, uav_id: int, now: float) -> None:
        """A ζ from ``uav_id`` (valid or not: it proves the peer's controller alive)."""
        peer = self._peer(uav_id)
        if peer is not None:
            peer.info_time = now

    def on_own_controller_status(self, local_state_valid: bool, now: float, platform_tilt: float = math.nan) -> None:
        """The own controller's status: whether its state is valid, and the platform's tilt [rad] in that state
        (NaN: unknown, the count of the platform envelope is left as it is)."""
        self._own_status_time = now
        if local_state_valid:
            self._estimate_valid_time = now
        if math.isfinite(platform_tilt):
            above = math.degrees(platform_tilt) > self.config.max_platform_tilt_deg
            self._platform_tilt_since = (self._platform_tilt_since if self._platform_tilt_since is not None
                                         else now) if above else None

    def on_local_position(self, height: float, climb_rate: float, tilt_deg: float, armed: bool, landed: bool,
                          now: float, north: float = math.nan, east: float = math.nan) -> None:
        """PX4's local position (height [m] up, climb rate [m/s] up, north and east [m]: NaN unknown, the
        geofence then keeps its last ones) and the UAV's tilt [°]."""
        cfg = self.config
        if not all(math.isfinite(v) for v in (height, climb_rate, tilt_deg)):
            return
        self._height = height
        if landed or not armed or self._takeoff_height is None:
            self._takeoff_height = height  # on the ground (or first seen in the air): the reference height
        if math.isfinite(north) and math.isfinite(east):
            self._horizontal = (north, east)
            if landed or not armed or self._takeoff_horizontal is None:
                self._takeoff_horizontal = self._horizontal
        self._climb_since = (self._climb_since if self._climb_since is not None else now) \
            if climb_rate > cfg.max_climb_rate else None
        self._tilt_since = (self._tilt_since if self._tilt_since is not None else now) \
            if tilt_deg > cfg.max_tilt_deg else None

    def reset_latch(self) -> None:
        """Landed and disarmed (or the operator took over): a latched envelope verdict ends."""
        self._latched = None

    # ---- verdict ---------------------------------------------------------------------------------------------
    def _envelope(self, now: float) -> str:
        cfg = self.config
        if self._height is not None and self._takeoff_height is not None and \
                self._height - self._takeoff_height > cfg.max_height:
            height = self._height - self._takeoff_height
            return f"height {height:.1f} m above take-off > max_height {cfg.max_height:g} m"
        if self._horizontal is not None and self._takeoff_horizontal is not None:
            distance = math.dist(self._horizontal, self._takeoff_horizontal)
            if distance > cfg.max_distance:
                return f"{distance:.1f} m from the take-off point > max_distance {cfg.max_distance:g} m (geofence)"
        if self._climb_since is not None and now - self._climb_since >= cfg.envelope_time:
            return f"climbing faster than max_climb_rate {cfg.max_climb_rate:g} m/s for {cfg.envelope_time:g} s"
        if self._tilt_since is not None and now - self._tilt_since >= cfg.envelope_time:
            return (f"tilt above max_tilt {cfg.max_tilt_deg:g}° for {cfg.envelope_time:g} s (attitude failure, "
                    "PX4 FD_FAIL_R/P)")
        if self._platform_tilt_since is not None and now - self._platform_tilt_since >= cfg.envelope_time:
            return (f"platform tilt above max_platform_tilt {cfg.max_platform_tilt_deg:g}° for {cfg.envelope_time:g} "
                    "s (the structure is out of control)")
        return ""

    def evaluate(self, now: float, setpoints_fresh: bool, flying: bool) -> Verdict:
        """The verdict at ``now``; ``setpoints_fresh``: the own controller's setpoints are fresh; ``flying``:
        this UAV is in OFFBOARD or in the emergency response (nothing is judged on the ground or before FLY).
        With fresh peer statuses the verdict also says (module doc, "Together"): ``peer_landing`` a peer already
        lands in its emergency response; ``waiting`` a peer is not ready to fly
        OFFBOARD; ``swarm_emergency`` a peer is in the emergency response."""
        verdict = self._evaluate(now, setpoints_fresh, flying)
        if not self.config.enabled:
            return verdict
        landing, waiting, emergency = "", "", ""
        for uav_id in sorted(self.peers):
            peer = self.peers[uav_id]
            if peer.status_time is None or now - peer.status_time > self.config.peer_status_deadline:
                continue  # a stale peer is judged by _evaluate's causes
            if not landing and (peer.emergency_landing or (peer.mode_name == "AUTO.LAND"
                                                           and peer.state in _PEER_LANDING_STATES)):
                landing = f"uav{uav_id} lands in the emergency response"
            if not waiting and not peer.ready and peer.state != _STATE_OFFBOARD:
                waiting = f"uav{uav_id} not ready to rejoin (state {peer.state})"
            if not emergency and peer.state == _STATE_EMERGENCY:
                emergency = f"uav{uav_id} in the emergency response"
        return replace(verdict, peer_landing=landing, waiting=waiting, swarm_emergency=emergency)

    def _evaluate(self, now: float, setpoints_fresh: bool, flying: bool) -> Verdict:
        cfg = self.config
        if not cfg.enabled:
            return Verdict(Cause.NONE)
        if self._latched is not None:
            return self._latched
        if not flying:
            return Verdict(Cause.NONE)
        envelope = self._envelope(now)
        if envelope:
            self._latched = Verdict(Cause.ENVELOPE, envelope, latched=True)
            return self._latched
        if not setpoints_fresh:
            return Verdict(Cause.SETPOINTS, "own controller's setpoints stale (controller dead or hung)")
        last_valid = self._estimate_valid_time
        if last_valid is not None and now - last_valid > cfg.estimate_deadline:
            status_age = now - self._own_status_time
            if status_age > cfg.estimate_deadline:  # no status at all: the controller, not the estimator
                return Verdict(Cause.ESTIMATE, f"own controller silent for {status_age:.2f} s (controller dead or "
                                               "hung)")
            return Verdict(Cause.ESTIMATE, f"own controller without a valid local state for {now - last_valid:.2f} "
                                           "s (pose estimator, or the motion capture of a ground-truth mode, "
                                           "dead or blind)")
        for uav_id in sorted(self.peers):
            peer = self.peers[uav_id]
            reason = self._peer_reason(uav_id, peer, now)
            if reason:
                return Verdict(Cause.PEER, reason)
        return Verdict(Cause.NONE)

    def _peer_reason(self, uav_id: int, peer: PeerState, now: float) -> str:
        cfg = self.config
        status_age = math.inf if peer.status_time is None else now - peer.status_time
        info_age = math.inf if peer.info_time is None else now - peer.info_time
        if peer.status_time is None and peer.info_time is None:
            return ""  # never heard from: not (yet) part of the swarm
        if status_age <= cfg.peer_status_deadline:
            if peer.emergency_own:
                return f"uav{uav_id} in an emergency: {peer.reason or 'no reason given'}"
            if peer.state in _PEER_LOST_STATES and (peer.linked or peer.state != _STATE_DISCONNECTED):
                return f"uav{uav_id}'s bridge reports {_PEER_LOST_STATES[peer.state]}"
            return ""
        if peer.status_time is not None and info_age <= cfg.peer_status_deadline:
            return f"uav{uav_id}'s bridge silent for {status_age:.2f} s while its zeta arrives (bridge dead)"
        if min(status_age, info_age) > cfg.peer_silence_deadline:
            return (f"uav{uav_id} silent for {min(status_age, info_age):.1f} s (no status, no zeta; "
                    f"peer_silence_deadline {cfg.peer_silence_deadline:g} s)")
        return ""
