"""Px4Bridge core over a real loopback socket, with explicit (synthetic) time: a synchronous fake PX4 peer."""

import math
import socket

import numpy as np
import pytest
from fpr_model.battery import normalized_thrust
from fpr_model.rotations import quat_from_axis_angle
from fpr_px4_bridge.bridge import BridgeConfig, Px4Bridge
from fpr_px4_bridge.link import MavlinkLink
from fpr_px4_bridge.offboard import BridgeState, OffboardConfig, TeleopMode
from fpr_px4_bridge.telemetry import BatterySample, BodyVelocitySample, ImuSample

from fpr_px4_bridge import px4_protocol as p

mavlink = p.import_mavlink()
ARMED = p.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | p.MAV_MODE_FLAG_SAFETY_ARMED
POSCTL = p.encode_custom_mode(p.Px4MainMode.POSCTL)
Q_NORTH = quat_from_axis_angle([0.0, 0.0, 1.0], math.pi / 2)


class Peer:
    """Synchronous PX4 side: sends what the test says, reads what the bridge sent."""

    def __init__(self, bridge_address):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.0)
        self.address = bridge_address
        self.mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        self.parser = mavlink.MAVLink(None)

    def send(self, msg):
        self.sock.sendto(msg.pack(self.mav), self.address)

    def heartbeat(self, base_mode, custom_mode):
        self.send(self.mav.heartbeat_encode(type=2, autopilot=12, base_mode=base_mode, custom_mode=custom_mode,
                                            system_status=4))

    def read(self):
        out = []
        while True:
            try:
                data = self.sock.recv(65535)
            except BlockingIOError:
                return out
            out.append(self.parser.decode(bytearray(data)))


@pytest.fixture
def setup():
    link = MavlinkLink("udp://127.0.0.1:0", system_id=1, target_system=1)
    config = BridgeConfig(uav_id=1, setpoint_timeout=0.2, offboard=OffboardConfig(offboard_warmup=1.0))
    bridge = Px4Bridge(config, link)
    peer = Peer(link.local_address)
    yield bridge, peer
    link.close()
    peer.sock.close()


def connect(bridge, peer, now, base=ARMED, mode=POSCTL):
    peer.heartbeat(base, mode)
    assert bridge.poll(now, timeout=1.0) == []
    assert bridge.machine.connected(now)


def fly(bridge, peer, t0, t1, dt=0.02, setpoints=True, thrust=10.0, heartbeat=(ARMED, POSCTL)):
    """Drive the bridge: heartbeat + setpoint + tick every dt; return [(t, message)] seen by the peer."""
    seen = []
    t = t0
    while t < t1 - 1e-9:
        peer.heartbeat(*heartbeat)
        bridge.poll(t, timeout=0.05)
        if setpoints:
            bridge.submit_setpoint(Q_NORTH, thrust, 1, t)
        bridge.tick(t)
        seen += [(t, m) for m in peer.read()]
        t = round(t + dt, 9)
    return seen


def kinds(seen, kind):
    return [(t, m) for t, m in seen if m.get_type() == kind]


def test_stream_rate_warmup_and_stale_stop_with_explicit_time(setup):
    bridge, peer = setup
    connect(bridge, peer, 0.0)
    bridge.on_teleop(TeleopMode.FLY, 0.0)
    seen = fly(bridge, peer, 0.0, 2.0)
    setpoints = kinds(seen, "SET_ATTITUDE_TARGET")
    # exactly one frame per 50 Hz period (each new setpoint forwarded on receipt, none repeated)
    assert len(setpoints) == 100 and bridge.repetitions_sent == 0
    assert 50.0 <= bridge.setpoint_rate(2.0) <= 51.0  # frames in the closed last second
    first = setpoints[0][0]
    requests = [t for t, m in kinds(seen, "COMMAND_LONG") if m.command == p.MAV_CMD_DO_SET_MODE]
    assert requests and requests[0] - first >= 1.0
    assert requests[0] - first <= 1.0 + 0.02 + 1e-9
    # PX4 reports OFFBOARD: the bridge follows
    seen = fly(bridge, peer, 2.0, 2.5, heartbeat=(ARMED, p.CUSTOM_MODE_OFFBOARD))
    assert bridge.state == BridgeState.OFFBOARD
    # setpoints stop arriving at t = 2.5: the stream stops within setpoint_timeout + one period
    seen = fly(bridge, peer, 2.5, 3.5, setpoints=False, heartbeat=(ARMED, p.CUSTOM_MODE_OFFBOARD))
    last = max(t for t, _ in kinds(seen, "SET_ATTITUDE_TARGET"))
    assert last <= 2.48 + 0.2 + 0.02 + 1e-9
    assert bridge.state == BridgeState.FAILSAFE and bridge.status(3.5).failsafe


def test_wire_content_is_ned_frd_attitude_and_battery_normalized_thrust(setup):
    bridge, peer = setup
    connect(bridge, peer, 0.0)
    peer.send(peer.mav.sys_status_encode(
        onboard_control_sensors_present=0, onboard_control_sensors_enabled=0, onboard_control_sensors_health=0,
        load=0, voltage_battery=11100, current_battery=-1, battery_remaining=-1, drop_rate_comm=0, errors_comm=0,
        errors_count1=0, errors_count2=0, errors_count3=0, errors_count4=0))
    samples = bridge.poll(0.01, timeout=1.0)
    assert isinstance(samples[0], BatterySample) and samples[0].voltage == pytest.approx(11.1)
    assert math.isnan(samples[0].current) and math.isnan(samples[0].remaining)
    bridge.on_teleop(TeleopMode.ARM, 0.02)
    bridge.tick(0.02)
    result = bridge.submit_setpoint(Q_NORTH, 12.0, 1, 0.03)
    assert result.accepted and result.sent
    msgs = kinds([(0, m) for m in peer.read()], "SET_ATTITUDE_TARGET")
    m = msgs[-1][1]
    np.testing.assert_allclose(m.q, [1.0, 0.0, 0.0, 0.0], atol=1e-7)  # level, facing north
    assert m.type_mask == 7 and (m.target_system, m.target_component) == (1, 1)
    assert m.thrust == pytest.approx(normalized_thrust(12.0, 11.1, 8.02, -61.66, 0.05), abs=1e-6)
    assert m.thrust == pytest.approx(12.0 / 27.362, abs=1e-6)
    # thrust clamping to [thrust_min, 1]
    assert bridge.normalized_thrust(0.0, 0.04) == pytest.approx(0.05)
    assert bridge.normalized_thrust(500.0, 0.04) == 1.0
    # without a (recent) voltage the fallback voltage is used
    assert bridge.normalized_thrust(12.0, 100.0) == pytest.approx(12.0 / (8.02 * 12.0 - 61.66))


def _report_voltage(bridge, peer, volts: float, now: float) -> None:
    peer.send(peer.mav.sys_status_encode(
        onboard_control_sensors_present=0, onboard_control_sensors_enabled=0, onboard_control_sensors_health=0,
        load=0, voltage_battery=int(round(volts * 1000)), current_battery=-1, battery_remaining=-1,
        drop_rate_comm=0, errors_comm=0, errors_count1=0, errors_count2=0, errors_count3=0, errors_count4=0))
    samples = bridge.poll(now, timeout=1.0)
    assert isinstance(samples[0], BatterySample) and samples[0].voltage == pytest.approx(volts)


def test_without_battery_compensation_the_thrust_is_normalized_at_the_nominal_voltage():
    """battery_compensation false (the first Exp. I flights, thesis §3.5.1): f_max at nominal_voltage whatever
    the reported voltage (or none, or one outside the model), so the same newtons give the same u_f as the battery
    sags; on (default), u_f follows the voltage."""
    link = MavlinkLink("udp://127.0.0.1:0", system_id=1, target_system=1)
    config = BridgeConfig(uav_id=1, battery_compensation=False, offboard=OffboardConfig(offboard_warmup=1.0))
    assert config.nominal_voltage == 12.4 and BridgeConfig().battery_compensation
    bridge = Px4Bridge(config, link)
    peer = Peer(link.local_address)
    compensated_link = MavlinkLink("udp://127.0.0.1:0", system_id=1, target_system=1)
    compensated = Px4Bridge(BridgeConfig(uav_id=1), compensated_link)
    compensated_peer = Peer(compensated_link.local_address)
    try:
        nominal = normalized_thrust(12.0, 12.4, 8.02, -61.66, 0.05)
        assert nominal == pytest.approx(12.0 / (8.02 * 12.4 - 61.66))
        assert bridge.normalized_thrust(12.0, 0.0) == nominal  # no voltage yet
        connect(bridge, peer, 0.0)
        connect(compensated, compensated_peer, 0.0)
        seen = []
        for k, volts in enumerate((12.4, 11.8, 11.1, 10.5)):
            now = 0.1 * (k + 1)
            _report_voltage(bridge, peer, volts, now)
            _report_voltage(compensated, compensated_peer, volts, now)
            assert bridge.normalized_thrust(12.0, now) == nominal
            assert compensated.normalized_thrust(12.0, now) == pytest.approx(
                normalized_thrust(12.0, volts, 8.02, -61.66, 0.05))
            seen.append(compensated.normalized_thrust(12.0, now))
        assert all(a < b for a, b in zip(seen, seen[1:], strict=False))  # compensated: more u_f as V drops
        _report_voltage(bridge, peer, 5.0, 0.5)  # outside the model: no fallback needed when off
        assert bridge.normalized_thrust(12.0, 0.5) == nominal and bridge.voltage_fallbacks == 0
        # and on the wire
        bridge.on_teleop(TeleopMode.ARM, 0.6)
        bridge.tick(0.6)
        assert bridge.submit_setpoint(Q_NORTH, 12.0, 1, 0.61).sent
        m = kinds([(0, m) for m in peer.read()], "SET_ATTITUDE_TARGET")[-1][1]
        assert m.thrust == pytest.approx(nominal, abs=1e-6)
        assert "OFF" in config.thrust_normalization() and "12.4 V" in config.thrust_normalization()
        assert "on" in BridgeConfig().thrust_normalization()
    finally:
        for closing in (link, compensated_link):
            closing.close()
        peer.sock.close()
        compensated_peer.sock.close()
    with pytest.raises(ValueError, match="nominal_voltage"):
        BridgeConfig(battery_compensation=False, nominal_voltage=7.0)  # f_max <= 0 there
    with pytest.raises(ValueError, match="nominal_voltage"):
        BridgeConfig(nominal_voltage=math.nan)


@pytest.mark.parametrize(
    "q, thrust, uav_id",
    [
        ([math.nan, 0.0, 0.0, 1.0], 10.0, 1),
        ([1.0, 0.0, math.inf, 0.0], 10.0, 1),
        ([0.5, 0.0, 0.0, 0.5], 10.0, 1),       # non-unit
        ([2.0, 0.0, 0.0, 0.0], 10.0, 1),       # non-unit
        ([1.0, 0.0, 0.0, 0.0], math.nan, 1),
        ([1.0, 0.0, 0.0, 0.0], math.inf, 1),
        ([1.0, 0.0, 0.0, 0.0], -1.0, 1),
        ([1.0, 0.0, 0.0, 0.0], 10.0, 2),       # another UAV's setpoint
        ([1.0, 0.0, 0.0, 0.0], 1e9, 1),        # finite but absurd (issue 12): above the thrust ceiling
        ([1.0, 0.0, 0.0, 0.0], 40.0, 1),       # > 1.1 x f_max 34.58 N at the 12 V fallback voltage
    ],
)
def test_bad_setpoints_are_refused_with_a_warning_and_never_forwarded(setup, q, thrust, uav_id):
    bridge, peer = setup
    connect(bridge, peer, 0.0)
    bridge.on_teleop(TeleopMode.ARM, 0.0)
    bridge.tick(0.0)
    peer.read()
    result = bridge.submit_setpoint(q, thrust, uav_id, 0.01)
    assert not result.accepted and not result.sent
    events = bridge.take_events()
    assert any(e.level == "warn" and e.key == "setpoint.refused" for e in events)
    for t in (0.02, 0.04, 0.06):
        bridge.tick(t)
    assert kinds([(0, m) for m in peer.read()], "SET_ATTITUDE_TARGET") == []
    assert bridge.status(0.06).rejected_setpoints == 1
    # a good setpoint after a bad one is streamed; the bad one never replaced it
    bridge.submit_setpoint(Q_NORTH, 10.0, 1, 0.07)
    bridge.submit_setpoint(q, thrust, uav_id, 0.08)
    bridge.tick(0.08)
    for _, m in kinds([(0, m) for m in peer.read()], "SET_ATTITUDE_TARGET"):
        assert np.isfinite(m.q).all() and np.isfinite(m.thrust)
        np.testing.assert_allclose(m.q, [1.0, 0.0, 0.0, 0.0], atol=1e-7)


def test_fuzz_10000_datagrams_into_the_bridge_socket_while_streaming(setup, corrupt_datagrams):
    bridge, peer = setup
    connect(bridge, peer, 0.0)
    bridge.on_teleop(TeleopMode.ARM, 0.0)
    fuzzer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    fuzzer.bind(("127.0.0.1", 0))
    t = 0.0
    sent_before = bridge.setpoints_sent
    datagrams = list(corrupt_datagrams(10_000, seed=11))
    try:
        for i in range(0, len(datagrams), 100):
            for data in datagrams[i:i + 100]:
                fuzzer.sendto(data, bridge.link.local_address)
            peer.heartbeat(ARMED, POSCTL)
            bridge.poll(t, timeout=0.05)
            bridge.submit_setpoint(Q_NORTH, 10.0, 1, t)
            bridge.tick(t)
            t = round(t + 0.02, 9)
        while bridge.poll(t, timeout=0.05):
            pass
    finally:
        fuzzer.close()
    c = bridge.link.counters
    assert c.rx_datagrams >= 10_000 + 100
    assert bridge.status(t).rx_garbage == c.rx_rejected > 7_000
    assert bridge.setpoints_sent - sent_before == 100  # one frame per stream period (forwarded at once)
    assert kinds([(0, m) for m in peer.read()], "SET_ATTITUDE_TARGET")
    # fuzzed frames from system 1 may look like a PX4; the peer must still be a real address, and the link alive
    assert bridge.machine.connected(t) and bridge.link.peer == peer.sock.getsockname()


def test_telemetry_is_converted_to_enu_flu(setup):
    bridge, peer = setup
    q_ned = [math.cos(0.3), 0.0, 0.0, math.sin(0.3)]  # yaw 0.6 rad in NED
    peer.send(peer.mav.highres_imu_encode(time_usec=999_000, xacc=0.5, yacc=0.25, zacc=-9.81, xgyro=0.0,
                                          ygyro=0.0, zgyro=0.0, xmag=0.0, ymag=0.0, zmag=0.0, abs_pressure=0.0,
                                          diff_pressure=0.0, pressure_alt=0.0, temperature=0.0,
                                          fields_updated=0))
    peer.send(peer.mav.attitude_quaternion_encode(time_boot_ms=1000, q1=q_ned[0], q2=q_ned[1], q3=q_ned[2],
                                                  q4=q_ned[3], rollspeed=0.1, pitchspeed=-0.2, yawspeed=0.3))
    peer.send(peer.mav.odometry_encode(time_usec=1_000_000, frame_id=1, child_frame_id=12, x=0.0, y=0.0, z=0.0,
                                       q=q_ned, vx=1.0, vy=2.0, vz=-0.5, rollspeed=0.1, pitchspeed=-0.2,
                                       yawspeed=0.3, pose_covariance=[0.0] * 21, velocity_covariance=[0.0] * 21))
    peer.send(peer.mav.local_position_ned_encode(time_boot_ms=1000, x=3.0, y=-4.0, z=-2.5, vx=1.0, vy=0.0, vz=0.0))
    samples = []
    for _ in range(20):
        samples += bridge.poll(5.0, timeout=0.2)
        if len(samples) >= 3:
            break
    imu = next(s for s in samples if isinstance(s, ImuSample))
    yaw_enu = math.pi / 2 - 0.6
    np.testing.assert_allclose(imu.orientation, [math.cos(yaw_enu / 2), 0.0, 0.0, math.sin(yaw_enu / 2)],
                               atol=1e-6)
    np.testing.assert_allclose(imu.angular_velocity, [0.1, 0.2, -0.3], atol=1e-6)
    np.testing.assert_allclose(imu.linear_acceleration, [0.5, -0.25, 9.81], atol=1e-6)
    assert imu.stamp == pytest.approx(5.0)
    odo, local = [s for s in samples if isinstance(s, BodyVelocitySample)]
    np.testing.assert_allclose(odo.linear, [1.0, -2.0, 0.5], atol=1e-6)
    # NED north velocity seen from a body yawed 0.6 rad (NED) to the right of north: FLU (cos, +sin... left<0)
    np.testing.assert_allclose(local.linear, [math.cos(0.6), math.sin(0.6), 0.0], atol=1e-6)
    position = bridge.telemetry.local_position  # the swarm guard's envelope inputs (height, geofence)
    assert (position.height, position.north, position.east, position.climb_rate) == pytest.approx((2.5, 3.0, -4.0, 0.0))


def _attitude_quaternion(peer, boot_ms):
    peer.send(peer.mav.attitude_quaternion_encode(time_boot_ms=boot_ms, q1=1.0, q2=0.0, q3=0.0, q4=0.0,
                                                  rollspeed=0.0, pitchspeed=0.0, yawspeed=0.0))


def test_set_attitude_target_carries_the_setpoint_stamp_on_px4_boot_clock_and_keeps_it_on_repeats(setup):
    """time_boot_ms = setpoint header stamp − (ROS time − PX4 boot time); the 50 Hz repetitions keep it."""
    bridge, peer = setup
    connect(bridge, peer, 100.0)
    bridge.on_teleop(TeleopMode.ARM, 100.0)  # ARMING streams (PX4 reports armed: WARMUP)
    # no telemetry yet: the offset is unknown, the former stamping ('now' since the bridge's start) is used
    assert bridge.telemetry.mapper.offset is None
    bridge.submit_setpoint(Q_NORTH, 10.0, 1, now=100.0, stamp=99.99)
    (msg,) = kinds([(0, m) for m in peer.read()], "SET_ATTITUDE_TARGET")[-1:]
    assert msg[1].time_boot_ms == 100_000  # bridge boot_time 0
    bridge.tick(100.0)  # the same 20 ms stream slot [100.00, 100.02): the next setpoint goes out in the next one
    # telemetry stamped 40.000 s on PX4's boot clock arrives at ROS time 100.002: offset 60.002 s
    _attitude_quaternion(peer, 40_000)
    bridge.poll(100.002, timeout=1.0)
    assert bridge.telemetry.mapper.offset == pytest.approx(60.002)
    result = bridge.submit_setpoint(Q_NORTH, 10.0, 1, now=100.020, stamp=100.005)
    assert result.sent
    for t in (100.04, 100.06, 100.08):  # no new setpoint: the slots ending at 100.06 and 100.08 get repetitions
        bridge.tick(t)
    frames = [m for _, m in kinds([(0, m) for m in peer.read()], "SET_ATTITUDE_TARGET")]
    assert len(frames) == 3 and {m.time_boot_ms for m in frames} == {40_003} and bridge.repetitions_sent == 2
    # zero stamp ("none"): 'now' mapped; NaN or another clock's stamp: 'now' mapped, with a warning
    for k, (stamp, warned) in enumerate(((0.0, False), (math.nan, True), (5.0, True))):
        bridge.take_events()
        now = 100.101 + 0.02 * k
        bridge.tick(now - 0.001)  # tops up the slot that ends (a repetition) and opens a fresh one
        peer.read()
        bridge.submit_setpoint(Q_NORTH, 10.0, 1, now=now, stamp=stamp)
        (frame,) = [m for _, m in kinds([(0, m) for m in peer.read()], "SET_ATTITUDE_TARGET")]
        assert frame.time_boot_ms == int(round((now - 60.002) * 1000.0))
        assert any(e.key == "setpoint.stamp" for e in bridge.take_events()) == warned
    assert bridge.stamp_fallbacks == 2


def test_any_frame_from_the_autopilot_keeps_the_link_up_other_components_do_not(setup):
    """PX4 silence (issue 13): judged on every frame from PX4's autopilot component (target system and
    component), not only HEARTBEATs; frames of another component of the vehicle (a camera) prove nothing."""
    bridge, peer = setup
    connect(bridge, peer, 0.0)
    camera = mavlink.MAVLink(None, srcSystem=1, srcComponent=100)
    for t in (0.3, 0.6, 0.9):  # telemetry from the autopilot, no HEARTBEAT after t = 0
        _attitude_quaternion(peer, int(t * 1000))
        bridge.poll(t, timeout=1.0)
        bridge.tick(t)
        assert bridge.status(t).connected
    for t in (1.2, 1.3):  # only another component talks
        peer.sock.sendto(camera.attitude_quaternion_encode(time_boot_ms=5, q1=1.0, q2=0.0, q3=0.0, q4=0.0,
                                                            rollspeed=0.0, pitchspeed=0.0, yawspeed=0.0
                                                            ).pack(camera), peer.address)
        bridge.poll(t, timeout=1.0)
    events = bridge.tick(1.36)
    status = bridge.status(1.36)
    assert not status.connected and status.state == BridgeState.DISCONNECTED
    assert status.link_age == pytest.approx(1.36 - 0.9)
    assert any(e.key == "link.down" and "PX4 silent" in e.text for e in events)


def test_thrust_ceiling_refuses_absurd_thrust_keeps_the_last_valid_setpoint_and_counts_it(setup):
    """Issue 12: thrust <= f_max (C.2, present voltage) passes as before; (f_max, 1.1 f_max] flies at 1.0 with one
    warning; above 1.1 f_max it is refused (one warning naming the ceiling), counted, the last valid setpoint
    streams until setpoint_timeout. Nothing above normalized 1.0 on the wire."""
    bridge, peer = setup
    connect(bridge, peer, 0.0)
    _report_voltage(bridge, peer, 11.1, 0.01)
    f_max, voltage = bridge.max_thrust(0.01)
    assert voltage == pytest.approx(11.1) and f_max == pytest.approx(8.02 * 11.1 - 61.66)
    bridge.on_teleop(TeleopMode.ARM, 0.02)
    bridge.tick(0.02)
    peer.read()
    assert bridge.submit_setpoint(Q_NORTH, f_max, 1, 0.03).accepted  # exactly f_max: as today
    assert bridge.take_events() == [] and bridge.thrust_saturations == 0
    saturated = bridge.submit_setpoint(Q_NORTH, 1.05 * f_max, 1, 0.05)
    assert saturated.accepted
    events = bridge.take_events()
    assert [e.key for e in events] == ["setpoint.saturated"] and "flown at full thrust" in events[0].text
    bridge.tick(0.06)
    result = bridge.submit_setpoint(Q_NORTH, 1e9, 1, 0.07)
    assert not result.accepted and "ceiling" in result.reason
    events = bridge.take_events()
    assert len(events) == 1 and events[0].key == "setpoint.refused" and "1e+09 N above the ceiling" in events[0].text
    status = bridge.status(0.07)
    assert status.thrust_refusals == 1 and status.rejected_setpoints == 1 and status.thrust_saturations == 1
    # the last valid setpoint (1.05 f_max, normalized 1.0) keeps streaming until setpoint_timeout (0.2 s)
    t = 0.08
    while t < 0.5:
        bridge.tick(t)
        t = round(t + 0.02, 9)
    frames = [m for _, m in kinds([(0, m) for m in peer.read()], "SET_ATTITUDE_TARGET")]
    assert frames and all(0.0 <= m.thrust <= 1.0 for m in frames)
    assert frames[-1].thrust == pytest.approx(1.0)
    assert not bridge.setpoint_fresh(0.5)  # 0.05 + 0.2 s: timed out, the stream stopped
    assert bridge.normalized_thrust(1e9, 0.5) == 1.0


def test_thrust_refusal_ratio_one_refuses_anything_above_f_max():
    link = MavlinkLink("udp://127.0.0.1:0", system_id=1, target_system=1)
    try:
        bridge = Px4Bridge(BridgeConfig(uav_id=1, thrust_refusal_ratio=1.0), link)
        f_max, voltage = bridge.max_thrust(0.0)
        assert voltage == 12.0 and f_max == pytest.approx(34.58)  # no telemetry: the fallback voltage
        assert bridge.submit_setpoint(Q_NORTH, f_max, 1, 0.0).accepted
        assert not bridge.submit_setpoint(Q_NORTH, f_max + 0.01, 1, 0.01).accepted
        assert bridge.thrust_refusals == 1
    finally:
        link.close()
    with pytest.raises(ValueError, match="thrust_refusal_ratio"):
        BridgeConfig(thrust_refusal_ratio=0.9)


def test_telemetry_rates_are_asked_of_px4_once_heard_one_at_a_time_acks_routed_to_them():
    """message_rates (fpr_px4_bridge.streams): nothing before the first HEARTBEAT; then one SET_MESSAGE_INTERVAL
    per entry, the next after PX4's ACK of 511; a refusal is the stream configurator's warning, not the state
    machine's; nothing is repeated once answered."""
    from fpr_px4_bridge.streams import parse_message_rates

    link = MavlinkLink("udp://127.0.0.1:0", system_id=1, target_system=1)
    config = BridgeConfig(uav_id=1, message_rates=parse_message_rates(["ATTITUDE=0", "LOCAL_POSITION_NED=50"]))
    bridge = Px4Bridge(config, link)
    peer = Peer(link.local_address)
    try:
        bridge.tick(0.0)
        assert [m for m in peer.read() if m.get_type() == "COMMAND_LONG"] == []  # PX4 not heard yet
        connect(bridge, peer, 0.02)
        bridge.tick(0.02)
        (first,) = [m for m in peer.read() if m.get_type() == "COMMAND_LONG"]
        assert (first.command, first.param1, first.param2) == (p.MAV_CMD_SET_MESSAGE_INTERVAL, 30.0, -1.0)
        assert (first.target_system, first.target_component) == (1, 1)
        bridge.tick(0.04)
        assert [m for m in peer.read() if m.get_type() == "COMMAND_LONG"] == []  # waits for the ACK
        camera = mavlink.MAVLink(None, srcSystem=1, srcComponent=100)  # another component's ACK is not PX4's
        peer.sock.sendto(camera.command_ack_encode(command=p.MAV_CMD_SET_MESSAGE_INTERVAL, result=0).pack(camera),
                         peer.address)
        bridge.poll(0.045, timeout=1.0)
        bridge.tick(0.046)
        assert [m for m in peer.read() if m.get_type() == "COMMAND_LONG"] == []
        peer.send(peer.mav.command_ack_encode(command=p.MAV_CMD_SET_MESSAGE_INTERVAL, result=0))
        bridge.poll(0.05, timeout=1.0)
        bridge.tick(0.06)
        (second,) = [m for m in peer.read() if m.get_type() == "COMMAND_LONG"]
        assert (second.param1, second.param2) == (32.0, 20000.0)
        peer.send(peer.mav.command_ack_encode(command=p.MAV_CMD_SET_MESSAGE_INTERVAL, result=2))  # DENIED
        bridge.poll(0.07, timeout=1.0)
        events = bridge.tick(0.08)
        texts = [e.text for e in events]
        assert any("PX4 did not take LOCAL_POSITION_NED 50 Hz (DENIED)" in t for t in texts), texts
        assert any(t == "PX4 telemetry: ATTITUDE off" for t in texts), texts
        assert not any("PX4 answered command 511" in t for t in texts), texts
        assert bridge.streams.done
        for t in (0.1, 0.3, 0.6, 1.0):  # nothing repeated once answered
            peer.heartbeat(ARMED, POSCTL)
            bridge.poll(t, timeout=1.0)
            bridge.tick(t)
        assert [m for m in peer.read() if m.get_type() == "COMMAND_LONG"] == []
    finally:
        link.close()
        peer.sock.close()
