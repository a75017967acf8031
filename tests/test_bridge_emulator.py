"""Integration: fpr_px4_bridge (the real bridge core, and the real px4_bridge node) against fpr_sim's PX4 emulators
driven by the simulation core in lockstep, over MAVLink 2 / UDP on 127.0.0.1.

ROS-free part: one :class:`Px4Bridge` per UAV, listening like on the robot; the emulators talk first (PX4 SITL
convention); one loop alternates a 20 ms control period of simulation with the bridges' receive / submit / tick at
the simulation time, so it is deterministic and as fast as the physics. The flight is run once (module fixture)
and each test checks one aspect of its record: connection, arming and OFFBOARD through the bridge's state machine,
setpoint frames and thrust normalization end-to-end, telemetry frames, setpoint-stream loss -> PX4 failsafe.

ROS part: the px4_bridge node in-process with its DEFAULT port (udp://127.0.0.1:14540) against a simulation with
the DEFAULT emulator ports (bind 14580 + i - 1, send to 14540 + i - 1), teleop ARM then FLY on /fpr/teleop,
setpoints on /fpr/uav1/setpoint, status / imu read back, all on simulation time (use_sim_time, /clock at 250 Hz
published by the test thread, which advances the simulation core in lockstep with the node's stream timer). (Fixed
ports are safe: the tests run in a private network namespace, scripts/run_tests.sh.)
"""

from __future__ import annotations

import math
import os
import threading
import time

import numpy as np
import pytest

os.environ["MAVLINK20"] = "1"
from fpr_model.battery import max_thrust, thrust_coefficients  # noqa: E402
from fpr_model.dynamics import gravity, thrusts_from_wrench  # noqa: E402
from fpr_model.rotations import quat_error, quat_from_axis_angle, quat_multiply, quat_to_rotmat  # noqa: E402
from fpr_px4_bridge.bridge import BridgeConfig, Px4Bridge  # noqa: E402
from fpr_px4_bridge.link import MavlinkLink  # noqa: E402
from fpr_px4_bridge.offboard import BridgeState, OffboardConfig, TeleopMode  # noqa: E402
from fpr_px4_bridge.px4_protocol import Px4AutoSubMode, Px4MainMode  # noqa: E402
from fpr_px4_bridge.streams import DEFAULT_MESSAGE_RATES, parse_message_rates  # noqa: E402
from fpr_px4_bridge.telemetry import BodyVelocitySample, ImuSample  # noqa: E402
from fpr_sim.scenario import Px4Config, scenario_from_dict  # noqa: E402
from fpr_sim.simulation import Simulation, SimulationOptions  # noqa: E402

CONTROL_PERIOD = 0.02  # [s] the bridge's stream period (50 Hz) and the simulation's lockstep period
YAW_OFFSETS = [0.3, -0.5, 1.2]  # F0i yaw offsets of the three PX4s [rad]
THRUST_RATIO = 1.1  # 1.1x the hover thrusts: the robot accelerates upwards at ~g/10, legs near equilibrium


def _angle(q, q_ref) -> float:
    """Rotation angle between two attitudes [rad]."""
    return 2.0 * math.asin(min(1.0, float(np.linalg.norm(quat_error(q, q_ref)[1:]))))


def _level_with_yaw(q) -> np.ndarray:
    """The level attitude with the yaw of ``q`` (ENU/FLU)."""
    w, x, y, z = q
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return quat_from_axis_angle([0.0, 0.0, 1.0], yaw)


def _tilt(q) -> float:
    """Angle between the body z axis and the world z axis [rad]."""
    return math.acos(max(-1.0, min(1.0, float(quat_to_rotmat(q)[2, 2]))))


def _scenario(mode: str):
    """``ground``: resting on the ground, disarmed; ``hover``: hovering (legs 60°), PX4s armed in OFFBOARD."""
    initial = {"mode": mode} if mode == "ground" else {"mode": "hover", "armed": True, "leg_angles": math.radians(60)}
    return scenario_from_dict({"initial_state": initial, "ground": {"enabled": mode == "ground"},
                               "px4": {"yaw_offsets": YAW_OFFSETS}, "cameras": {"enabled": False}})


# ------------------------------------------------------------------------------------------------ ROS-free rig
class Rig:
    """Three bridge cores + the simulation core, stepped together (see the module doc)."""

    def __init__(self, scenario, message_rates=()) -> None:
        self.links = [MavlinkLink("udp://127.0.0.1:0", system_id=i, target_system=i) for i in (1, 2, 3)]
        offboard = OffboardConfig(command_max_attempts=20)
        self.bridges = [Px4Bridge(BridgeConfig(uav_id=i, target_system=i, a_f=thrust_coefficients(i).a_f,
                                               b_f=thrust_coefficients(i).b_f, offboard=offboard,
                                               message_rates=message_rates), link)
                        for i, link in zip((1, 2, 3), self.links, strict=True)]
        ports = tuple(link.local_address[1] for link in self.links)
        # the stream-loss test silences the controllers on purpose: a stall is counted and the simulation flies on
        # (the default, "stop", would end the run with a LockstepStalled error)
        self.sim = Simulation(scenario, SimulationOptions(local_base_port=0, remote_ports=ports, lockstep=True,
                                                          lockstep_timeout=0.3, lockstep_on_timeout="continue"))
        self.imu: list[ImuSample | None] = [None] * 3
        self.velocity: list[BodyVelocitySample | None] = [None] * 3
        self.setpoints: list[tuple[np.ndarray, float]] | None = None  # (q local ENU/FLU, thrust N) per UAV

    def close(self) -> None:
        self.sim.close()
        for link in self.links:
            link.close()

    @property
    def now(self) -> float:
        return self.sim.time

    def teleop(self, mode: TeleopMode) -> None:
        for bridge in self.bridges:
            bridge.on_teleop(int(mode), self.now)

    def cycle(self) -> None:
        """One control period: simulation (lockstep), then each bridge reads, gets its setpoint, ticks."""
        self.sim.advance(CONTROL_PERIOD)
        now = self.now
        for i, bridge in enumerate(self.bridges):
            for sample in bridge.poll(now):
                if isinstance(sample, ImuSample):
                    self.imu[i] = sample
                elif isinstance(sample, BodyVelocitySample):
                    self.velocity[i] = sample
            if self.setpoints is not None:
                q, thrust = self.setpoints[i]
                result = bridge.submit_setpoint(q, thrust, i + 1, now)
                assert result.accepted, result.reason
            bridge.tick(now)

    def run_until(self, condition, timeout: float, what: str) -> float:
        """Cycle until ``condition()`` holds (at most ``timeout`` s of simulation); return the simulation time."""
        deadline = self.now + timeout
        while not condition():
            assert self.now < deadline, f"{what}: not reached within {timeout} s of simulation"
            self.cycle()
        return self.now

    def status(self, i: int):
        return self.bridges[i].status(self.now)


def _hover_forces(plant) -> np.ndarray:
    """J^-T g: the thrust vectors holding the structure (plant's true parameters), world frame [N], (n, 3)."""
    q = plant.state.configuration()
    return thrusts_from_wrench(plant.params, q, gravity(plant.params, q))


@pytest.fixture(scope="module")
def ground_start():
    """Robot resting on the ground, disarmed: connect, teleop ARM, then FLY (idle thrust, present attitudes)."""
    rig = Rig(_scenario("ground"))
    record: dict = {"failure": ""}
    try:
        sim, bridges, emulators = rig.sim, rig.bridges, rig.sim.emulators
        record["connected_at"] = rig.run_until(lambda: all(rig.status(i).connected for i in range(3)), 2.0,
                                               "connected")
        rig.run_until(lambda: all(s is not None for s in rig.imu), 1.0, "first telemetry")
        record["initial_status"] = [rig.status(i) for i in range(3)]
        # the controller's setpoint: each UAV's present attitude in ITS frame, 0 N (-> thrust_min): stays put
        rig.setpoints = [(rig.imu[i].orientation.copy(), 0.0) for i in range(3)]
        rig.teleop(TeleopMode.ARM)
        rig.cycle()  # the first setpoint and the first ARM go out at the end of this period
        record["stream_started_at"] = rig.now
        record["armed_at"] = rig.run_until(lambda: all(e.armed for e in emulators), 3.0, "armed")
        record["armed_seen_after"] = rig.run_until(  # the bridges see it in the next HEARTBEAT (2 Hz)
            lambda: all(rig.status(i).armed for i in range(3)), 0.6, "armed HEARTBEAT") - record["armed_at"]
        record["armed_status"] = [rig.status(i) for i in range(3)]
        rig.teleop(TeleopMode.FLY)
        record["offboard_at"] = rig.run_until(
            lambda: all(b.machine.state == BridgeState.OFFBOARD for b in bridges)
            and all(e.offboard for e in emulators), 4.0, "OFFBOARD")
        record["offboard_requested_at"] = [b.machine.offboard_requested_at for b in bridges]
        record["offboard_status"] = [rig.status(i) for i in range(3)]
        record["emulator_thrust"] = [e.thrust for e in emulators]
        record["voltages"] = [b.battery_voltage(rig.now) for b in bridges]
        record["lockstep_timeouts"] = sim.lockstep_timeouts
    except AssertionError as error:
        record["failure"] = str(error)
    finally:
        rig.close()
    return record


@pytest.fixture(scope="module")
def hover_flight():
    """Robot hovering, PX4s armed in OFFBOARD (scenario start); the bridges fly it open loop: UAV 1 LEVEL, UAVs 2
    and 3 at their hover attitudes, all with 1.1x their hover thrust (the robot accelerates upwards at ~g/10 with
    its legs near equilibrium); after 1 s the controller goes silent (setpoint stream loss)."""
    rig = Rig(_scenario("hover"))
    record: dict = {"failure": ""}
    try:
        sim, bridges, emulators = rig.sim, rig.bridges, rig.sim.emulators
        plant = sim.plant
        forces = _hover_forces(plant)
        quats = plant.default_uav_attitudes(forces)
        setpoints = [(sim.sensors.world_to_local_quat(i, quats[i]), THRUST_RATIO * float(np.linalg.norm(forces[i])))
                     for i in range(3)]
        setpoints[0] = (_level_with_yaw(setpoints[0][0]), setpoints[0][1])
        rig.setpoints = setpoints
        rig.teleop(TeleopMode.FLY)  # PX4 is already armed: the bridges stream, then see OFFBOARD
        rig.run_until(lambda: rig.now >= 0.9 - 1e-9, 1.5, "0.9 s of flight")  # between two BATTERY_STATUS
        truth = sim.ground_truth()
        record["hover"] = {
            "setpoints": setpoints, "states": [b.machine.state for b in bridges],
            "emulator_quat_local": [e.quat_local.copy() for e in emulators],
            "emulator_thrust": [e.thrust for e in emulators],
            "bridge_voltages": [b.battery_voltage(rig.now) for b in bridges],
            "plant_thrust": plant.fleet.thrust().copy(), "plant_max_thrust": plant.fleet.max_thrust().copy(),
            "true_quats": truth.uav_quats.copy(), "true_rates": truth.uav_rates.copy(),
            "true_velocities": truth.uav_velocities.copy(),
            "true_local_quats": [sim.sensors.world_to_local_quat(i, truth.uav_quats[i]) for i in range(3)],
            "imu": list(rig.imu), "velocity": list(rig.velocity), "time": rig.now,
            "gyro_bias": sim.sensors.gyro_bias.copy(),
        }
        record["lockstep_timeouts_streaming"] = sim.lockstep_timeouts
        # setpoint stream loss: the bridges repeat the last setpoint for setpoint_timeout, then stop; PX4's
        # COM_OF_LOSS_T failsafe then takes over (AUTO.LOITER: PX4's position hold, taking over bumplessly)
        rig.setpoints = None
        record["stop_at"] = stop_at = rig.now
        sent = [b.setpoints_sent for b in bridges]
        last_sent = [rig.now] * 3
        failsafe_at: list[float | None] = [None] * 3
        failsafe_command: list = [None] * 3
        thrust_before = [e.thrust for e in emulators]
        quat_before = plant.command.quat.copy()  # the attitude flown (world frame) when the stream stops
        record["bridge_failsafe_at"] = None

        def watch() -> bool:
            for i, (bridge, emulator) in enumerate(zip(bridges, emulators, strict=True)):
                if bridge.setpoints_sent != sent[i]:
                    sent[i], last_sent[i] = bridge.setpoints_sent, rig.now
                if failsafe_at[i] is None and emulator.counters.failsafes:
                    failsafe_at[i] = rig.now
                    failsafe_command[i] = (plant.command.quat[i].copy(), float(plant.command.thrust[i]))
            if record["bridge_failsafe_at"] is None and all(b.machine.state == BridgeState.FAILSAFE
                                                            for b in bridges):
                record["bridge_failsafe_at"] = rig.now
            return all(t is not None for t in failsafe_at) and rig.now >= max(failsafe_at) + 0.6

        rig.run_until(watch, 2.5, "PX4 failsafe")
        record["stream_stopped_after"] = [t - stop_at for t in last_sent]
        record["last_setpoint_sent_at"] = last_sent
        record["px4_failsafe_at"] = failsafe_at
        record["failsafe_command"] = failsafe_command
        record["thrust_before_loss"] = thrust_before
        record["quat_before_loss"] = quat_before
        record["failsafe_status"] = [rig.status(i) for i in range(3)]
        record["lockstep_timeouts_after_loss"] = sim.lockstep_timeouts
    except AssertionError as error:
        record["failure"] = str(error)
    finally:
        rig.close()
    return record


def _get(record: dict, key: str):
    assert key in record, f"phase not reached: {record['failure']}"
    return record[key]


def test_heartbeat_connects_every_bridge(ground_start):
    connected_at = _get(ground_start, "connected_at")
    assert connected_at <= 0.6  # first HEARTBEAT at 0.5 s (2 Hz), sent unprompted to the bridge's port
    for status in _get(ground_start, "initial_status"):
        assert status.connected and status.state == BridgeState.IDLE and not status.armed
        assert status.mode_name == "POSCTL" and status.battery_voltage == pytest.approx(12.4, abs=0.05)


def test_arming_and_offboard_through_the_state_machine(ground_start):
    stream_start, armed_at = _get(ground_start, "stream_started_at"), _get(ground_start, "armed_at")
    # PX4 has no stream-duration rule for arming (offboardCheck.cpp); in POSCTL the emulator arms at the first ARM
    # (Px4Config.manual_modes_without_rc), sent with the first setpoints
    assert 0.0 <= armed_at - stream_start <= 0.5
    for status in ground_start["armed_status"]:
        assert status.armed and status.state == BridgeState.WARMUP and not status.offboard
    requested = _get(ground_start, "offboard_requested_at")
    for t in requested:
        assert t is not None and t - stream_start >= OffboardConfig().offboard_warmup - 1e-9  # >= 1.2 s of stream
    assert ground_start["offboard_at"] - max(requested) <= 0.6  # the next HEARTBEAT (2 Hz) confirms it
    for status in ground_start["offboard_status"]:
        assert status.state == BridgeState.OFFBOARD and status.offboard and status.armed and not status.failsafe
        assert status.mode_name == "OFFBOARD" and status.px4_custom_mode == 6 << 16
        assert status.setpoint_rate >= 50.0
    # 0 N is clamped to thrust_min by the bridge, never sent as 0 (PX4 would see "no thrust")
    assert ground_start["emulator_thrust"] == pytest.approx([BridgeConfig().thrust_min] * 3, rel=1e-6)
    assert ground_start["lockstep_timeouts"] == 0


def test_setpoints_reach_px4_in_ned_frd_and_fly_with_the_battery_normalized_thrust(hover_flight):
    hover = _get(hover_flight, "hover")
    assert hover["states"] == [BridgeState.OFFBOARD] * 3
    assert hover_flight["lockstep_timeouts_streaming"] == 0  # the lockstep never waited in vain on the bridges
    for i in range(3):
        q_local, thrust_newton = hover["setpoints"][i]
        q_world = quat_multiply(quat_from_axis_angle([0.0, 0.0, 1.0], YAW_OFFSETS[i]), q_local)
        print(f"UAV {i + 1}: attitude error {math.degrees(_angle(hover['true_quats'][i], q_world)):.3f} deg, "
              f"tilt {math.degrees(_tilt(hover['true_quats'][i])):.3f} deg, thrust {hover['plant_thrust'][i]:.3f} N "
              f"for {thrust_newton:.3f} N, normalized {hover['emulator_thrust'][i]:.4f}")
        # ENU/FLU -> NED/FRD in the bridge, NED/FRD -> ENU/FLU in the emulator: float32 on the wire
        assert _angle(hover["emulator_quat_local"][i], q_local) < 1e-6
        # the emulated PX4 flies it in its own frame F0i: in the world, yaw offset o local setpoint
        assert math.degrees(_angle(hover["true_quats"][i], q_world)) < 2.5  # frame errors: >= 17 deg
        # thrust: N -> normalized by (C.1)-(C.2) with Table C.1's a_f, b_f and PX4's reported voltage ...
        coefficients = thrust_coefficients(i + 1)
        voltage = hover["bridge_voltages"][i]
        expected = thrust_newton / max_thrust(voltage, coefficients.a_f, coefficients.b_f)
        assert 0.2 < expected < 0.8
        assert hover["emulator_thrust"][i] == pytest.approx(expected, rel=1e-6)  # float32 on the wire
        # ... and back to newtons by the plant's own battery and thrust curve (the same Table C.1 rows)
        assert hover["plant_max_thrust"][i] == pytest.approx(
            max_thrust(voltage, coefficients.a_f, coefficients.b_f), rel=0.01)
        assert hover["plant_thrust"][i] == pytest.approx(thrust_newton, rel=0.02)
    assert math.degrees(_tilt(hover["true_quats"][0])) < 1.5  # the level setpoint flies level (3.2 deg before)


def test_telemetry_is_in_each_uav_local_enu_frame_and_flu_body(hover_flight):
    hover = _get(hover_flight, "hover")
    for i in range(3):
        imu, velocity = hover["imu"][i], hover["velocity"][i]
        assert imu.stamp == pytest.approx(hover["time"], abs=0.03)
        # orientation in F0i (its yaw offset included), not in the world frame: attitude noise 0.002 rad/axis
        assert _angle(imu.orientation, hover["true_local_quats"][i]) < 0.01
        assert _angle(imu.orientation, hover["true_quats"][i]) > abs(YAW_OFFSETS[i]) - 0.05
        # FLU body rates: truth + the UAV's constant gyro bias, noise 0.003 rad/s
        assert np.allclose(imu.angular_velocity, hover["true_rates"][i] + hover["gyro_bias"][i], atol=0.015)
        # FLU body velocity: R^T v_world of the truth; velocity noise 0.02 m/s per axis
        v_body = quat_to_rotmat(hover["true_quats"][i]).T @ hover["true_velocities"][i]
        assert np.allclose(velocity.linear, v_body, atol=0.08)
        assert v_body[2] > 0.3 and velocity.linear[2] > 0.2  # climbing, body z up (FLU, not FRD)


def test_setpoint_stream_loss_stops_the_bridge_and_triggers_the_px4_failsafe(hover_flight):
    failsafe_at = _get(hover_flight, "px4_failsafe_at")
    setpoint_timeout = BridgeConfig().setpoint_timeout
    loss_timeout = Px4Config().offboard_loss_timeout  # COM_OF_LOSS_T
    for stopped_after, last_sent, t_failsafe in zip(hover_flight["stream_stopped_after"],
                                                    hover_flight["last_setpoint_sent_at"], failsafe_at, strict=True):
        # the bridge repeats the last setpoint for setpoint_timeout, then stops (within one period)
        assert setpoint_timeout - CONTROL_PERIOD <= stopped_after <= setpoint_timeout + CONTROL_PERIOD + 1e-9
        # PX4: COM_OF_LOSS_T after the last setpoint (checked at 250 Hz, observed every 20 ms)
        assert loss_timeout <= t_failsafe - last_sent <= loss_timeout + 2 * CONTROL_PERIOD + 1e-9
    bridge_failsafe_at = hover_flight["bridge_failsafe_at"]
    assert bridge_failsafe_at is not None
    assert bridge_failsafe_at - hover_flight["stop_at"] <= setpoint_timeout + 2 * CONTROL_PERIOD
    for status in hover_flight["failsafe_status"]:
        assert status.failsafe and status.state == BridgeState.FAILSAFE and status.connected
        assert status.mode_name == "AUTO.LOITER" and status.armed and not status.offboard
        assert status.px4_custom_mode == (Px4MainMode.AUTO << 16 | Px4AutoSubMode.LOITER << 24)
    for (quat, thrust), before, quat_before in zip(hover_flight["failsafe_command"],
                                                   hover_flight["thrust_before_loss"],
                                                   hover_flight["quat_before_loss"], strict=True):
        # Hold is PX4's position controller (fpr_sim.px4_position_control): the robot climbs ~2 m/s when the stream
        # stops, so Hold brakes: less thrust than the last setpoint, within MPC_THR_MIN..MAX and MPC_TILTMAX_AIR
        pc = scenario_from_dict({}).px4.position_control
        assert pc.thr_min - 1e-9 <= thrust < before
        assert _tilt(quat) <= pc.tilt_max + 1e-6 and _angle(quat, quat_before) <= pc.tilt_max + 1e-6
    # the lockstep waited once in vain for the stopped streams, then let PX4's failsafe play out
    assert hover_flight["lockstep_timeouts_after_loss"] == 1


# ------------------------------------------------------------------------------------------------ ROS node
CLOCK_STEP = 0.004  # [s] /clock period of the node test: 250 Hz of simulation time, as the simulator (DESIGN.md §5)
#: [s] wall: the lockstep's wait for the bridge's setpoint. The test waits for each bridge tick, so the setpoint is
#: on PX4's socket before the simulation reaches the boundary: the lockstep waits only once, in vain, at the silence
NODE_LOCKSTEP_TIMEOUT = 0.2
WALL_LIMIT = 60.0  # [s] hang guard per phase; the phases themselves are judged in simulation time only


def test_the_bridges_telemetry_rates_reach_the_emulated_px4_and_attitude_stops():
    """The default message_rates (fpr_px4_bridge.streams) against fpr_sim's emulators: each PX4 takes them
    (SET_MESSAGE_INTERVAL, ACKed), ATTITUDE stops reaching the bridge, the IMU and local position stay at 50 Hz."""
    rig = Rig(_scenario("ground"), message_rates=parse_message_rates(DEFAULT_MESSAGE_RATES))
    try:
        kinds: list[dict[str, int]] = [{} for _ in range(3)]
        for i, bridge in enumerate(rig.bridges):
            def counting(msg, now, handle=bridge.handle_message, seen=kinds[i]):
                seen[msg.get_type()] = seen.get(msg.get_type(), 0) + 1
                return handle(msg, now)
            bridge.handle_message = counting
        done_at = rig.run_until(lambda: all(b.streams.done and b.streams.rounds == 1 for b in rig.bridges), 2.0,
                                "telemetry rates answered")
        assert done_at <= 0.8  # first HEARTBEAT at 0.5 s, then four ACKed requests one period apart
        for emulator in rig.sim.emulators:
            assert emulator.intervals[30] is None  # ATTITUDE stopped
            assert emulator.intervals[31] == emulator.intervals[105] == emulator.intervals[32] == 20000
        rig.run_until(lambda: rig.now >= done_at + 0.1, 1.0, "in flight")  # frames in flight before the stop
        for seen in kinds:
            seen.clear()
        rig.run_until(lambda: rig.now >= done_at + 1.1 - 1e-9, 2.0, "one more second")
        for seen in kinds:
            assert "ATTITUDE" not in seen, seen
            for kind in ("ATTITUDE_QUATERNION", "HIGHRES_IMU", "LOCAL_POSITION_NED"):
                assert seen[kind] == pytest.approx(50, abs=1), (kind, seen)
    finally:
        rig.close()


def _wait_wall(condition, timeout: float, what: str) -> None:
    """Wait (wall clock, a hang guard only) until ``condition()``, leaving the GIL to the executor threads."""
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"{what}: not within {timeout} s of wall time (hang guard)"
        time.sleep(0.0002)


def test_px4_bridge_node_flies_the_emulated_px4_on_default_ports():
    """All on simulation time, as in the real system: the test thread is the simulator (it advances the core in
    lockstep by CLOCK_STEP, publishes /clock, and waits until the bridge node's clock shows it, so no /clock value
    is skipped and nothing races ahead) and the controller (setpoint and teleop mode at each 20 ms control period
    of simulation time); the bridge node runs with use_sim_time, so its stream timer, timeouts, warm-up, retries
    and status are simulation time and its stream is deterministic relative to it."""
    rclpy = pytest.importorskip("rclpy")
    from fpr_px4_bridge.px4_bridge_node import Px4BridgeNode
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
    from rclpy.time import Time
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import Imu

    from fpr_msgs.msg import AttitudeThrustSetpoint, TeleopCommand, UavStatus

    sim = Simulation(_scenario("ground"), SimulationOptions(lockstep=True, lockstep_timeout=NODE_LOCKSTEP_TIMEOUT,
                                                            lockstep_on_timeout="continue"))  # silenced on purpose
    context = rclpy.Context()
    rclpy.init(context=context)
    executor = SingleThreadedExecutor(context=context)
    spinning = threading.Event()
    spinner = None
    bridge = test_node = None
    sim_time = [Parameter("use_sim_time", value=True)]
    try:
        assert sim.ports == [14580, 14581, 14582] and sim.remote_ports == [14540, 14541, 14542]  # 14580+ -> 14540+
        # swarm guard off: this test is PX4's own offboard-loss failsafe (COM_OF_LOSS_T) against the bridge's FAILSAFE
        # state; with the guard (the default) a silent controller is an EMERGENCY in which the bridge commands Hold
        # itself (src/fpr_px4_bridge/test/test_node.py, tests/test_fault_response.py)
        bridge = Px4BridgeNode(context=context, namespace="/fpr/uav1", parameter_overrides=sim_time + [
            Parameter("uav_id", value=1), Parameter("command_max_attempts", value=20),
            Parameter("swarm_guard", value=False)])  # default connection URL
        assert bridge.link.local_address == ("127.0.0.1", 14540)
        test_node = rclpy.create_node("bridge_emulator_test", context=context, parameter_overrides=sim_time)
        statuses, imus = [], []
        test_node.create_subscription(UavStatus, "/fpr/uav1/status", statuses.append, 10)
        test_node.create_subscription(Imu, "/fpr/uav1/imu", imus.append, qos_profile_sensor_data)
        best_effort = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
        clock_pub = test_node.create_publisher(Clock, "/clock", 10)
        teleop_pub = test_node.create_publisher(TeleopCommand, "/fpr/teleop", best_effort)
        setpoint_pub = test_node.create_publisher(AttitudeThrustSetpoint, "/fpr/uav1/setpoint", best_effort)
        executor.add_node(bridge)
        executor.add_node(test_node)
        spinning.set()

        def spin() -> None:
            while spinning.is_set():
                executor.spin_once(timeout_sec=0.05)

        spinner = threading.Thread(target=spin, daemon=True)
        spinner.start()
        _wait_wall(lambda: clock_pub.get_subscription_count() >= 2 and teleop_pub.get_subscription_count() >= 1
                   and setpoint_pub.get_subscription_count() >= 1 and bridge.status_pub.get_subscription_count() >= 1
                   and bridge.imu_pub.get_subscription_count() >= 1, 10.0, "discovery")

        emulator = sim.emulators[0]
        command = {"mode": TeleopCommand.MODE_IDLE, "setpoint": None}
        stream = {"count": 0, "first_at": None, "last_at": None}  # setpoints received by PX4 1 (simulation time)
        ticks: list[float] = []  # the bridge's periodic steps (stream, commands, HEARTBEAT), at its clock
        bridge_tick = bridge.bridge.tick

        def recorded_tick(now: float):
            ticks.append(now)
            return bridge_tick(now)

        bridge.bridge.tick = recorded_tick  # observed, not changed: the lockstep below waits for each tick
        steps_per_period = int(round(CONTROL_PERIOD * sim.options.physics_rate))

        def step() -> None:
            """CLOCK_STEP of simulation (lockstep), /clock, then at each control period the controller's output."""
            sim.advance(CLOCK_STEP)
            if emulator.counters.setpoints != stream["count"]:
                stream["count"], stream["last_at"] = emulator.counters.setpoints, sim.time
                stream["first_at"] = stream["first_at"] or sim.time
            stamp = Time(nanoseconds=int(round(sim.time * 1e9)))
            clock_pub.publish(Clock(clock=stamp.to_msg()))
            _wait_wall(lambda: bridge.get_clock().now().nanoseconds >= stamp.nanoseconds, WALL_LIMIT,
                       f"bridge clock at {sim.time:.3f} s")
            if sim.plant.steps % steps_per_period == 0:
                # the bridge's stream timer (50 Hz of simulation time) has run at this control period: what it sent
                # is on PX4's socket before the simulation moves on (the lockstep then sees it at this very time)
                _wait_wall(lambda: ticks and ticks[-1] >= sim.time - 1e-6, WALL_LIMIT,
                           f"bridge tick at {sim.time:.3f} s")
                teleop = TeleopCommand()
                teleop.mode = command["mode"]
                teleop_pub.publish(teleop)
                if command["setpoint"] is not None:
                    q, thrust = command["setpoint"]
                    msg = AttitudeThrustSetpoint()
                    msg.header.stamp = stamp.to_msg()
                    msg.uav_id = 1
                    msg.attitude.w, msg.attitude.x, msg.attitude.y, msg.attitude.z = (float(v) for v in q)
                    msg.thrust = float(thrust)
                    setpoint_pub.publish(msg)

        def run_until(condition, sim_timeout: float, what: str) -> float:
            """Step until ``condition()`` (at most ``sim_timeout`` s of simulation); return the simulation time."""
            sim_deadline, wall_deadline = sim.time + sim_timeout, time.monotonic() + WALL_LIMIT
            while not condition():
                assert sim.time < sim_deadline, \
                    f"{what}: not reached within {sim_timeout} s of simulation (last status " \
                    f"{statuses[-1] if statuses else None})"
                assert time.monotonic() < wall_deadline, f"{what}: hang guard ({WALL_LIMIT} s wall)"
                step()
            return sim.time

        run_until(lambda: statuses and statuses[-1].connected and imus, 3.0, "connected")
        assert statuses[-1].state == UavStatus.STATE_IDLE and statuses[-1].mode_name == "POSCTL"
        assert not statuses[-1].armed and not statuses[-1].failsafe
        orientation = imus[-1].orientation
        q_local = np.array([orientation.w, orientation.x, orientation.y, orientation.z])
        q_local /= np.linalg.norm(q_local)
        thrust_newton = 0.5 * float(np.linalg.norm(_hover_forces(sim.plant)[0]))  # stays on the ground
        command["setpoint"] = (q_local, thrust_newton)  # the present attitude, in UAV 1's own frame
        command["mode"] = TeleopCommand.MODE_ARM
        arm_at = sim.time
        armed_at = run_until(lambda: emulator.armed, 6.0, "armed")
        # no stream-duration rule for arming (PX4's offboardCheck.cpp): armed at the first ARM in POSCTL
        armed_after = armed_at - stream["first_at"]
        assert 0.0 <= armed_after <= OffboardConfig().command_retry_interval + 2 * CONTROL_PERIOD + CLOCK_STEP
        command["mode"] = TeleopCommand.MODE_FLY
        run_until(lambda: statuses[-1].state == UavStatus.STATE_OFFBOARD and statuses[-1].offboard, 8.0, "OFFBOARD")
        # the rotors take their load (and the battery sags) only in OFFBOARD: let one BATTERY_STATUS through so
        # the bridge's voltage and the reported one agree before checking the thrust normalization
        settle = sim.time
        run_until(lambda: sim.time >= settle + 0.6, 1.0, "battery status")
        status = statuses[-1]
        # confirmed by PX4's HEARTBEAT: custom_mode OFFBOARD (main mode 6)
        assert status.px4_custom_mode == Px4MainMode.OFFBOARD << 16 and status.mode_name == "OFFBOARD"
        assert emulator.offboard and status.armed and not status.failsafe
        requested_at = bridge.bridge.machine.offboard_requested_at
        assert requested_at is not None and requested_at - arm_at >= OffboardConfig().offboard_warmup
        assert _angle(emulator.quat_local, q_local) < 1e-6
        coefficients = thrust_coefficients(1)
        assert emulator.thrust == pytest.approx(
            thrust_newton / max_thrust(status.battery_voltage, coefficients.a_f, coefficients.b_f), rel=0.02)
        orientation = imus[-1].orientation
        q_imu = [orientation.w, orientation.x, orientation.y, orientation.z]
        q_truth_local = sim.sensors.world_to_local_quat(0, sim.plant.fleet.quat[0])
        # in UAV 1's local frame F0i (yaw offset 0.3 rad from the world); the message may be a few periods old
        assert _angle(q_imu, q_truth_local) < 0.15 < _angle(q_imu, sim.plant.fleet.quat[0])
        # time_boot_ms -> ROS time: PX4's boot clock is the simulation clock here, so the offset is ~0 (at most
        # the /clock lag behind the MAVLink telemetry) and the IMU stamps are simulation times
        offset = bridge.bridge.telemetry.mapper.offset
        assert offset is not None and abs(offset) <= CONTROL_PERIOD  # receive-thread / /clock lag, either sign
        imu_stamp = Time.from_msg(imus[-1].header.stamp).nanoseconds * 1e-9
        assert sim.time - 3 * CONTROL_PERIOD <= imu_stamp <= sim.time + CONTROL_PERIOD

        # the stream in simulation time, from its start to OFFBOARD (> 2 s): >= 50 Hz at PX4, and as the bridge
        # reports it (over its last second)
        rate_at_px4 = (stream["count"] - 1) / (stream["last_at"] - stream["first_at"])
        print(f"setpoints at PX4: {rate_at_px4:.1f} Hz over {stream['last_at'] - stream['first_at']:.2f} s "
              f"(simulation time), bridge status {status.setpoint_rate} Hz, armed {armed_after:.3f} s after "
              f"the first setpoint, OFFBOARD requested after {requested_at - arm_at:.3f} s")
        assert rate_at_px4 >= 50.0 and status.setpoint_rate >= 50.0

        # the controller goes silent: the bridge repeats the last setpoint for setpoint_timeout, then stops (its
        # failsafe); PX4's offboard-loss failsafe (COM_OF_LOSS_T) takes over: AUTO.LOITER
        command["setpoint"] = None
        stop_at = sim.time  # the last setpoint was published at this control period
        failsafe_at = run_until(lambda: emulator.counters.failsafes >= 1, 3.0, "PX4 failsafe")
        assert emulator.main_mode == Px4MainMode.AUTO
        setpoint_timeout = BridgeConfig().setpoint_timeout
        stopped_after = stream["last_at"] - stop_at
        assert setpoint_timeout - CONTROL_PERIOD <= stopped_after <= setpoint_timeout + CONTROL_PERIOD + CLOCK_STEP
        loss_timeout = Px4Config().offboard_loss_timeout  # COM_OF_LOSS_T
        assert loss_timeout - CLOCK_STEP <= failsafe_at - stream["last_at"] <= loss_timeout + 2 * CLOCK_STEP
        run_until(lambda: statuses[-1].failsafe and statuses[-1].mode_name == "AUTO.LOITER", 2.0, "status failsafe")
        status = statuses[-1]
        assert status.state == UavStatus.STATE_FAILSAFE and status.connected and status.armed
        assert status.px4_custom_mode == (Px4MainMode.AUTO << 16 | Px4AutoSubMode.LOITER << 24)
        print(f"stream stopped {stopped_after:.3f} s after the last setpoint, PX4 failsafe "
              f"{failsafe_at - stream['last_at']:.3f} s after the last frame; lockstep timeouts "
              f"{sim.lockstep_timeouts}")
        assert sim.lockstep_timeouts == 1  # only at the silence: every tick's setpoint was there in time
    finally:
        spinning.clear()  # stop spinning before anything is destroyed (no callback on a destroyed handle)
        if spinner is not None:
            spinner.join(timeout=5.0)
        executor.shutdown(timeout_sec=2.0)
        if bridge is not None:
            bridge.destroy_node()
        if test_node is not None:
            test_node.destroy_node()
        sim.close()
        rclpy.try_shutdown(context=context)
