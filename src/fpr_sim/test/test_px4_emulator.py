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


def test_default_ports_are_px4_sitl_ones_and_the_first_talker_keeps_the_link():
    """PX4 SITL instance k: binds 14580 + k, sends to 14540 + k; the first valid frame's sender becomes the link's
    partner and keeps it (PX4's UDP link); a second client gets its COMMAND_ACKs, not the streams.
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
        # the first talker (a client on its own port) becomes the partner
        first = _udp_socket()
        first_mav = mavutil.mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        first.sendto(first_mav.heartbeat_encode(type=6, autopilot=8, base_mode=0, custom_mode=0,
                                                system_status=4).pack(first_mav), ("127.0.0.1", emulator.port))
        for _ in range(400):  # wait for the datagram (loopback: immediate in practice)
            if emulator.poll(0.0):
                break
            time.sleep(0.005)
        assert emulator.peer == first.getsockname() and emulator.peer_latched
        # a second client: its command is acknowledged to it, the link stays with the first
        second = _udp_socket()
        second_mav = mavutil.mavlink.MAVLink(None, srcSystem=250, srcComponent=1)
        second.sendto(second_mav.command_long_encode(2, 1, 520, 0, 0, 0, 0, 0, 0, 0, 0).pack(second_mav),
                      ("127.0.0.1", emulator.port))
        for _ in range(400):
            if emulator.poll(0.0):
                break
            time.sleep(0.005)
        assert emulator.peer == first.getsockname() and emulator.counters.other_clients == 1
        data, _ = second.recvfrom(4096)
        ack = mavutil.mavlink.MAVLink(None).parse_char(data)
        assert ack.get_type() == "COMMAND_ACK" and ack.command == 520 and ack.target_system == 250
        emulator.send_status(12.0, 0.9, 1.0)
        data, sender = first.recvfrom(4096)
        assert sender[1] == emulator.port
        first.close()
        second.close()
    finally:
        emulator.close()
        ground_station.close()


def test_heartbeat_is_mavlink2_px4_quadrotor(ground):
    sim, client = ground
    sim.advance(0.6)  # the emulator sends from the start (t = 0), before anyone talked to it
    msg = client.recv_match(type="HEARTBEAT", blocking=True, timeout=2.0)
    assert msg is not None
    assert msg.get_msgbuf()[0] == 0xFD  # MAVLink 2 frame
    assert msg.autopilot == mavutil.mavlink.MAV_AUTOPILOT_PX4
    assert msg.type == mavutil.mavlink.MAV_TYPE_QUADROTOR
    assert msg.get_srcSystem() == 1
    assert msg.base_mode & 1 and not msg.base_mode & 128
    seen = set()
    for _ in range(21):  # HEARTBEAT at 1 Hz, BATTERY_STATUS at 0.5 Hz; read as it comes (a full socket drops)
        sim.advance(0.1)
        while (msg := client.recv_match(blocking=False)) is not None:
            seen.add(msg.get_type())
    assert {"ATTITUDE_QUATERNION", "ATTITUDE", "HIGHRES_IMU", "LOCAL_POSITION_NED", "SYS_STATUS",
            "BATTERY_STATUS", "HEARTBEAT"} <= seen


def test_offboard_and_arming_in_offboard_need_only_the_offboard_signal(ground):
    """PX4's offboard check (offboardCheck.cpp): OFFBOARD and arming in it need a setpoint younger than
    COM_OF_LOSS_T, not a second of stream (MAVSDK sends one setpoint, then switches)."""
    ground_sim, client = ground
    _connect(client, ground_sim)
    _drain(client)
    _command(client, SET_MODE, 1.0, OFFBOARD)
    assert _ack(client, ground_sim, SET_MODE) == 1  # TEMPORARILY_REJECTED: no offboard signal
    _setpoint(client)
    _command(client, SET_MODE, 1.0, OFFBOARD)
    assert _ack(client, ground_sim, SET_MODE) == 0
    _command(client, ARM, 1.0)
    assert _ack(client, ground_sim, ARM) == 0
    emulator = ground_sim.emulators[0]
    assert emulator.armed and emulator.offboard
    for _ in range(10):
        _setpoint(client, thrust=0.0)
        ground_sim.advance(0.1)
    heartbeat = None
    while (msg := client.recv_match(type="HEARTBEAT", blocking=False)) is not None:
        heartbeat = msg
    assert heartbeat.custom_mode == 393216 and heartbeat.base_mode & 128


def test_failsafe_after_com_of_loss_t_of_silence_then_land(ground):
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
    ground_sim.advance(emulator.config.offboard_loss_timeout - 0.1)
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


def _swarm(scenario: dict):
    """The scenario with three listening clients, one per UAV, each connected to its emulator: (sim, clients)."""
    clients = [_listening_client() for _ in range(3)]
    sim = Simulation(scenario_from_dict(scenario),
                     SimulationOptions(local_base_port=0, lockstep=False,
                                       remote_ports=tuple(c.port.getsockname()[1] for c in clients)))
    try:
        for client in clients:
            _connect(client, sim)
    except BaseException:
        sim.close()
        for client in clients:
            client.close()
        raise
    return sim, clients


def _ground_swarm(seconds_of_stream: float, thrust: float):
    """Ground scenario, three clients streaming ``thrust`` setpoints at 20 Hz for ``seconds_of_stream``."""
    sim, clients = _swarm({"initial_state": {"mode": "ground"}})
    try:
        _stream(sim, clients, seconds_of_stream, thrust)
    except BaseException:
        sim.close()
        for client in clients:
            client.close()
        raise
    return sim, clients


def _stream(sim, clients, seconds: float, thrust: float, record=None) -> None:
    """Advance ``seconds`` while every client streams a level ``thrust`` setpoint at 20 Hz (as fpr_px4_bridge
    does while WARMUP), reading what comes back; ``record(sim)`` after each 50 ms."""
    for _ in range(int(round(seconds / 0.05))):
        for uav, client in enumerate(clients, start=1):
            client.mav.set_attitude_target_send(
                time_boot_ms=0, target_system=uav, target_component=1, type_mask=7,
                q=[float(v) for v in quat_enu_flu_to_ned_frd(np.array([1.0, 0.0, 0.0, 0.0]))],
                body_roll_rate=0.0, body_pitch_rate=0.0, body_yaw_rate=0.0, thrust=thrust)
        sim.advance(0.05)
        for client in clients:
            _drain(client)
        if record is not None:
            record(sim)


def test_armed_in_posctl_on_the_ground_idles_and_disarms_after_com_disarm_prflt():
    """Integration defect: armed but not yet in OFFBOARD (fpr_px4_bridge arms, then switches ~1.2 s later), the
    emulated PX4 used to fly the streamed offboard thrust level in POSCTL (~11 N per UAV): after ~1.5 s the robot
    lifted off, its legs broke through and it ended 240 m up. PX4 without RC keeps a landed vehicle at idle in
    POSCTL and disarms it COM_DISARM_PRFLT = 10 s after arming if it never took off."""
    from fpr_model.rotations import quat_to_euler_zyx

    sim, clients = _ground_swarm(1.2, thrust=0.4)  # ~15 N per UAV if it were flown, > the ~11 N hover share
    try:
        for uav, client in enumerate(clients, start=1):
            client.mav.command_long_send(target_system=uav, target_component=1, command=ARM, confirmation=0,
                                         param1=1.0, param2=0, param3=0, param4=0, param5=0, param6=0, param7=0)
        emulators = sim.emulators
        for _ in range(100):
            _stream(sim, clients, 0.05, thrust=0.4)
            if all(e.armed for e in emulators):
                break
        assert all(e.armed for e in emulators) and all(e.main_mode == 3 for e in emulators)  # POSCTL
        armed_at = [e.armed_time for e in emulators]
        start = sim.ground_truth().state
        uav_z0 = sim.ground_truth().uav_positions[:, 2].copy()
        worst = {"position": 0.0, "tilt": 0.0, "legs": 0.0, "uav_z": 0.0, "thrust": 0.0, "armed_thrust": 0.0}

        def record(s) -> None:
            truth = s.ground_truth()
            state = truth.state
            roll, pitch, _ = quat_to_euler_zyx(state.quat)
            worst["position"] = max(worst["position"], float(np.linalg.norm(state.position - start.position)))
            worst["tilt"] = max(worst["tilt"], abs(roll), abs(pitch))
            worst["legs"] = max(worst["legs"], float(np.abs(state.leg_angles - start.leg_angles).max()))
            worst["uav_z"] = max(worst["uav_z"], float(np.abs(truth.uav_positions[:, 2] - uav_z0).max()))
            worst["thrust"] = max(worst["thrust"], float(truth.uav_thrusts.max()))
            if all(e.armed for e in s.emulators):
                worst["armed_thrust"] = max(worst["armed_thrust"], float(truth.uav_thrusts.max()))

        _stream(sim, clients, 12.0, thrust=0.4, record=record)  # stays in POSCTL: no OFFBOARD request
        assert worst["position"] < 0.01 and worst["uav_z"] < 0.01
        assert worst["tilt"] < np.radians(1.0) and worst["legs"] < np.radians(1.0)
        assert worst["thrust"] < 0.1  # [N] idle (the ~11 N hover share would lift it)
        for emulator, t_arm in zip(emulators, armed_at, strict=True):
            assert not emulator.armed and not emulator.taken_off
            time_disarmed, reason = emulator.auto_disarm
            assert reason == "preflight"
            assert time_disarmed - t_arm == pytest.approx(emulator.config.disarm_preflight_timeout, abs=0.01)
            assert emulator.counters.failsafes == 0
        print(f"\n[posctl] 12 s armed in POSCTL: platform moved {1000 * worst['position']:.2f} mm, tilt "
              f"{np.degrees(worst['tilt']):.3f} deg, legs {np.degrees(worst['legs']):.3f} deg, max rotor thrust "
              f"{worst['thrust']:.4f} N; disarmed {emulators[0].auto_disarm[0] - armed_at[0]:.3f} s after arming")
    finally:
        sim.close()
        for client in clients:
            client.close()


def test_airborne_in_posctl_without_rc_triggers_the_rc_loss_failsafe():
    """Switched from OFFBOARD to POSCTL in the air (no RC): COM_RC_LOSS_T = 0.5 s later the RC-loss failsafe
    holds (AUTO.LOITER), then lands (AUTO.LAND, NAV_RCL_ACT's Return falling back to Land indoors)."""
    client = _listening_client()
    sim = _simulation(scenario_from_dict({"initial_state": {"mode": "hover", "leg_angles": 0.9, "armed": True},
                                          "ground": {"enabled": False}}), client)
    try:
        emulator = sim.emulators[0]
        hover_local, thrust = emulator.quat_local.copy(), emulator.thrust
        _connect(client, sim)
        for _ in range(5):
            _setpoint(client, hover_local, thrust)
            sim.advance(0.02)
        _command(client, SET_MODE, 1.0, 3)  # POSCTL
        assert _ack(client, sim, SET_MODE) == 0
        switched = sim.time
        assert emulator.main_mode == 3 and emulator.armed and emulator.taken_off
        while emulator.main_mode == 3 and sim.time < switched + 2.0:
            _setpoint(client, hover_local, thrust)  # offboard setpoints do not count outside OFFBOARD
            sim.advance(0.01)
            _drain(client)
        assert emulator.custom_mode == (4 << 16 | 3 << 24)  # AUTO.LOITER (hold)
        assert sim.time - switched == pytest.approx(emulator.config.rc_loss_timeout, abs=0.03)
        assert emulator.counters.failsafes == 1 and emulator.armed
        sim.advance(emulator.config.failsafe_hold_time + 0.05)
        assert emulator.custom_mode == (4 << 16 | 6 << 24)  # AUTO.LAND
        assert emulator.counters.failsafes == 1
    finally:
        sim.close()
        client.close()


def test_auto_land_of_the_whole_fpr_from_2_m_ends_resting_and_disarmed():
    """PX4's per-UAV AUTO.LAND with its position controller: each UAV holds its x/y and descends at
    MPC_LAND_SPEED, so the structure comes down in shape (formerly each UAV descended LEVEL and the legs folded
    onto their stops). It must end finite, at rest, on the ground and disarmed (COM_DISARM_LAND), the legs
    within the stops (± a small penetration)."""
    from fpr_model.rotations import quat_to_euler_zyx

    sim, clients = _swarm({"initial_state": {"mode": "hover", "position": [0.0, 0.0, 2.0],
                                             "leg_angles": np.radians(60.0), "armed": True}})
    try:
        stops = sim.scenario.joint_stops
        for uav, client in enumerate(clients, start=1):
            client.mav.command_long_send(target_system=uav, target_component=1, command=SET_MODE,
                                         confirmation=0, param1=1.0, param2=4, param3=6, param4=0, param5=0,
                                         param6=0, param7=0)
        commanded = sim.time
        low, high, finite = np.inf, -np.inf, True
        for _ in range(120):  # 12 s
            sim.advance(0.1)
            for client in clients:
                _drain(client)
            truth = sim.ground_truth()
            angles = truth.state.leg_angles
            finite = finite and bool(np.isfinite(sim.plant._x).all() and np.isfinite(truth.uav_quats).all())
            low, high = min(low, angles.min()), max(high, angles.max())
        assert all(e.custom_mode == (4 << 16 | 6 << 24) for e in sim.emulators)  # AUTO.LAND
        state = sim.ground_truth().state
        roll, pitch, _ = quat_to_euler_zyx(state.quat)
        assert finite
        assert stops.lower - np.radians(2.0) < low and high < stops.upper + np.radians(2.0)
        assert np.abs(state.velocity).max() < 1e-3 and np.abs(state.rate).max() < 1e-3
        assert np.abs(state.leg_rates).max() < 1e-3
        assert np.allclose(sim.ground_truth().uav_positions[:, 2], sim.plant.gear, atol=0.01)  # on their gear
        for emulator in sim.emulators:
            assert not emulator.armed and emulator.auto_disarm[1] == "landed"
            assert emulator.auto_disarm[0] - commanded < 6.0
        print(f"\n[land] AUTO.LAND from 2 m: legs {np.degrees(low):.1f}°..{np.degrees(high):.1f}°, rests at "
              f"z = {state.position[2]:.3f} m, legs {np.round(np.degrees(state.leg_angles), 1)}°, roll "
              f"{np.degrees(roll):.2f}°, pitch {np.degrees(pitch):.2f}°; disarmed "
              f"{[round(e.auto_disarm[0] - commanded, 2) for e in sim.emulators]} s after LAND")
    finally:
        sim.close()
        for client in clients:
            client.close()


@pytest.mark.parametrize("latency", [0.0, 0.02])
def test_command_latency_delays_the_setpoint_taking_effect_not_its_arrival(latency):
    """px4.command_latency L: an attitude/thrust setpoint flies from its arrival + L (the emulator's 250 Hz
    updates, 4 ms apart: 20 ms is five of them); its stamp (the lockstep's and the offboard signal's) counts on
    arrival; L = 0 applies it on arrival."""
    client = _listening_client()
    scenario = scenario_from_dict({"initial_state": {"mode": "ground"}, "px4": {"command_latency": latency}})
    sim = _simulation(scenario, client)
    try:
        _connect(client, sim)
        emulator = sim.emulators[0]
        assert emulator.thrust == 0.0
        _setpoint(client, thrust=0.3)
        arrival = effect = None
        for _ in range(200):
            sim.step()  # 1 ms
            if arrival is None and emulator.setpoint_time_ms is not None:
                arrival = emulator.time  # the poll of the PX4 update that read it (stamped on arrival)
            if effect is None and emulator.thrust != 0.0:
                effect = emulator.time
        assert arrival is not None and effect is not None
        assert effect == pytest.approx(arrival + latency, abs=1e-9)
        assert emulator.thrust == pytest.approx(0.3, abs=1e-6)
    finally:
        sim.close()
        client.close()


def test_command_latency_is_validated():
    for bad in (-0.01, float("nan"), 0.5):
        with pytest.raises(ValueError, match="command_latency"):
            scenario_from_dict({"px4": {"command_latency": bad}})


def test_admitted_reception_handles_exactly_the_admitted_datagrams():
    """Gated reception (fpr_experiments.overlapped): after ``admit(total)``, poll handles only datagrams admitted so
    far, however many more are waiting in the socket; ``admit`` waits for datagrams still in flight and says which
    UAV's are missing after its timeout. ``sent_datagrams`` counts what the emulator sent."""
    emulator = Px4Emulator(1, Px4Config(), 0.0, local_port=0, remote_port=0)
    client = _udp_socket()
    mav = mavutil.mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    try:
        for _ in range(4):
            client.sendto(mav.heartbeat_encode(type=6, autopilot=8, base_mode=0, custom_mode=0,
                                               system_status=4).pack(mav), ("127.0.0.1", emulator.port))
        emulator.admit(1, timeout=2.0)
        assert emulator.poll(0.0) == 1 and emulator.poll(0.0) == 0  # the other three wait in the socket
        emulator.admit(3, timeout=2.0)
        assert emulator.poll(0.0) == 2 and emulator.counters.datagrams == 3 and emulator.admitted_datagrams == 3
        with pytest.raises(TimeoutError, match="uav1's PX4 emulator: 4 of the 5 datagrams"):
            emulator.admit(5, timeout=0.1)  # the fourth is there, the fifth was never sent
        assert emulator.sent_datagrams == 0
        emulator.send_status(12.0, 0.9, 1.0)  # to its partner, the client that talked first: one datagram each
        assert emulator.sent_datagrams >= 1
        for _ in range(emulator.sent_datagrams):
            assert client.recvfrom(4096)[1][1] == emulator.port
        client.setblocking(False)
        with pytest.raises(BlockingIOError):
            client.recvfrom(4096)
    finally:
        emulator.close()
        client.close()
