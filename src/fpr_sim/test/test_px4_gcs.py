"""The PX4 emulator as a drop-in for PX4 SITL, driven by pymavlink clients the way a GCS (QGroundControl), MAVSDK
and MAVROS drive PX4: streams and SET_MESSAGE_INTERVAL, REQUEST_MESSAGE, PX4's arming and mode rules, legacy
SET_MODE, SET_POSITION_TARGET_LOCAL_NED, and the position-controlled Hold / Land / Takeoff of the whole FPR.
Everything is measured in simulation time (``Simulation`` with lockstep off), never wall time."""

import os

import numpy as np
import pytest

os.environ["MAVLINK20"] = "1"
from fpr_model.frames import quat_enu_flu_to_ned_frd  # noqa: E402
from fpr_sim.scenario import scenario_from_dict  # noqa: E402
from fpr_sim.simulation import Simulation, SimulationOptions  # noqa: E402
from pymavlink import mavutil  # noqa: E402

ARM, SET_MODE, TAKEOFF, LAND_CMD, RTL = 400, 176, 22, 21, 20
SET_INTERVAL, REQUEST_MESSAGE = 511, 512
OFFBOARD, POSCTL, AUTO = 6, 3, 4
LOITER, LAND = 3, 6
HOLD_MODE = AUTO << 16 | LOITER << 24
LAND_MODE = AUTO << 16 | LAND << 24
ACCEPTED, TEMPORARILY_REJECTED, DENIED, UNSUPPORTED = 0, 1, 2, 3
#: config/scenarios/hover.yaml: hovering at 1.5 m, legs at 45°, each PX4 with its own yaw offset (frame F0i)
HOVER = {"seed": 2, "initial_state": {"mode": "hover", "position": [0.0, 0.0, 1.5], "leg_angles": 0.7854,
                                      "armed": True}, "px4": {"yaw_offsets": [0.3, -0.8, 1.9]}}


def _client():
    return mavutil.mavlink_connection("udpin:127.0.0.1:0", source_system=255, source_component=190)


class Rig:
    """A simulation with one listening pymavlink client per UAV (each its emulator's first talker)."""

    def __init__(self, scenario: dict) -> None:
        self.clients = [_client() for _ in range(3)]
        self.sim = Simulation(scenario_from_dict(scenario),
                              SimulationOptions(local_base_port=0, lockstep=False,
                                                remote_ports=tuple(c.port.getsockname()[1] for c in self.clients)))
        self.messages: list[list] = [[] for _ in self.clients]  # (sim time, message) read so far, per client
        for client in self.clients:
            for _ in range(100):
                self.advance(0.05)
                if any(m.get_type() == "HEARTBEAT" for _, m in self.messages[self.clients.index(client)]):
                    break
            client.mav.heartbeat_send(type=6, autopilot=8, base_mode=0, custom_mode=0, system_status=4)
        self.advance(0.01)

    def close(self) -> None:
        self.sim.close()
        for client in self.clients:
            client.close()

    def read(self) -> None:
        for k, client in enumerate(self.clients):
            while (msg := client.recv_match(blocking=False)) is not None:
                self.messages[k].append((self.sim.time, msg))

    def advance(self, seconds: float, every=None, step: float = 0.02) -> None:
        """Advance ``seconds`` of simulation time reading continuously; ``every()`` before each ``step``."""
        for _ in range(max(1, int(round(seconds / step)))):
            if every is not None:
                every()
            self.sim.advance(step)
            self.read()

    def command(self, uav: int, command: int, *params: float, use_int: bool = False) -> int:
        """Send a command to UAV ``uav`` (1-based) and return the result of its COMMAND_ACK."""
        client = self.clients[uav - 1]
        p = [float(v) for v in params] + [0.0] * (7 - len(params))
        start = len(self.messages[uav - 1])
        if use_int:
            client.mav.command_int_send(uav, 1, 0, command, 0, 0, p[0], p[1], p[2], p[3], int(p[4]), int(p[5]), p[6])
        else:
            client.mav.command_long_send(uav, 1, command, 0, *p)
        for _ in range(100):
            self.advance(0.002, step=0.002)
            for _, msg in self.messages[uav - 1][start:]:
                if msg.get_type() == "COMMAND_ACK" and msg.command == command:
                    return int(msg.result)
        raise AssertionError(f"no COMMAND_ACK for {command}")

    def count(self, uav: int, kind: str, start: float, end: float) -> int:
        return sum(1 for t, m in self.messages[uav - 1] if m.get_type() == kind and start < t <= end)

    def attitude_setpoints(self, uavs=(1, 2, 3)) -> None:
        """Each UAV's hover attitude setpoint (time_boot_ms 0: stamped on arrival)."""
        for uav in uavs:
            emulator = self.sim.emulators[uav - 1]
            q = [float(v) for v in quat_enu_flu_to_ned_frd(emulator.quat_local)]
            self.clients[uav - 1].mav.set_attitude_target_send(0, uav, 1, 7, q, 0.0, 0.0, 0.0, emulator.thrust)


@pytest.fixture
def hover():
    rig = Rig(HOVER)
    yield rig
    rig.close()


@pytest.fixture
def ground():
    rig = Rig({"initial_state": {"mode": "ground"}})
    yield rig
    rig.close()


def _platform_z(sim) -> float:
    return float(sim.ground_truth().state.position[2])


def test_heartbeat_identity_and_custom_mode(ground):
    for uav in (1, 2, 3):
        heartbeats = [m for _, m in ground.messages[uav - 1] if m.get_type() == "HEARTBEAT"]
        assert heartbeats, f"no HEARTBEAT from uav{uav}"
        hb = heartbeats[-1]
        assert hb.type == mavutil.mavlink.MAV_TYPE_QUADROTOR and hb.autopilot == mavutil.mavlink.MAV_AUTOPILOT_PX4
        assert hb.get_srcSystem() == uav and hb.get_srcComponent() == 1
        assert hb.custom_mode == POSCTL << 16 and hb.base_mode & 1 and not hb.base_mode & 128


def test_default_rates_are_px4_onboard_ones_and_set_message_interval_changes_them(ground):
    t0 = ground.sim.time
    ground.advance(4.0)
    t1 = ground.sim.time
    rates = {kind: ground.count(1, kind, t0, t1) / (t1 - t0) for kind in (
        "HEARTBEAT", "ATTITUDE", "ATTITUDE_QUATERNION", "HIGHRES_IMU", "LOCAL_POSITION_NED", "SYS_STATUS",
        "BATTERY_STATUS", "EXTENDED_SYS_STATE")}
    expected = {"HEARTBEAT": 2.0, "ATTITUDE": 100.0, "ATTITUDE_QUATERNION": 50.0, "HIGHRES_IMU": 50.0,
                "LOCAL_POSITION_NED": 50.0, "SYS_STATUS": 5.0, "BATTERY_STATUS": 0.5, "EXTENDED_SYS_STATE": 5.0}
    for kind, rate in expected.items():
        assert rates[kind] == pytest.approx(rate, abs=max(0.3, 0.03 * rate)), (kind, rates[kind])
    # ATTITUDE at 50 Hz (20 ms), LOCAL_POSITION_NED off, BATTERY_STATUS at 10 Hz, by COMMAND_LONG and COMMAND_INT
    assert ground.command(1, SET_INTERVAL, 30, 20000) == ACCEPTED
    assert ground.command(1, SET_INTERVAL, 32, -1, use_int=True) == ACCEPTED
    assert ground.command(1, SET_INTERVAL, 147, 100000) == ACCEPTED
    assert ground.command(1, SET_INTERVAL, 12345, 100000) == DENIED  # not a streamed message
    t0 = ground.sim.time
    ground.advance(4.0)
    t1 = ground.sim.time
    assert ground.count(1, "ATTITUDE", t0, t1) / (t1 - t0) == pytest.approx(50.0, abs=1.0)
    assert ground.count(1, "LOCAL_POSITION_NED", t0, t1) == 0
    assert ground.count(1, "BATTERY_STATUS", t0, t1) / (t1 - t0) == pytest.approx(10.0, abs=0.5)
    assert ground.count(2, "ATTITUDE", t0, t1) / (t1 - t0) == pytest.approx(100.0, abs=3.0)  # per link
    # 0: back to the default
    assert ground.command(1, SET_INTERVAL, 30, 0) == ACCEPTED
    t0 = ground.sim.time
    ground.advance(2.0)
    assert ground.count(1, "ATTITUDE", t0, ground.sim.time) / (ground.sim.time - t0) == pytest.approx(100.0, abs=3.0)
    print(f"\n[rates] default {', '.join(f'{k} {v:.2f} Hz' for k, v in rates.items())}")


def test_request_message_sends_it_once_and_unknown_commands_are_unsupported(ground):
    start = len(ground.messages[0])
    assert ground.command(1, REQUEST_MESSAGE, 148) == ACCEPTED  # AUTOPILOT_VERSION
    assert ground.command(1, REQUEST_MESSAGE, 245) == ACCEPTED  # EXTENDED_SYS_STATE
    assert ground.command(1, REQUEST_MESSAGE, 9999) == DENIED
    ground.advance(0.01)
    kinds = [m.get_type() for _, m in ground.messages[0][start:]]
    assert kinds.count("AUTOPILOT_VERSION") == 1
    version = next(m for _, m in ground.messages[0][start:] if m.get_type() == "AUTOPILOT_VERSION")
    assert version.capabilities & (1 << 13)  # MAVLINK2
    landed = [m for _, m in ground.messages[0][start:] if m.get_type() == "EXTENDED_SYS_STATE"]
    assert landed and landed[-1].landed_state == 1  # ON_GROUND
    assert ground.command(1, 31000) == UNSUPPORTED
    assert ground.command(1, 179) == UNSUPPORTED  # DO_SET_HOME: not emulated


def test_arming_rules(ground):
    sim = ground.sim
    emulator = sim.emulators[0]
    # AUTO.LAND prevents arming (mode_req_prevent_arming)
    assert ground.command(1, SET_MODE, 1, AUTO, LAND) == ACCEPTED
    assert ground.command(1, ARM, 1) == TEMPORARILY_REJECTED and not emulator.armed
    # Hold (AUTO.LOITER): arming allowed; on the ground it stays at idle
    assert ground.command(1, SET_MODE, 1, AUTO, LOITER) == ACCEPTED
    assert ground.command(1, ARM, 1) == ACCEPTED and emulator.armed
    ground.advance(1.0)
    assert float(sim.ground_truth().uav_thrusts[0].max()) < 0.1
    assert ground.command(1, ARM, 0) == ACCEPTED and not emulator.armed  # landed: plain disarm
    # POSCTL without RC: PX4 refuses (modeCheck.cpp); the emulator's default accepts it (bridge flow)
    assert ground.command(1, SET_MODE, 1, POSCTL) == ACCEPTED
    emulator.config.manual_modes_without_rc = False
    try:
        assert ground.command(1, ARM, 1) == TEMPORARILY_REJECTED
        assert ground.command(1, ARM, 1, 21196) == ACCEPTED  # forced: no checks
        assert ground.command(1, ARM, 0) == ACCEPTED
    finally:
        emulator.config.manual_modes_without_rc = True
    assert ground.command(1, ARM, 1) == ACCEPTED
    assert ground.command(1, ARM, 0) == ACCEPTED
    # RTL needs a global position: rejected; not a custom mode: unsupported
    assert ground.command(1, RTL) == TEMPORARILY_REJECTED
    assert ground.command(1, SET_MODE, 0, 3) == UNSUPPORTED


def test_in_flight_disarm_needs_the_force_code(hover):
    emulator = hover.sim.emulators[0]
    assert emulator.armed and not emulator.landed
    assert hover.command(1, ARM, 0) == DENIED and emulator.armed
    assert hover.command(1, ARM, 0, 21196) == ACCEPTED and not emulator.armed


def test_offboard_by_do_set_mode_and_by_legacy_set_mode_with_one_setpoint(ground):
    sim = ground.sim
    # UAV 1: DO_SET_MODE (MAVSDK), UAV 2: legacy SET_MODE (QGroundControl / MAVROS set_mode)
    for uav in (1, 2):
        assert sim.emulators[uav - 1].main_mode == POSCTL
    assert ground.command(1, SET_MODE, 1, OFFBOARD) == TEMPORARILY_REJECTED  # no offboard signal yet
    ground.attitude_setpoints(uavs=(1, 2))
    assert ground.command(1, SET_MODE, 1, OFFBOARD) == ACCEPTED
    start = len(ground.messages[1])
    ground.clients[1].mav.set_mode_send(2, 1, OFFBOARD << 16)
    ground.advance(0.01, step=0.002)
    acks = [m for _, m in ground.messages[1][start:] if m.get_type() == "COMMAND_ACK"]
    assert acks and acks[-1].command == SET_MODE and acks[-1].result == ACCEPTED and acks[-1].target_system == 255
    for uav in (1, 2):
        assert sim.emulators[uav - 1].offboard
        assert ground.command(uav, ARM, 1) == ACCEPTED
    # a SET_MODE for another system is ignored
    ignored = sim.emulators[1].counters.ignored
    ground.clients[1].mav.set_mode_send(7, 1, POSCTL << 16)
    ground.advance(0.01, step=0.002)
    assert sim.emulators[1].offboard and sim.emulators[1].counters.ignored == ignored + 1


def test_offboard_loss_in_flight_holds_then_lands(hover):
    sim = hover.sim
    hover.advance(0.5, every=hover.attitude_setpoints)
    stop = sim.time
    while all(e.offboard for e in sim.emulators) and sim.time < stop + 2.0:
        hover.advance(0.02)
    assert all(e.custom_mode == HOLD_MODE for e in sim.emulators)
    assert sim.time - stop == pytest.approx(sim.scenario.px4.offboard_loss_timeout, abs=0.05)
    hold_start = sim.time
    z0 = lowest = highest = _platform_z(sim)  # Hold holds where it was entered
    while sim.time < hold_start + sim.scenario.px4.failsafe_hold_time - 0.05:
        hover.advance(0.02)
        z = _platform_z(sim)
        lowest, highest = min(lowest, z), max(highest, z)
    assert all(e.custom_mode == HOLD_MODE for e in sim.emulators)
    # really holding, not landing (AUTO.LAND would descend 0.7 m/s x 5 s = 3.5 m) nor climbing. Not rigid: after
    # COM_OF_LOSS_T of frozen attitudes the legs fold slowly in Hold (the structure's negative stiffness against
    # PX4's position loop): measured 0.39 m down in 5 s with the FPR's 0.5 s, < 0.3 m with PX4's default 1 s
    assert highest - z0 < 0.3 and z0 - lowest < 0.5
    hover.advance(0.1)
    assert all(e.custom_mode == LAND_MODE for e in sim.emulators)
    assert all(e.counters.failsafes == 1 for e in sim.emulators)


def test_hold_keeps_the_fpr_within_0_3_m_for_10_s_after_an_offboard_stop(hover):
    """MAVSDK's offboard stop switches to Hold (DO_SET_MODE AUTO.LOITER) and stops the stream. PX4's Hold is a
    position hold per vehicle: the whole robot keeps its altitude (main: it kept the last thrust, climbed 340 m)."""
    sim = hover.sim
    hover.advance(1.0, every=hover.attitude_setpoints)
    for uav in (1, 2, 3):
        assert hover.command(uav, SET_MODE, 1, AUTO, LOITER) == ACCEPTED
    start = sim.time
    truth = sim.ground_truth()
    z0, xy0 = float(truth.state.position[2]), truth.state.position[:2].copy()
    uav_z0 = truth.uav_positions[:, 2].copy()
    legs0 = truth.state.leg_angles.copy()
    worst = {"z": 0.0, "xy": 0.0, "uav_z": 0.0, "legs": 0.0}
    while sim.time < start + 10.0:
        hover.advance(0.1)
        truth = sim.ground_truth()
        worst["z"] = max(worst["z"], abs(float(truth.state.position[2]) - z0))
        worst["xy"] = max(worst["xy"], float(np.linalg.norm(truth.state.position[:2] - xy0)))
        worst["uav_z"] = max(worst["uav_z"], float(np.abs(truth.uav_positions[:, 2] - uav_z0).max()))
        worst["legs"] = max(worst["legs"], float(np.abs(truth.state.leg_angles - legs0).max()))
    assert all(e.custom_mode == HOLD_MODE and e.armed for e in sim.emulators)
    assert worst["z"] < 0.3 and worst["uav_z"] < 0.3
    print(f"\n[hold] 10 s in Hold: platform |dz| max {1000 * worst['z']:.1f} mm, |dxy| max "
          f"{1000 * worst['xy']:.1f} mm, UAV |dz| max {1000 * worst['uav_z']:.1f} mm, legs "
          f"{np.degrees(worst['legs']):.2f} deg")
    assert worst["xy"] < 0.3 and worst["legs"] < np.radians(10.0)


def test_land_brings_the_fpr_down_and_disarms_every_vehicle(hover):
    sim = hover.sim
    hover.advance(0.5, every=hover.attitude_setpoints)
    for uav in (1, 2, 3):
        assert hover.command(uav, LAND_CMD) == ACCEPTED  # NAV_LAND
    commanded = sim.time
    landing_states = set()
    while sim.time < commanded + 12.0 and any(e.armed for e in sim.emulators):
        hover.advance(0.1)
        landing_states |= {m.landed_state for _, m in hover.messages[0] if m.get_type() == "EXTENDED_SYS_STATE"}
    assert not any(e.armed for e in sim.emulators)
    assert all(e.auto_disarm[1] == "landed" for e in sim.emulators)
    assert 4 in landing_states  # LANDING
    hover.advance(1.0)
    state = sim.ground_truth().state
    assert np.abs(state.velocity).max() < 0.05
    assert np.allclose(sim.ground_truth().uav_positions[:, 2], sim.plant.gear, atol=0.05) or \
        float(state.position[2]) < 0.3
    times = [round(e.auto_disarm[0] - commanded, 2) for e in sim.emulators]
    print(f"\n[land] NAV_LAND from 1.5 m: disarmed {times} s after the command, platform at "
          f"z = {state.position[2]:.3f} m, legs {np.round(np.degrees(state.leg_angles), 1)} deg")


def _position_target(rig, uav, mask, frame=1, pos=(0.0, 0.0, 0.0), vel=(0.0, 0.0, 0.0), yaw=0.0):
    rig.clients[uav - 1].mav.set_position_target_local_ned_send(0, uav, 1, frame, mask, *pos, *vel, 0.0, 0.0, 0.0,
                                                                 yaw, 0.0)


VELOCITY_ONLY = 0b1001_1100_0111  # ignore position, acceleration, yaw rate: velocity + yaw used
POSITION_ONLY = 0b1001_1111_1000  # ignore velocity, acceleration, yaw rate: position + yaw used


def test_set_position_target_velocity_then_position_flies_the_fpr(hover):
    """MAVSDK / MAVROS offboard examples: velocity setpoints (NED, up = −z) then a position setpoint, each UAV in
    its own local frame."""
    sim = hover.sim
    for uav, emulator in enumerate(sim.emulators, start=1):
        yaw_ned = float(np.pi / 2 - _yaw(emulator))
        _position_target(hover, uav, VELOCITY_ONLY, vel=(0.0, 0.0, -0.5), yaw=yaw_ned)
    for uav in (1, 2, 3):
        assert hover.command(uav, SET_MODE, 1, OFFBOARD) == ACCEPTED
    z0 = _platform_z(sim)
    targets = {}

    def velocity_stream():
        for uav, emulator in enumerate(sim.emulators, start=1):
            yaw_ned = float(np.pi / 2 - _yaw(emulator))
            targets[uav] = yaw_ned
            _position_target(hover, uav, VELOCITY_ONLY, vel=(0.0, 0.0, -0.5), yaw=yaw_ned)

    hover.advance(2.0, every=velocity_stream)
    climbed = _platform_z(sim) - z0
    assert all(e.offboard and e.offboard_kind == "position" for e in sim.emulators)
    assert 0.6 < climbed < 1.2  # 0.5 m/s for 2 s, with the velocity loop's rise
    # position: hold 1 m below the present height (NED z + 1)
    goals = [e.position_local.copy() for e in sim.emulators]

    def position_stream():
        for uav, goal in enumerate(goals, start=1):
            ned = (goal[1], goal[0], -(goal[2] - 1.0))
            _position_target(hover, uav, POSITION_ONLY, pos=ned, yaw=targets[uav])

    z1 = _platform_z(sim)
    hover.advance(8.0, every=position_stream)
    errors = [float(np.linalg.norm(e.position_local - (g - [0.0, 0.0, 1.0]))) for e, g in
              zip(sim.emulators, goals, strict=True)]
    assert max(errors) < 0.15
    assert _platform_z(sim) - z1 == pytest.approx(-1.0, abs=0.15)
    print(f"\n[offboard position] climbed {climbed:.3f} m in 2 s at 0.5 m/s, then descended "
          f"{z1 - _platform_z(sim):.3f} m to a position setpoint, UAV errors {np.round(errors, 3)} m")


def _yaw(emulator) -> float:
    w, x, y, z = emulator._attitude_local
    return float(np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))


def test_takeoff_climbs_to_mis_takeoff_alt_then_holds(ground):
    sim = ground.sim
    for uav in (1, 2, 3):
        assert ground.command(uav, SET_MODE, 1, AUTO, 2) == ACCEPTED  # AUTO.TAKEOFF
    for uav in (1, 2, 3):
        assert ground.command(uav, ARM, 1) == ACCEPTED
    uav_z0 = sim.ground_truth().uav_positions[:, 2].copy()
    ground.advance(8.0)
    assert all(e.custom_mode == HOLD_MODE and e.armed for e in sim.emulators)
    climb = sim.ground_truth().uav_positions[:, 2] - uav_z0
    assert climb == pytest.approx(np.full(3, sim.scenario.px4.takeoff_altitude), abs=0.15)
    ground.advance(3.0)
    still = sim.ground_truth().uav_positions[:, 2] - uav_z0
    assert np.abs(still - climb).max() < 0.1
    print(f"\n[takeoff] AUTO.TAKEOFF of the FPR: UAVs climbed {np.round(climb, 3)} m, then Hold (3 s later "
          f"{np.round(still, 3)} m)")


def test_malformed_input_is_counted_and_never_crashes(ground):
    sim = ground.sim
    emulator = sim.emulators[0]
    client = ground.clients[0]
    rejected, garbage = emulator.counters.rejected_setpoints, emulator.counters.garbage
    nan = float("nan")
    client.mav.set_position_target_local_ned_send(0, 1, 1, 1, 0, float("inf"), 0, 0, 0, 0, 0, 0, 0, 0, 0, 0)
    client.mav.set_position_target_local_ned_send(0, 1, 1, 21, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0)  # frame 21
    client.mav.set_position_target_local_ned_send(0, 1, 1, 1, 0xFFF, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0)  # nothing
    client.mav.command_long_send(1, 1, SET_MODE, 0, nan, nan, nan, 0, 0, 0, 0)
    client.mav.command_long_send(1, 1, SET_INTERVAL, 0, nan, nan, 0, 0, 0, 0, 0)
    client.mav.set_mode_send(1, 0, 0xFFFFFFFF)
    client.write(b"\xfd\x09\x00\x00\x00garbage")
    client.write(bytes(range(256)))
    ground.advance(0.1)
    assert emulator.counters.rejected_setpoints == rejected + 3
    assert emulator.counters.garbage > garbage
    assert emulator.main_mode == POSCTL and not emulator.armed
    assert ground.command(1, REQUEST_MESSAGE, 0) == ACCEPTED  # still answering


def test_position_target_frames_and_type_mask():
    """LOCAL_NED -> F0i ENU; BODY_NED velocities along the heading (x forward, y right, z down); offsets from the
    present position; ignored components are NaN (not used)."""
    from fpr_sim.px4_emulator import Px4Emulator
    from fpr_sim.scenario import Px4Config

    emulator = Px4Emulator(1, Px4Config(), 0.0, local_port=0, remote_port=0)
    try:
        mav = mavutil.mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        address = ("127.0.0.1", 9)
        yaw = np.radians(90.0)  # heading north (ENU)
        emulator._attitude_local = np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])
        emulator.position_local = np.array([1.0, 2.0, 3.0])

        def send(frame, mask, pos=(0.0, 0.0, 0.0), vel=(0.0, 0.0, 0.0), yaw_ned=0.0):
            msg = mav.set_position_target_local_ned_encode(0, 1, 1, frame, mask, *pos, *vel, 0.0, 0.0, 0.0, yaw_ned,
                                                           0.0)
            emulator._handle(mavutil.mavlink.MAVLink(None).parse_char(msg.pack(mav)), address)
            return emulator.position_target

        target = send(1, POSITION_ONLY, pos=(1.0, 2.0, -3.0), yaw_ned=0.0)  # NED north 1, east 2, up 3
        assert np.allclose(target.position, [2.0, 1.0, 3.0]) and np.isnan(target.velocity).all()
        assert target.yaw == pytest.approx(np.pi / 2)  # facing north
        target = send(8, VELOCITY_ONLY, vel=(1.0, 0.5, -0.2), yaw_ned=0.0)  # forward 1, right 0.5, up 0.2
        assert np.allclose(target.velocity, [0.5, 1.0, 0.2])  # heading north: right = east
        assert target.yaw == pytest.approx(yaw)  # body yaw 0 = keep the heading
        target = send(7, POSITION_ONLY & ~0b100 | 0b100, pos=(1.0, 0.0, 0.0))  # offset north 1, z ignored
        assert np.allclose(target.position[:2], [1.0, 3.0]) and np.isnan(target.position[2])
        assert emulator.counters.setpoints == 3 and emulator.setpoint_time_ms is not None
    finally:
        emulator.close()


def test_px4_default_horizontal_gains_let_the_hover_fpr_collapse_in_hold():
    """Why Px4Config.position_control is stiffer than PX4's defaults: with MPC_XY_P 0.95 / MPC_XY_VEL_P_ACC 1.8 the
    weight of the structure (platform above the UAVs, legs at 45°) beats the UAVs' horizontal position loops and
    the legs oscillate and collapse in Hold within 10 s, though every UAV holds its altitude."""
    scenario = dict(HOVER, px4=dict(HOVER["px4"], position_control={"xy_p": 0.95, "xy_vel_p": 1.8, "xy_vel_i": 0.4}))
    rig = Rig(scenario)
    try:
        sim = rig.sim
        rig.advance(1.0, every=rig.attitude_setpoints)
        for uav in (1, 2, 3):
            assert rig.command(uav, SET_MODE, 1, AUTO, LOITER) == ACCEPTED
        legs0 = sim.ground_truth().state.leg_angles.copy()
        uav_z0 = sim.ground_truth().uav_positions[:, 2].copy()
        legs, uav_z = 0.0, 0.0
        for _ in range(100):
            rig.advance(0.1)
            truth = sim.ground_truth()
            legs = max(legs, float(np.abs(truth.state.leg_angles - legs0).max()))
            uav_z = max(uav_z, float(np.abs(truth.uav_positions[:, 2] - uav_z0).max()))
        assert legs > np.radians(20.0) and uav_z < 0.1
        print(f"\n[hold, PX4 default MPC_XY gains] legs moved up to {np.degrees(legs):.1f} deg, UAV |dz| max "
              f"{1000 * uav_z:.1f} mm")
    finally:
        rig.close()
