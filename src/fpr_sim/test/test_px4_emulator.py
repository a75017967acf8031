"""PX4 emulator driven by a plain pymavlink client over UDP on 127.0.0.1. As with PX4 SITL, the emulator talks
first: it binds its own port and sends to the client's listening port; the client answers whoever it heard."""

import os
import socket
import time

import numpy as np
import pytest

os.environ["MAVLINK20"] = "1"
from fpr_model.frames import quat_enu_flu_to_ned_frd  # noqa: E402
from fpr_model.rotations import quat_error, quat_from_axis_angle, quat_multiply  # noqa: E402
from fpr_sim.px4_emulator import LOCAL_BASE_PORT, REMOTE_BASE_PORT, Px4Emulator  # noqa: E402
from fpr_sim.scenario import Px4Config, scenario_from_dict  # noqa: E402
from fpr_sim.simulation import Simulation, SimulationOptions  # noqa: E402
from pymavlink import mavutil  # noqa: E402

ARM, SET_MODE = 400, 176
OFFBOARD = 6


def _listening_client():
    """A client listening like MAVROS / MAVSDK / fpr_px4_bridge (on an ephemeral port here): pymavlink's udpin
    can only send once it heard the autopilot (it replies to the last sender)."""
    return mavutil.mavlink_connection("udpin:127.0.0.1:0", source_system=255, source_component=190)


def _simulation(scenario, client):
    """UAV 1's emulator sends to the client's port; UAVs 2 and 3 stay silent until contacted."""
    port = client.port.getsockname()[1]
    return Simulation(scenario, SimulationOptions(local_base_port=0, remote_ports=(port, 0, 0), lockstep=False))


def _connect(client, sim):
    """Advance the simulation until the client heard the emulator's HEARTBEAT, then answer with ours."""
    for _ in range(100):
        sim.advance(0.05)
        if client.recv_match(type="HEARTBEAT", blocking=True, timeout=0.05) is not None:
            client.mav.heartbeat_send(type=18, autopilot=8, base_mode=0, custom_mode=0, system_status=4)
            return client
    raise AssertionError("no HEARTBEAT from the emulator")


@pytest.fixture
def ground():
    client = _listening_client()
    sim = _simulation(scenario_from_dict({"initial_state": {"mode": "ground"}}), client)
    yield sim, client
    sim.close()
    client.close()


def _command(client, command, p1=0.0, p2=0.0, p3=0.0):
    client.mav.command_long_send(target_system=1, target_component=1, command=command, confirmation=0, param1=p1,
                                 param2=p2, param3=p3, param4=0, param5=0, param6=0, param7=0)


def _drain(client):
    """Read what is queued (a real client reads continuously; a full loopback socket drops datagrams)."""
    while client.recv_match(blocking=False) is not None:
        pass


def _ack(client, sim, command):
    for _ in range(200):
        sim.advance(0.002)
        while (msg := client.recv_match(blocking=False)) is not None:
            if msg.get_type() == "COMMAND_ACK" and msg.command == command:
                return msg.result
    raise AssertionError("no COMMAND_ACK")


def _setpoint(client, q_enu_flu=(1.0, 0.0, 0.0, 0.0), thrust=0.3, mask=7, q_raw=None):
    q = list(q_raw) if q_raw is not None else [float(v) for v in quat_enu_flu_to_ned_frd(np.array(q_enu_flu))]
    client.mav.set_attitude_target_send(time_boot_ms=0, target_system=1, target_component=1, type_mask=mask, q=q,
                                        body_roll_rate=0.0, body_pitch_rate=0.0, body_yaw_rate=0.0, thrust=thrust)


def _udp_socket(port=0):
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", port))
    sock.settimeout(2.0)
    return sock


def test_default_ports_are_px4_sitl_ones_and_the_emulator_talks_first():
    """PX4 SITL instance k: binds 14580 + k, sends to 14540 + k; then replies to whoever sent valid frames.
    (Fixed ports are safe here: the tests run in a private network namespace, scripts/run_tests.sh.)"""
    assert (LOCAL_BASE_PORT, REMOTE_BASE_PORT) == (14580, 14540)
    ground_station = _udp_socket(REMOTE_BASE_PORT + 1)  # where UAV 2's emulator sends by default
    emulator = Px4Emulator(2, Px4Config(), 0.0)
    try:
        assert emulator.port == LOCAL_BASE_PORT + 1
        assert emulator.receive_buffer > 212992  # enlarged beyond the usual kernel default (208 KiB)
        emulator.send_status(12.0, 0.9, 1.0)
        data, sender = ground_station.recvfrom(4096)
        assert sender == ("127.0.0.1", LOCAL_BASE_PORT + 1)
        mav = mavutil.mavlink.MAVLink(None)
        heartbeat = mav.parse_char(data)
        assert heartbeat.get_type() == "HEARTBEAT" and heartbeat.get_srcSystem() == 2
        # another client talks to it: replies go there from now on, not to the remote port any more
        other = _udp_socket()
        other_mav = mavutil.mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        other.sendto(other_mav.heartbeat_encode(type=6, autopilot=8, base_mode=0, custom_mode=0,
                                                system_status=4).pack(other_mav), ("127.0.0.1", emulator.port))
        for _ in range(400):  # wait for the datagram (loopback: immediate in practice)
            if emulator.poll(0.0):
                break
            time.sleep(0.005)
        assert emulator.peer == other.getsockname()
        emulator.send_status(12.0, 0.9, 1.0)
        data, sender = other.recvfrom(4096)
        assert sender[1] == emulator.port
        other.close()
    finally:
        emulator.close()
        ground_station.close()


def test_heartbeat_is_mavlink2_px4_quadrotor(ground):
    sim, client = ground
    sim.advance(0.6)  # the emulator sends from the start, before anyone talked to it
    msg = client.recv_match(type="HEARTBEAT", blocking=True, timeout=2.0)
    assert msg is not None
    assert msg.get_msgbuf()[0] == 0xFD  # MAVLink 2 frame
    assert msg.autopilot == mavutil.mavlink.MAV_AUTOPILOT_PX4
    assert msg.type == mavutil.mavlink.MAV_TYPE_QUADROTOR
    assert msg.get_srcSystem() == 1
    assert msg.base_mode & 1 and not msg.base_mode & 128
    sim.advance(0.6)
    seen = set()
    while (msg := client.recv_match(blocking=True, timeout=0.5)) is not None:
        seen.add(msg.get_type())
    assert {"ATTITUDE_QUATERNION", "ATTITUDE", "HIGHRES_IMU", "LOCAL_POSITION_NED", "SYS_STATUS",
            "BATTERY_STATUS", "HEARTBEAT"} <= seen


def test_arming_and_offboard_need_a_setpoint_stream(ground):
    ground_sim, client = ground
    _connect(client, ground_sim)
    _drain(client)
    _command(client, ARM, 1.0)
    assert _ack(client, ground_sim, ARM) != 0
    _command(client, SET_MODE, 1.0, OFFBOARD)
    assert _ack(client, ground_sim, SET_MODE) != 0
    # 0.8 s of a 5 Hz stream: still too short
    for _ in range(4):
        _setpoint(client)
        ground_sim.advance(0.2)
        _drain(client)
    _command(client, ARM, 1.0)
    assert _ack(client, ground_sim, ARM) != 0
    for _ in range(3):
        _setpoint(client)
        ground_sim.advance(0.2)
        _drain(client)
    _setpoint(client)
    _command(client, SET_MODE, 1.0, OFFBOARD)
    assert _ack(client, ground_sim, SET_MODE) == 0
    _command(client, ARM, 1.0)
    assert _ack(client, ground_sim, ARM) == 0
    emulator = ground_sim.emulators[0]
    assert emulator.armed and emulator.offboard
    ground_sim.advance(0.5)
    heartbeat = None
    while (msg := client.recv_match(type="HEARTBEAT", blocking=False)) is not None:
        heartbeat = msg
    assert heartbeat.custom_mode == 393216 and heartbeat.base_mode & 128


def test_failsafe_after_one_second_of_silence_then_land(ground):
    ground_sim, client = ground
    _connect(client, ground_sim)
    for _ in range(30):
        _setpoint(client, thrust=0.05)
        ground_sim.advance(0.05)
        _drain(client)
    _command(client, SET_MODE, 1.0, OFFBOARD)
    assert _ack(client, ground_sim, SET_MODE) == 0
    _command(client, ARM, 1.0)
    assert _ack(client, ground_sim, ARM) == 0
    emulator = ground_sim.emulators[0]
    ground_sim.advance(0.9)
    assert emulator.offboard and emulator.counters.failsafes == 0
    ground_sim.advance(0.2)
    assert not emulator.offboard and emulator.counters.failsafes == 1
    assert emulator.custom_mode == (4 << 16 | 3 << 24)  # AUTO.LOITER (hold)
    ground_sim.advance(emulator.config.failsafe_hold_time)
    assert emulator.custom_mode == (4 << 16 | 6 << 24)  # AUTO.LAND
    ground_sim.advance(emulator.config.land_disarm_delay + 0.5)
    assert not emulator.armed  # landed (it never left the ground) -> disarmed


def test_bad_input_is_ignored_and_counted(ground):
    ground_sim, client = ground
    _connect(client, ground_sim)
    emulator = ground_sim.emulators[0]
    ground_sim.advance(0.01)
    _setpoint(client, q_enu_flu=(1.0, 0.0, 0.0, 0.0), thrust=0.4)
    ground_sim.advance(0.01)
    previous = emulator.quat_local.copy()
    _setpoint(client, q_raw=[float("nan"), 0.0, 0.0, 0.0], thrust=0.5)
    _setpoint(client, q_raw=[0.5, 0.0, 0.0, 0.0], thrust=0.5)
    client.write(b"\xfd\x09\x00\x00\x00garbage-bytes-not-mavlink")
    client.write(bytes(range(60)))
    ground_sim.advance(0.01)
    assert emulator.counters.rejected_setpoints == 2
    assert emulator.counters.garbage >= 1
    assert np.allclose(emulator.quat_local, previous) and emulator.thrust == pytest.approx(0.4)
    _setpoint(client, thrust=7.0)
    ground_sim.advance(0.01)
    assert emulator.thrust == 1.0
    _setpoint(client, thrust=-3.0)
    ground_sim.advance(0.01)
    assert emulator.thrust == 0.0
    client.mav.param_request_list_send(target_system=1, target_component=1)
    ground_sim.advance(0.01)
    assert emulator.counters.ignored >= 1


def test_attitude_step_response_matches_the_p_gain_time_constant():
    scenario = scenario_from_dict({"initial_state": {"mode": "hover", "leg_angles": 0.8, "armed": True},
                                   "ground": {"enabled": False}, "plant": {"joint_offset": 0.0},
                                   "px4": {"yaw_offsets": [0.4]}})
    client = _listening_client()
    sim = _simulation(scenario, client)
    try:
        emulator = sim.emulators[0]
        hover_local, thrust = emulator.quat_local.copy(), emulator.thrust
        # the emulator's first telemetry reaches the client within the first 20 ms (hover: armed from t = 0)
        sim.advance(0.02)
        assert client.recv_match(blocking=True, timeout=2.0) is not None
        for _ in range(10):
            _setpoint(client, hover_local, thrust)
            sim.advance(0.02)
        angle = 0.1
        step_local = quat_multiply(hover_local, quat_from_axis_angle([1.0, 0.0, 0.0], angle))
        target_world = quat_multiply(np.array([np.cos(0.2), 0, 0, np.sin(0.2)]), step_local)
        start = sim.plant.fleet.quat[0].copy()
        times, errors = [], []
        for _ in range(25):  # 0.5 s, setpoint stream at 50 Hz
            _setpoint(client, step_local, thrust)
            for _ in range(20):
                sim.step()
                err = quat_error(sim.plant.fleet.quat[0], target_world)
                times.append(sim.time)
                errors.append(2.0 * np.arcsin(min(1.0, np.linalg.norm(err[1:]))))
        initial = 2.0 * np.arcsin(np.linalg.norm(quat_error(start, target_world)[1:]))
        assert initial == pytest.approx(angle, abs=0.01)
        errors = np.array(errors)
        t_step = times[0] - sim.plant.dt
        crossing = next(t for t, e in zip(times, errors, strict=True) if e <= initial * np.exp(-1.0))
        tau = 1.0 / scenario.px4.attitude_p_gain[0]
        assert (crossing - t_step) == pytest.approx(tau, rel=0.10)
        assert errors[-1] < 0.1 * initial
    finally:
        sim.close()
        client.close()
