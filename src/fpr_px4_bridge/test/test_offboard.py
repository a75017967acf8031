"""Offboard state machine with explicit time (no I/O, no sleeping)."""

import pytest
from fpr_px4_bridge.offboard import BridgeState, OffboardConfig, OffboardStateMachine, TeleopMode

from fpr_px4_bridge import px4_protocol as p

ARMED = p.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | p.MAV_MODE_FLAG_SAFETY_ARMED
DISARMED = p.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
POSCTL = p.encode_custom_mode(p.Px4MainMode.POSCTL)


def labels(decision):
    return [c.label for c in decision.commands]


def run(machine, t0, t1, fresh=True, base=None, mode=POSCTL, dt=0.02):
    """Step from t0 to t1 (exclusive) with HEARTBEATs every step; return [(t, decision)]."""
    out = []
    t = t0
    while t < t1 - 1e-9:
        if base is not None:
            machine.on_heartbeat(base, mode, t)
        out.append((t, machine.step(t, fresh)))
        t = round(t + dt, 9)
    return out


def test_starts_disconnected_then_idle_on_heartbeat():
    m = OffboardStateMachine()
    assert m.reported_state(0.0) == BridgeState.DISCONNECTED
    m.on_heartbeat(DISARMED, POSCTL, 0.0)
    d = m.step(0.0, True)
    assert m.reported_state(0.0) == BridgeState.IDLE and not d.stream and not d.commands
    assert any(e.key == "link.up" for e in d.events)
    # heartbeat_timeout (0.45 s) without any frame -> DISCONNECTED with a warning
    d = m.step(1.6, True)
    assert m.reported_state(1.6) == BridgeState.DISCONNECTED
    assert any(e.level == "warn" and e.key == "link.down" for e in d.events)
    assert m.link_age(1.6) == pytest.approx(1.6)


def test_fly_sequence_arm_warmup_then_offboard_only_after_one_second_of_stream():
    m = OffboardStateMachine(OffboardConfig(offboard_warmup=1.0))
    m.on_heartbeat(DISARMED, POSCTL, 0.0)
    m.on_teleop(TeleopMode.FLY, 0.0)
    assert m.state == BridgeState.ARMING
    d = m.step(0.0, True)
    assert labels(d) == ["ARM"] and d.stream  # arming streams already
    # ARM is retried every 0.5 s until the heartbeat says armed
    steps = run(m, 0.02, 0.6, base=DISARMED)
    assert sum(labels(d).count("ARM") for _, d in steps) == 1
    m.on_heartbeat(ARMED, POSCTL, 0.6)
    m.step(0.6, True)
    assert m.state == BridgeState.WARMUP
    steps = run(m, 0.62, 3.0, base=ARMED)
    requests = [t for t, d in steps if "OFFBOARD" in labels(d)]
    assert requests, "OFFBOARD never requested"
    # the stream has run continuously since t = 0.0 (ARMING streams)
    assert requests[0] >= 1.0
    assert all(d.stream for _, d in steps)
    # PX4 switches: OFFBOARD state
    m.on_heartbeat(ARMED, p.CUSTOM_MODE_OFFBOARD, 3.0)
    m.step(3.0, True)
    assert m.state == BridgeState.OFFBOARD and m.px4_mode.is_offboard


def test_warmup_timer_restarts_when_setpoints_go_stale():
    m = OffboardStateMachine(OffboardConfig(offboard_warmup=1.0))
    m.on_heartbeat(ARMED, POSCTL, 0.0)
    m.on_teleop(TeleopMode.FLY, 0.0)
    assert m.state == BridgeState.WARMUP
    run(m, 0.0, 0.8, base=ARMED)
    stale = run(m, 0.8, 1.0, fresh=False, base=ARMED)
    assert not any(d.stream for _, d in stale)
    steps = run(m, 1.0, 2.5, base=ARMED)
    requests = [t for t, d in steps if "OFFBOARD" in labels(d)]
    assert requests[0] >= 2.0 - 1e-9


def _flying():
    m = OffboardStateMachine(OffboardConfig(offboard_warmup=1.0))
    m.on_heartbeat(ARMED, POSCTL, 0.0)
    m.on_teleop(TeleopMode.FLY, 0.0)
    run(m, 0.0, 1.2, base=ARMED)
    m.on_heartbeat(ARMED, p.CUSTOM_MODE_OFFBOARD, 1.2)
    m.step(1.2, True)
    assert m.state == BridgeState.OFFBOARD
    return m


def test_stale_setpoints_in_offboard_stop_the_stream_and_latch_failsafe():
    m = _flying()
    d = m.step(1.3, False)
    assert not d.stream and m.state == BridgeState.FAILSAFE and m.failsafe
    assert any(e.level == "error" for e in d.events)
    # fresh setpoints again do not restart the stream while the operator keeps FLY
    assert not m.step(1.4, True).stream
    # a new FLY cycle needs a mode change
    m.on_teleop(TeleopMode.ARM, 1.5)
    assert m.state == BridgeState.WARMUP


def test_px4_leaving_offboard_or_disarming_is_failsafe():
    m = _flying()
    m.on_heartbeat(ARMED, p.encode_custom_mode(p.Px4MainMode.AUTO, p.Px4AutoSubMode.LOITER), 1.3)
    m.step(1.3, True)
    assert m.state == BridgeState.FAILSAFE
    m = _flying()
    m.on_heartbeat(DISARMED, p.CUSTOM_MODE_OFFBOARD, 1.3)
    m.step(1.3, True)
    assert m.state == BridgeState.FAILSAFE


def test_land_requests_auto_land_until_px4_confirms_then_idle_after_disarm():
    m = _flying()
    m.on_teleop(TeleopMode.LAND, 1.3)
    d = m.step(1.3, True)
    assert m.state == BridgeState.LANDING and labels(d) == ["AUTO.LAND"] and not d.stream
    cmd = d.commands[0]
    assert cmd.command == p.MAV_CMD_DO_SET_MODE and cmd.params[:3] == (1.0, 4.0, 6.0)
    m.on_heartbeat(ARMED, p.CUSTOM_MODE_AUTO_LAND, 1.4)
    assert not m.step(2.0, True).commands
    m.on_heartbeat(DISARMED, p.CUSTOM_MODE_AUTO_LAND, 5.0)
    m.step(5.0, True)
    assert m.state == BridgeState.IDLE


def test_kill_forces_disarm_until_disarmed_and_is_latched():
    m = _flying()
    m.on_teleop(TeleopMode.KILL, 1.3)
    d = m.step(1.3, True)
    assert not d.stream and m.state == BridgeState.KILLED
    assert labels(d) == ["FORCE_DISARM"]
    assert d.commands[0].params[:2] == (0.0, p.FORCE_DISARM_MAGIC)
    # retried without limit while PX4 still reports armed
    steps = run(m, 1.32, 6.0, base=ARMED)
    assert sum(labels(d).count("FORCE_DISARM") for _, d in steps) >= 9
    m.on_teleop(TeleopMode.FLY, 6.0)
    assert m.state == BridgeState.KILLED  # latched
    m.on_heartbeat(DISARMED, POSCTL, 6.1)
    assert not m.step(6.1, True).commands
    m.on_teleop(TeleopMode.IDLE, 6.2)
    assert m.state == BridgeState.IDLE


def test_kill_with_flight_termination():
    m = OffboardStateMachine(OffboardConfig(kill_flight_termination=True))
    m.on_heartbeat(ARMED, POSCTL, 0.0)
    m.on_teleop(TeleopMode.KILL, 0.0)
    assert labels(m.step(0.0, True)) == ["FORCE_DISARM", "FLIGHT_TERMINATION"]


def test_arming_gives_up_after_max_attempts_and_acks_are_logged():
    m = OffboardStateMachine(OffboardConfig(command_max_attempts=3))
    m.on_heartbeat(DISARMED, POSCTL, 0.0)
    m.on_teleop(TeleopMode.ARM, 0.0)
    m.on_command_ack(p.MAV_CMD_COMPONENT_ARM_DISARM, 2, 0.1)
    steps = run(m, 0.0, 3.0, base=DISARMED)
    assert sum(labels(d).count("ARM") for _, d in steps) == 3
    assert m.state == BridgeState.IDLE
    events = [e for _, d in steps for e in d.events]
    assert any("DENIED" in e.text for e in events)
    assert any(e.level == "error" and "arming failed" in e.text for e in events)


def test_commands_are_held_while_disconnected_and_bad_teleop_modes_ignored():
    m = OffboardStateMachine()
    m.on_teleop(TeleopMode.ARM, 0.0)
    assert not m.step(0.0, True).commands  # no heartbeat yet: nothing sent, nothing wasted
    m.on_teleop(99, 0.1)
    d = m.step(0.1, True)
    assert m.mode == TeleopMode.ARM and any(e.key == "teleop.bad" for e in d.events)


def test_config_refuses_short_warmup():
    with pytest.raises(ValueError):
        OffboardConfig(offboard_warmup=0.5)


# ---- disarming: only on the operator's explicit IDLE, never at start-up ---------------------------------------
def _all_commands(steps):
    return [label for _, d in steps for label in labels(d)]


def test_start_up_with_an_armed_px4_never_disarms_and_waits_for_the_operator():
    """A bridge (re)started while PX4 flies in OFFBOARD (hover scenario, restart in flight): IDLE, PX4's state
    reported, not one command sent, however long the operator's IDLE (the teleop default) lasts."""
    m = OffboardStateMachine(OffboardConfig(offboard_warmup=1.0))
    m.on_teleop(TeleopMode.IDLE, 0.0)  # teleop publishes IDLE from its start: a no-op
    steps = run(m, 0.0, 10.0, base=ARMED, mode=p.CUSTOM_MODE_OFFBOARD)
    for t in (2.0, 5.0):
        m.on_teleop(TeleopMode.IDLE, t)
    steps += run(m, 10.0, 12.0, base=ARMED, mode=p.CUSTOM_MODE_OFFBOARD)
    assert _all_commands(steps) == []
    assert m.state == BridgeState.IDLE and m.reported_state(12.0) == BridgeState.IDLE
    assert m.armed and m.px4_mode.is_offboard and m.custom_mode == p.CUSTOM_MODE_OFFBOARD
    warnings = [e for _, d in steps for e in d.events if e.key == "px4.armed_idle"]
    assert len(warnings) == 1 and "not disarming" in warnings[0].text and warnings[0].level == "warn"
    assert not any(d.stream for _, d in steps)
    # the operator takes over: FLY streams, and PX4 (already OFFBOARD) makes it OFFBOARD without any command
    m.on_teleop(TeleopMode.FLY, 12.0)
    steps = run(m, 12.0, 12.1, base=ARMED, mode=p.CUSTOM_MODE_OFFBOARD)
    assert m.state == BridgeState.OFFBOARD and steps[-1][1].stream
    assert _all_commands(steps) == []


def test_start_up_with_an_armed_px4_then_kill_is_the_forced_disarm():
    m = OffboardStateMachine()
    steps = run(m, 0.0, 3.0, base=ARMED)
    assert _all_commands(steps) == []
    m.on_teleop(TeleopMode.KILL, 3.0)
    assert labels(m.step(3.0, True)) == ["FORCE_DISARM"]


def test_operator_idle_after_fly_sends_plain_disarm_with_limited_attempts():
    m = _flying()
    m.on_teleop(TeleopMode.IDLE, 1.3)
    steps = run(m, 1.3, 8.0, base=ARMED, mode=p.CUSTOM_MODE_OFFBOARD)  # PX4 refuses (in the air)
    assert m.state == BridgeState.IDLE and not any(d.stream for _, d in steps)
    disarms = [d.commands[0] for _, d in steps if d.commands]
    assert len(disarms) == OffboardConfig().command_max_attempts
    assert all(c.label == "DISARM" and c.params[:2] == (0.0, 0.0) for c in disarms)  # plain, never forced
    events = [e for _, d in steps for e in d.events]
    keys = [e.key for e in events]
    assert "disarm.failed" in keys and events[keys.index("disarm.failed")].level == "error"
    # then, still armed: reported, nothing more sent (waits for the operator's LAND or KILL)
    assert "px4.armed_idle" not in keys or keys.index("px4.armed_idle") > keys.index("disarm.failed")


def test_operator_idle_disarm_stops_once_disarmed():
    m = _flying()
    m.on_teleop(TeleopMode.IDLE, 1.3)
    assert labels(m.step(1.3, True)) == ["DISARM"]
    steps = run(m, 1.32, 6.0, base=DISARMED)
    assert _all_commands(steps) == [] and m.state == BridgeState.IDLE and not m.armed


def test_operator_idle_after_arm_disarms_a_px4_that_arms_late():
    """ARM then IDLE at once: the ARM command in flight arms PX4 a moment later; the operator's IDLE wins."""
    m = OffboardStateMachine()
    m.on_heartbeat(DISARMED, POSCTL, 0.0)
    m.on_teleop(TeleopMode.ARM, 0.0)
    assert labels(m.step(0.0, True)) == ["ARM"]
    m.on_teleop(TeleopMode.IDLE, 0.1)
    steps = run(m, 0.1, 0.5, base=DISARMED)
    assert _all_commands(steps) == []
    steps = run(m, 0.5, 1.5, base=ARMED)
    assert _all_commands(steps)[:1] == ["DISARM"]


def test_idle_after_kill_or_failed_arming_sends_no_plain_disarm():
    m = OffboardStateMachine()
    m.on_heartbeat(ARMED, POSCTL, 0.0)
    m.on_teleop(TeleopMode.KILL, 0.0)
    m.step(0.0, True)
    m.on_teleop(TeleopMode.IDLE, 0.1)  # unlatch KILL (PX4 still reports armed)
    steps = run(m, 0.1, 4.0, base=ARMED)
    assert "DISARM" not in _all_commands(steps) and m.state == BridgeState.IDLE


def test_px4_silence_is_judged_on_any_frame_and_reported_within_half_a_second():
    """Telemetry at 50 Hz with HEARTBEATs at 1 Hz keeps the link up; when every frame stops, the 50 Hz step
    reports "PX4 silent" (DISCONNECTED, a warning) within 0.5 s of the last frame, and the next frame restores it."""
    m = OffboardStateMachine()
    assert m.config.heartbeat_timeout == 0.45
    m.on_frame(0.0)
    assert not m.connected(0.0)  # telemetry alone, before any HEARTBEAT: not connected yet
    events = []
    t = 0.0
    for k in range(150):  # 3 s: HEARTBEAT every second, a telemetry frame every 20 ms
        t = round(0.02 * k, 9)
        if k % 50 == 0:
            m.on_heartbeat(DISARMED, POSCTL, t)
        else:
            m.on_frame(t)
        events += m.step(t, True).events
        assert m.connected(t) and m.reported_state(t) == BridgeState.IDLE, t
    last_frame = t
    assert not any(e.key == "link.down" for e in events)
    down_at = None
    while down_at is None:
        t = round(t + 0.02, 9)
        down = [e for e in m.step(t, True).events if e.key == "link.down"]
        if down:
            down_at = t
            assert down[0].level == "warn" and "PX4 silent" in down[0].text
    assert 0.45 < down_at - last_frame <= 0.5 and m.reported_state(down_at) == BridgeState.DISCONNECTED
    assert m.link_age(down_at) == pytest.approx(down_at - last_frame)
    m.on_frame(down_at + 0.01)  # telemetry again: connected at once (the HEARTBEAT was seen before)
    assert any(e.key == "link.up" for e in m.step(down_at + 0.02, True).events)
    assert m.reported_state(down_at + 0.02) == BridgeState.IDLE
