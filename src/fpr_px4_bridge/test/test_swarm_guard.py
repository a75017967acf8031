"""Swarm guard and the EMERGENCY state (issue 12), explicit time, no I/O."""

import math
from dataclasses import replace

import pytest
from fpr_px4_bridge.offboard import BridgeState, OffboardConfig, OffboardStateMachine, TeleopMode
from fpr_px4_bridge.swarm_guard import Cause, SwarmGuard, SwarmGuardConfig, Verdict

from fpr_px4_bridge import px4_protocol as p

ARMED = p.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | p.MAV_MODE_FLAG_SAFETY_ARMED
DISARMED = p.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
OFFBOARD = p.encode_custom_mode(p.Px4MainMode.OFFBOARD)
HOLD = p.encode_custom_mode(p.Px4MainMode.AUTO, p.Px4AutoSubMode.LOITER)
LAND = p.encode_custom_mode(p.Px4MainMode.AUTO, p.Px4AutoSubMode.LAND)
NONE = Verdict(Cause.NONE)
PEER = Verdict(Cause.PEER, "uav2 in an emergency: own controller's setpoints stale")
OWN = Verdict(Cause.SETPOINTS, "own controller's setpoints stale")


def healthy_guard(now: float = 0.0) -> SwarmGuard:
    guard = SwarmGuard(SwarmGuardConfig(uav_id=1))
    for j in (2, 3):
        guard.on_peer_status(j, 4, False, "", now)
        guard.on_info(j, now)
    guard.on_own_controller_status(True, now)
    return guard


def own_controller_fine(guard: SwarmGuard, t: float) -> None:
    guard.on_own_controller_status(True, t)


def test_guard_is_quiet_while_everything_is_fresh_and_off_the_ground():
    guard = healthy_guard()
    assert guard.evaluate(0.1, setpoints_fresh=True, flying=True) == NONE
    # on the ground / before FLY nothing is judged, however stale
    assert guard.evaluate(100.0, setpoints_fresh=False, flying=False) == NONE
    assert not SwarmGuard(SwarmGuardConfig(enabled=False)).evaluate(0.0, False, True).emergency


def test_own_causes_setpoints_then_estimate():
    guard = healthy_guard()
    verdict = guard.evaluate(0.1, setpoints_fresh=False, flying=True)
    assert verdict.cause is Cause.SETPOINTS and verdict.own and "controller" in verdict.reason
    guard.on_own_controller_status(False, 0.1)  # the estimator died: no valid local state since 0.0
    deadline = guard.config.estimate_deadline
    assert guard.evaluate(deadline - 0.01, True, True) == NONE  # within estimate_deadline
    verdict = guard.evaluate(deadline + 0.01, True, True)
    assert verdict.cause is Cause.ESTIMATE and verdict.own and "estimator" in verdict.reason
    # a controller whose status stopped altogether is named as such (not its estimator)
    assert "controller silent" in guard.evaluate(0.1 + deadline + 0.01, True, True).reason
    guard.on_own_controller_status(True, 0.4)
    assert guard.evaluate(0.41, True, True) == NONE


def test_a_peer_own_emergency_is_followed_but_a_peer_following_is_not_echoed():
    guard = healthy_guard()
    guard.on_peer_status(2, 8, True, "own controller's setpoints stale", 0.1)
    verdict = guard.evaluate(0.15, True, True)
    assert verdict.cause is Cause.PEER and not verdict.own and "uav2" in verdict.reason
    guard.on_peer_status(2, 8, False, "following uav3", 0.2)  # uav2 only follows: no echo back
    own_controller_fine(guard, 0.2)
    verdict = guard.evaluate(0.25, True, True)
    assert verdict.cause is Cause.NONE
    # ... but it is in the emergency response and not ready: a rejoin waits for it, a joining UAV too
    assert "uav2" in verdict.waiting and "uav2" in verdict.swarm_emergency and not verdict.peer_landing
    guard.on_peer_status(2, 8, False, "following uav3", 0.3, mode_name="AUTO.LOITER", ready=True)
    verdict = guard.evaluate(0.35, True, True)
    assert verdict.waiting == "" and "uav2" in verdict.swarm_emergency


def test_a_peer_landing_in_its_emergency_is_said_to_every_verdict():
    """Everybody lands together (bridge restarted, seed 0: two UAVs landing while the third held, 50° tilt)."""
    guard = healthy_guard()
    guard.on_peer_status(3, 8, True, "own controller silent, again after a rejoin", 0.1, mode_name="AUTO.LAND")
    verdict = guard.evaluate(0.15, True, True)
    assert verdict.emergency and verdict.peer_landing == "uav3 lands in the emergency response"
    # the operator's LAND (state LANDING) is not an emergency landing: every bridge gets LAND from the teleop
    guard = healthy_guard()
    guard.on_peer_status(3, 5, False, "", 0.1, mode_name="AUTO.LAND")
    assert guard.evaluate(0.15, True, True).peer_landing == ""
    # a stale status says nothing (the stale peer is a cause of its own)
    guard = healthy_guard()
    guard.on_peer_status(3, 8, True, "x", 0.1, mode_name="AUTO.LAND")
    assert guard.evaluate(0.1 + guard.config.peer_status_deadline + 0.01, True, True).peer_landing == ""


def test_rejoin_waits_for_peers_that_are_not_ready_and_flying_peers_count_as_ready():
    guard = healthy_guard()
    guard.on_peer_status(2, 3, False, "", 0.1, mode_name="AUTO.LOITER", ready=False)  # a restarted bridge warming up
    guard.on_peer_status(3, 4, False, "", 0.1, mode_name="OFFBOARD", ready=False)
    verdict = guard.evaluate(0.15, True, True)
    assert verdict.cause is Cause.NONE and verdict.waiting == "uav2 not ready to rejoin (state 3)"
    guard.on_peer_status(2, 3, False, "", 0.2, mode_name="AUTO.LOITER", ready=True)
    assert guard.evaluate(0.25, True, True).waiting == ""


@pytest.mark.parametrize("state, word", [(0, "DISCONNECTED"), (6, "KILLED"), (7, "FAILSAFE")])
def test_a_peer_bridge_reporting_a_lost_state_is_followed(state, word):
    guard = healthy_guard()
    guard.on_peer_status(3, state, False, "", 0.1)
    verdict = guard.evaluate(0.15, True, True)
    assert verdict.cause is Cause.PEER and "uav3" in verdict.reason and word in verdict.reason


def test_a_dead_peer_bridge_is_its_status_stale_while_its_zeta_arrives():
    guard = healthy_guard()
    for k in range(1, 16):  # uav2's controller keeps publishing zeta, its bridge's status stopped at 0.0
        t = 0.1 * k
        guard.on_info(2, t)
        guard.on_info(3, t)
        guard.on_peer_status(3, 4, False, "", t)
        own_controller_fine(guard, t)
        verdict = guard.evaluate(t, True, True)
        if t <= guard.config.peer_status_deadline + 1e-9:
            assert verdict == NONE, t
        else:
            assert verdict.cause is Cause.PEER and "uav2's bridge silent" in verdict.reason, t


def test_a_link_outage_shorter_than_the_silence_deadline_is_left_to_the_nc_fallback():
    """comm_loss: every zeta dropped for 3 s (statuses fresh) must not start an emergency; a peer silent on both
    for longer than peer_silence_deadline (5 s) does."""
    guard = healthy_guard()
    for k in range(1, 31):  # zeta gone for 3 s, statuses fresh
        t = 0.1 * k
        for j in (2, 3):
            guard.on_peer_status(j, 4, False, "", t)
        own_controller_fine(guard, t)
        assert guard.evaluate(t, True, True) == NONE, t
    verdicts = []
    for k in range(1, 60):  # now both silent
        own_controller_fine(guard, 3.0 + 0.1 * k)
        verdicts.append(guard.evaluate(3.0 + 0.1 * k, True, True))
    first = next(k for k, v in enumerate(verdicts, 1) if v.emergency)
    assert 3.0 + 0.1 * first == pytest.approx(3.0 + 5.0 + 0.1, abs=0.11)  # 5 s after the last status (3.0)
    assert "silent for" in verdicts[first - 1].reason


def test_a_peer_never_heard_from_is_not_part_of_the_swarm():
    guard = SwarmGuard(SwarmGuardConfig(uav_id=1))
    assert guard.evaluate(60.0, True, True) == NONE


def test_envelope_climb_rate_tilt_and_height_latch_until_disarmed():
    cfg = SwarmGuardConfig(uav_id=1)
    guard = SwarmGuard(SwarmGuardConfig(uav_id=1))  # no peers, no own controller status: envelope alone
    guard.on_local_position(0.0, 0.0, 0.0, armed=False, landed=True, now=0.0)  # take-off point: height 0
    guard.on_local_position(1.0, 2.5, 5.0, armed=True, landed=False, now=1.0)  # climbing 2.5 m/s
    assert guard.evaluate(1.0 + cfg.envelope_time - 0.01, True, True) == NONE  # not for envelope_time yet
    guard.on_local_position(1.7, 2.5, 5.0, armed=True, landed=False, now=1.0 + cfg.envelope_time)
    verdict = guard.evaluate(1.0 + cfg.envelope_time, True, True)
    assert verdict.cause is Cause.ENVELOPE and verdict.latched and "climbing" in verdict.reason
    guard.on_local_position(1.7, 0.0, 5.0, armed=True, landed=False, now=2.0)  # climb over: still latched
    assert guard.evaluate(2.0, True, True) == verdict
    guard.reset_latch()
    assert guard.evaluate(2.1, True, True) == NONE
    guard.on_local_position(2.0, 0.0, 70.0, armed=True, landed=False, now=3.0)  # attitude failure
    guard.on_local_position(2.0, 0.0, 70.0, armed=True, landed=False, now=3.35)
    assert "tilt" in guard.evaluate(3.35, True, True).reason
    guard.reset_latch()
    guard.on_local_position(12.0, 0.0, 0.0, armed=True, landed=False, now=4.0)  # above max_height (10 m)
    assert "height" in guard.evaluate(4.0, True, True).reason
    guard.on_local_position(math.nan, 0.0, 0.0, armed=True, landed=False, now=5.0)  # NaN: ignored, no crash


def test_geofence_from_the_take_off_point_latches_and_ignores_an_unknown_position():
    cfg = SwarmGuardConfig(uav_id=1, max_distance=5.0)
    guard = SwarmGuard(cfg)
    guard.on_local_position(0.0, 0.0, 0.0, armed=False, landed=True, now=0.0, north=10.0, east=-3.0)  # take-off
    guard.on_local_position(1.0, 0.0, 0.0, armed=True, landed=False, now=1.0, north=13.0, east=0.9)  # 4.9 m
    assert guard.evaluate(1.0, True, True) == NONE
    guard.on_local_position(1.0, 0.0, 0.0, armed=True, landed=False, now=2.0, north=math.nan, east=0.0)  # unknown
    assert guard.evaluate(2.0, True, True) == NONE
    guard.on_local_position(1.0, 0.0, 0.0, armed=True, landed=False, now=3.0, north=14.0, east=0.1)  # 5.1 m
    verdict = guard.evaluate(3.0, True, True)
    assert verdict.cause is Cause.ENVELOPE and verdict.latched and "geofence" in verdict.reason
    assert "5.1 m" in verdict.reason and "max_distance 5 m" in verdict.reason
    guard.on_local_position(1.0, 0.0, 0.0, armed=True, landed=False, now=4.0, north=10.0, east=-3.0)  # back
    assert guard.evaluate(4.0, True, True) == verdict  # latched until landed
    # first seen in the air (a hover start): that point is the reference
    airborne = SwarmGuard(cfg)
    airborne.on_local_position(1.5, 0.0, 0.0, armed=True, landed=False, now=0.0, north=-7.0, east=2.0)
    airborne.on_local_position(1.5, 0.0, 0.0, armed=True, landed=False, now=1.0, north=-3.0, east=2.0)
    assert airborne.evaluate(1.0, True, True) == NONE
    with pytest.raises(ValueError, match="max_distance"):
        SwarmGuardConfig(max_distance=0.0)


def test_platform_envelope_latches_on_a_sustained_platform_tilt_only():
    """The own controller's platform tilt above max_platform_tilt_deg for envelope_time is an own, latched ENVELOPE
    verdict; a brief excess, a tilt below the limit and a NaN tilt (no state) are not."""
    guard = healthy_guard()
    cfg = guard.config
    limit = math.radians(cfg.max_platform_tilt_deg)
    for k in range(20):  # 50 Hz below the limit: nothing
        guard.on_own_controller_status(True, 0.02 * k, limit - 0.01)
        assert guard.evaluate(0.02 * k, True, True) == NONE
    guard.on_own_controller_status(True, 0.4, limit + 0.01)  # above for less than envelope_time, then back
    guard.on_own_controller_status(True, 0.4 + cfg.envelope_time - 0.02, limit + 0.01)
    assert guard.evaluate(0.4 + cfg.envelope_time - 0.02, True, True) == NONE
    guard.on_own_controller_status(True, 0.4 + cfg.envelope_time, limit - 0.01)  # the count restarts
    assert guard.evaluate(0.4 + cfg.envelope_time + 0.1, True, True) == NONE
    start = 1.0
    guard.on_own_controller_status(True, start, limit + 0.2)
    guard.on_own_controller_status(True, start + 0.1, math.nan)  # unknown: the count goes on
    guard.on_own_controller_status(True, start + cfg.envelope_time, limit + 0.2)
    verdict = guard.evaluate(start + cfg.envelope_time, True, True)
    assert verdict.cause is Cause.ENVELOPE and verdict.latched and verdict.own
    assert "platform tilt" in verdict.reason and f"{cfg.max_platform_tilt_deg:g}" in verdict.reason
    guard.on_own_controller_status(True, 2.0, 0.0)  # level again: still latched (no rejoin)
    assert guard.evaluate(2.0, True, True) == verdict
    # a lower limit of the node's parameter applies
    strict = SwarmGuard(SwarmGuardConfig(uav_id=1, max_platform_tilt_deg=20.0))
    strict.on_own_controller_status(True, 0.0, math.radians(25.0))
    strict.on_own_controller_status(True, 0.0 + cfg.envelope_time, math.radians(25.0))
    assert strict.evaluate(cfg.envelope_time, True, True).cause is Cause.ENVELOPE
    # on the ground nothing is judged (the tilt of a robot standing on its feet is not a flight)
    grounded = SwarmGuard(SwarmGuardConfig(uav_id=1))
    grounded.on_own_controller_status(True, 0.0, 1.0)
    grounded.on_own_controller_status(True, 1.0, 1.0)
    assert grounded.evaluate(1.0, True, flying=False) == NONE


def test_guard_config_refuses_nonsense():
    with pytest.raises(ValueError, match="peer_status_deadline"):
        SwarmGuardConfig(peer_status_deadline=-1.0)
    with pytest.raises(ValueError, match="max_tilt_deg"):
        SwarmGuardConfig(max_tilt_deg=0.0)
    for bad in (0.0, 180.0, math.nan):
        with pytest.raises(ValueError, match="max_platform_tilt_deg"):
            SwarmGuardConfig(max_platform_tilt_deg=bad)


# ---- the EMERGENCY state -----------------------------------------------------------------------------------
def flying_machine(hold_time: float = 5.0) -> OffboardStateMachine:
    """A state machine in OFFBOARD (operator FLY), PX4 armed in OFFBOARD, at t = 0."""
    m = OffboardStateMachine(OffboardConfig(emergency_hold_time=hold_time, rejoin_delay=0.5))
    m.on_heartbeat(ARMED, OFFBOARD, 0.0)
    m.on_teleop(TeleopMode.FLY, 0.0)
    m.step(0.0, True, NONE)
    m.step(0.02, True, NONE)
    assert m.state == BridgeState.OFFBOARD
    return m


def labels(decision):
    return [c.label for c in decision.commands]


def test_emergency_holds_then_lands_when_the_cause_persists():
    m = flying_machine()
    m.on_heartbeat(ARMED, OFFBOARD, 1.0)
    d = m.step(1.0, False, OWN)
    assert m.state == BridgeState.EMERGENCY and labels(d) == ["AUTO.LOITER"]  # Hold at once, same tick
    assert any(e.level == "error" and "swarm emergency (own fault)" in e.text for e in d.events)
    assert not d.stream  # the controller's setpoints are stale: nothing to stream
    commands = []
    t = 1.1
    while t < 6.2:
        m.on_heartbeat(ARMED, LAND if any(c == "AUTO.LAND" for _, c in commands) else HOLD, t)
        commands += [(t, c) for c in labels(m.step(t, False, OWN))]
        t = round(t + 0.02, 9)
    land = [t for t, c in commands if c == "AUTO.LAND"]
    assert land and land[0] == pytest.approx(6.0, abs=0.021)  # emergency_hold_time after the entry
    assert "AUTO.LOITER" not in [c for _, c in commands]  # PX4 in Hold: not asked again
    m.on_heartbeat(DISARMED, LAND, 9.0)
    m.step(9.0, False, OWN)
    assert m.state == BridgeState.IDLE and m.emergency is None


def test_emergency_rejoins_once_the_cause_stays_clear():
    m = flying_machine()
    m.step(1.0, True, PEER)
    assert m.state == BridgeState.EMERGENCY and m.emergency == PEER and not m.emergency.own
    m.on_heartbeat(ARMED, HOLD, 1.05)
    d = m.step(1.1, True, PEER)
    assert d.stream  # the healthy controller's stream goes on (PX4 ignores it in Hold; OFFBOARD resumes at once)
    for t in (1.5, 2.0):
        m.on_heartbeat(ARMED, HOLD, t)
        m.step(t, True, PEER if t < 2.0 else NONE)  # clear from 2.0
    m.on_heartbeat(ARMED, HOLD, 2.4)
    m.step(2.4, True, NONE)
    assert m.state == BridgeState.EMERGENCY  # not yet rejoin_delay
    d = m.step(2.52, True, NONE)
    assert m.state == BridgeState.WARMUP and any("rejoining" in e.text for e in d.events)
    d = m.step(2.54, True, NONE)
    assert "OFFBOARD" in labels(d)  # the stream has run > offboard_warmup: OFFBOARD requested at once
    m.on_heartbeat(ARMED, OFFBOARD, 2.6)
    m.step(2.62, True, NONE)
    assert m.state == BridgeState.OFFBOARD


def _in_rejoin_warm_up():
    """A machine in EMERGENCY (peer) from 1.0 s, clear from 2.0 s, rejoining (WARMUP, PX4 still in Hold) at 2.6 s."""
    m = flying_machine()
    m.step(1.0, True, PEER)
    m.on_heartbeat(ARMED, HOLD, 1.05)
    m.step(2.0, True, NONE)
    m.step(2.6, True, NONE)
    assert m.state == BridgeState.WARMUP
    return m


def test_a_new_fault_during_the_rejoin_returns_to_the_emergency():
    m = _in_rejoin_warm_up()
    m.step(2.62, True, PEER)
    assert m.state == BridgeState.EMERGENCY


def test_a_fault_in_the_rejoin_warm_up_resumes_the_emergency_instead_of_landing():
    """Before PX4 flies the stream again (WARMUP, PX4 still in Hold) a new fault is not a flapping cause: the
    emergency of before goes on with its own Hold deadline, and the UAV can rejoin once it clears (fault runs: a
    restarted controller's status 0.16 s late just after the rejoin landed the swarm)."""
    m = _in_rejoin_warm_up()
    d = m.step(2.62, True, OWN)  # PX4 still in Hold
    assert m.state == BridgeState.EMERGENCY and m.emergency == OWN and m.emergency.cause is not Cause.REPEATED
    assert "AUTO.LAND" not in labels(d) and any("goes on" in e.text for e in d.events)
    m.step(2.7, True, NONE)
    d = m.step(3.25, True, NONE)  # clear for rejoin_delay: rejoins again
    assert m.state == BridgeState.WARMUP
    m.step(3.27, True, NONE)
    m.on_heartbeat(ARMED, OFFBOARD, 3.3)
    m.step(3.32, True, NONE)
    assert m.state == BridgeState.OFFBOARD


def test_a_fault_in_the_rejoin_warm_up_keeps_the_first_emergency_s_deadline():
    m = flying_machine()
    m.step(1.0, True, PEER)
    for t in (1.05, 2.0, 3.0, 4.0, 4.95):
        m.on_heartbeat(ARMED, HOLD, t)
    m.step(5.0, True, NONE)
    m.on_heartbeat(ARMED, HOLD, 5.55)
    m.step(5.6, True, NONE)
    assert m.state == BridgeState.WARMUP
    m.step(5.62, True, OWN)
    assert m.state == BridgeState.EMERGENCY
    commands = []
    t = 5.64
    while t < 6.2:
        m.on_heartbeat(ARMED, HOLD, t)
        commands += [(t, c) for c in labels(m.step(t, True, OWN))]
        t = round(t + 0.02, 9)
    land = [t for t, c in commands if c == "AUTO.LAND"]
    assert land and land[0] == pytest.approx(6.0, abs=0.021)  # 5 s after the first entry (1.0 s), not after 5.62


def test_a_fault_once_px4_flies_the_rejoin_is_a_flapping_cause():
    m = _in_rejoin_warm_up()
    m.on_heartbeat(ARMED, OFFBOARD, 2.61)  # PX4 flies the stream, the bridge has not yet confirmed it
    m.step(2.62, True, OWN)
    assert m.state == BridgeState.EMERGENCY and m.emergency.cause is Cause.REPEATED


def _rejoined(m, at: float) -> None:
    """EMERGENCY (peer) at ``at``, clear from at + 0.5, rejoined and back in OFFBOARD by at + 1.2."""
    m.step(at, True, PEER)
    m.on_heartbeat(ARMED, HOLD, at + 0.05)
    m.step(at + 0.5, True, NONE)
    m.step(at + 1.01, True, NONE)
    assert m.state == BridgeState.WARMUP
    m.step(at + 1.03, True, NONE)
    m.on_heartbeat(ARMED, OFFBOARD, at + 1.1)
    m.step(at + 1.12, True, NONE)
    assert m.state == BridgeState.OFFBOARD


def test_an_emergency_soon_after_a_rejoin_lands_the_swarm_instead_of_cycling():
    """A flapping cause (an estimator that keeps losing its track after a restart, seen in the fault runs): the
    second emergency within rejoin_window of a rejoin is latched, this UAV's own (the peers follow), AUTO.LAND now."""
    m = flying_machine()
    _rejoined(m, 1.0)
    m.on_heartbeat(ARMED, OFFBOARD, 4.0)
    d = m.step(4.0, True, PEER)
    assert m.state == BridgeState.EMERGENCY
    assert m.emergency.cause is Cause.REPEATED and m.emergency.own and m.emergency.latched
    assert "AUTO.LAND" in labels(d) and any("no more rejoins" in e.text for e in d.events)
    for t in (4.5, 5.0, 6.0):  # the cause clears: no rejoin, still landing
        m.on_heartbeat(ARMED, LAND, t)
        m.step(t, True, NONE)
        assert m.state == BridgeState.EMERGENCY and m.emergency.cause is Cause.REPEATED
    m.on_heartbeat(DISARMED, LAND, 9.0)
    m.step(9.0, True, NONE)
    assert m.state == BridgeState.IDLE


def test_an_emergency_long_after_a_rejoin_is_an_ordinary_one():
    m = flying_machine()
    _rejoined(m, 1.0)
    later = 1.0 + m.config.rejoin_window + 1.5
    m.on_heartbeat(ARMED, OFFBOARD, later)
    d = m.step(later, True, PEER)
    assert m.state == BridgeState.EMERGENCY and m.emergency == PEER and labels(d) == ["AUTO.LOITER"]


def test_px4_leaving_offboard_on_its_own_is_an_own_emergency_and_px4_landing_is_followed():
    m = flying_machine()
    m.on_heartbeat(ARMED, LAND, 1.0)  # PX4's own failsafe
    d = m.step(1.0, True, NONE)
    assert m.state == BridgeState.EMERGENCY and m.emergency.own and m.emergency.cause is Cause.PX4
    assert any("landing with it" in e.text for e in d.events)
    d = m.step(1.02, True, NONE)
    assert "AUTO.LOITER" not in labels(d)  # PX4 lands on its own: landing with it, no rejoin
    m.step(3.0, True, NONE)
    assert m.state == BridgeState.EMERGENCY


def test_the_operator_overrides_the_emergency_but_fly_or_arm_does_not_abort_it():
    m = flying_machine()
    m.step(1.0, True, PEER)
    m.on_teleop(TeleopMode.ARM, 1.1)
    m.on_teleop(TeleopMode.FLY, 1.2)
    assert m.state == BridgeState.EMERGENCY
    m.on_teleop(TeleopMode.LAND, 1.3)
    assert m.state == BridgeState.LANDING and m.emergency is None


def test_without_a_guard_the_former_failsafe_stays():
    m = flying_machine()
    m.step(1.0, False)  # no verdict: no guard
    assert m.state == BridgeState.FAILSAFE


# ---- together: land together, rejoin together (fault matrix, bridge restarted after 2 s) ------------------------
def test_a_peer_landing_in_its_emergency_makes_a_holding_uav_land_at_once():
    m = flying_machine()
    m.on_heartbeat(ARMED, OFFBOARD, 1.0)
    m.step(1.0, False, OWN)  # own fault: Hold, AUTO.LAND only after the 5 s hold
    m.on_heartbeat(ARMED, HOLD, 1.5)
    d = m.step(1.5, False, replace(OWN, peer_landing="uav3 lands in the emergency response"))
    assert "AUTO.LAND" in labels(d) and any("uav3 lands" in e.text for e in d.events)
    # and a UAV still flying OFFBOARD (a peer that only followed, then landed) joins the landing too
    m = flying_machine()
    m.on_heartbeat(ARMED, OFFBOARD, 1.0)
    d = m.step(1.0, True, replace(NONE, peer_landing="uav2 lands in the emergency response"))
    assert m.state == BridgeState.EMERGENCY and "AUTO.LAND" in labels(d)


def test_an_emergency_rejoins_only_when_every_peer_is_ready_and_lands_if_one_never_is():
    m = flying_machine(hold_time=5.0)
    m.step(1.0, True, PEER)
    m.on_heartbeat(ARMED, HOLD, 1.05)
    waiting = replace(NONE, waiting="uav2 not ready to rejoin (state 3)")
    d = m.step(1.5, True, waiting)  # the cause cleared (the restarted bridge talks), but it is still warming up
    d = m.step(2.2, True, waiting)
    assert m.state == BridgeState.EMERGENCY and any("rejoining together" in e.text for e in d.events)
    assert m.ready(2.2, True)  # this UAV itself is ready: its cause was a peer's, its stream runs
    d = m.step(2.3, True, NONE)  # uav2 ready: rejoin now (clear for > rejoin_delay)
    assert m.state == BridgeState.WARMUP
    # a peer that never gets ready: the hold time ends the wait with a landing, as a cause that persists
    m = flying_machine(hold_time=5.0)
    m.step(1.0, True, PEER)
    m.on_heartbeat(ARMED, HOLD, 1.05)
    commands = []
    for k in range(60, 320):
        t = k / 50.0
        m.on_heartbeat(ARMED, HOLD, t)
        commands += [(t, c) for c in labels(m.step(t, True, waiting))]
    land = [t for t, c in commands if c == "AUTO.LAND"]
    # the wait counts from the cause's clearing (t = 1.2): emergency_hold_time later, AUTO.LAND
    assert land and land[0] == pytest.approx(6.2, abs=0.021) and m.state == BridgeState.EMERGENCY


def test_a_uav_whose_own_stream_is_still_warming_up_waits_in_the_emergency():
    """A restarted controller: the bridge's stream restarts with it, so this UAV is not ready (offboard_warmup)
    when its cause clears; it leaves the emergency with the others once warmed up, not alone before them."""
    m = flying_machine()
    m.on_heartbeat(ARMED, OFFBOARD, 1.0)
    m.step(1.0, False, OWN)  # controller dead: stream stopped
    t = 1.0
    while t < 3.0:  # restarted at 3 s: fresh setpoints again
        t = round(t + 0.02, 9)
        m.on_heartbeat(ARMED, HOLD, t)
        m.step(t, False, OWN)
    states = []
    while t < 5.0:
        t = round(t + 0.02, 9)
        m.on_heartbeat(ARMED, HOLD, t)
        m.step(t, True, NONE)
        states.append((t, m.state))
    left = [t for t, s in states if s != BridgeState.EMERGENCY]
    assert left and left[0] >= 3.0 + m.config.offboard_warmup - 1e-9  # not before its own stream warmed up


def test_a_uav_joining_a_swarm_in_its_emergency_waits_before_offboard_and_is_ready():
    """A restarted bridge (fresh WARMUP, PX4 armed in Hold): warmed up, it requests OFFBOARD only once no peer is in
    the emergency response any more, so that the UAVs switch together; meanwhile its status says ready."""
    m = OffboardStateMachine(OffboardConfig(offboard_warmup=1.0))
    m.on_heartbeat(ARMED, HOLD, 0.0)
    m.on_teleop(TeleopMode.FLY, 0.0)
    in_emergency = replace(NONE, swarm_emergency="uav1 in the emergency response")
    commands, events = [], []
    for k in range(0, 100):
        t = k / 50.0
        m.on_heartbeat(ARMED, HOLD, t)
        d = m.step(t, True, in_emergency)
        commands += labels(d)
        events += [e.text for e in d.events]
    assert m.state == BridgeState.WARMUP and "OFFBOARD" not in commands and m.ready(1.98, True)
    assert sum("not requesting OFFBOARD" in e for e in events) == 1
    d = m.step(2.0, True, NONE)
    assert "OFFBOARD" in labels(d)


def test_own_emergency_is_reported_only_while_its_cause_holds():
    m = flying_machine()
    m.on_heartbeat(ARMED, OFFBOARD, 1.0)
    m.step(1.0, True, OWN)
    assert m.own_emergency and not m.ready(1.0, True)
    m.on_heartbeat(ARMED, HOLD, 1.2)
    m.step(1.2, True, NONE)  # cleared: the peers stop following, everybody can get ready
    assert m.state == BridgeState.EMERGENCY and not m.own_emergency and m.ready(1.2, True)


def test_a_peer_deciding_to_land_is_followed_before_its_px4_confirms():
    """UavStatus.emergency_landing: said when the bridge commands AUTO.LAND; PX4's mode in its 2 Hz HEARTBEAT came
    up to 0.5 s later, and a UAV that landed 0.5 s after the others tilted the platform to 70° (seed 4)."""
    guard = healthy_guard()
    guard.on_peer_status(2, 8, True, "again after a rejoin", 0.1, mode_name="OFFBOARD", emergency_landing=True)
    assert guard.evaluate(0.15, True, True).peer_landing == "uav2 lands in the emergency response"
    m = flying_machine()
    m.on_heartbeat(ARMED, OFFBOARD, 1.0)
    m.step(1.0, True, OWN)
    assert not m.emergency_landing
    m.step(1.0 + m.config.emergency_hold_time + 0.01, True, OWN)
    assert m.emergency_landing


def test_a_peer_still_starting_is_not_a_lost_peer():
    """A peer bridge's first statuses say DISCONNECTED until its PX4's first HEARTBEAT: not a lost PX4 (a hover start
    took it for one, fault matrix seed 4); once its link was up, DISCONNECTED is followed."""
    guard = SwarmGuard(SwarmGuardConfig(uav_id=1))
    guard.on_own_controller_status(True, 0.0)
    guard.on_info(2, 0.0)
    guard.on_peer_status(2, 0, False, "", 0.0)  # starting: PX4 not heard yet
    assert guard.evaluate(0.05, True, True).cause is Cause.NONE
    guard.on_peer_status(2, 3, False, "", 0.1)  # link up (WARMUP)
    guard.on_peer_status(2, 0, False, "", 0.2)  # then silent: lost
    guard.on_own_controller_status(True, 0.2)
    assert "DISCONNECTED" in guard.evaluate(0.25, True, True).reason
