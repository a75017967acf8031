"""Standard MAVLink clients against the simulator's PX4 emulation (issue 13): MAVSDK (the self-contained 4.x wheel,
no server process) flies its own offboard flow on each of the 3 vehicles at once — connect, telemetry with a
message-interval request, one setpoint then OFFBOARD, arm, hold position, Hold (AUTO.LOITER) and offboard stop,
10 s of Hold, Land, disarm — against ``python -m fpr_sim.simulator`` in its own process (= ``ros2 run fpr_sim
simulator``), with the simulator's lockstep on and off. MAVSDK keeps its own clock in ``time_boot_ms``: with the
lockstep on, the simulator must see that and run those links paced instead of waiting for them.

Time: the simulator runs at real_time_factor 1; durations that matter (the 10 s of Hold) are measured in simulated
time from ``/clock``; wall-clock limits only bound the waits. The scenario is ``ground_start`` (on the ground,
disarmed, legs at 60°): every vehicle is one of the robot's three, each MAVSDK client flies its vehicle alone (a
position setpoint 1 m above where it stands), and the emulated PX4s' position controllers together lift and hold
the structure.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time

import pytest
from mavsdk.component_type import ComponentType
from mavsdk.mavsdk import Configuration, Mavsdk
from mavsdk.plugins.action.action import Action
from mavsdk.plugins.offboard.offboard import Offboard, PositionNedYaw
from mavsdk.plugins.telemetry.telemetry import FlightMode, Telemetry

N = 3
LOCAL_BASE, REMOTE_BASE = 24580, 24540  # not the defaults: nothing else of the suite can answer there
REAL_TIME_FACTOR = 1.0  # 2.0 starved the test's MAVSDK callbacks on a loaded CI machine (10.4 Hz counted for 20)
RATE_WINDOW = 4.0  # [s] simulated: the LOCAL_POSITION_NED rate is counted over this window
HOLD_SECONDS = 10.0  # [s] simulated


class SimulatedClock:
    """The simulator's /clock, read on demand: a subscription of depth 1 keeps only the latest stamp, taken when the
    test asks for :attr:`now`. No spinning thread: one rclpy callback per /clock (250 Hz) in this process took the
    GIL from MAVSDK's callback threads, and on a loaded machine the test counted 12.45 Hz of the 20 Hz of
    LOCAL_POSITION_NED the emulator sent (CI; every message was on the wire, 50 ms apart in time_boot_ms)."""

    def __init__(self) -> None:
        import rclpy
        from rclpy.qos import QoSProfile
        from rosgraph_msgs.msg import Clock

        self._rclpy = rclpy
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node("mavsdk_test_clock", context=self.context)
        self._now, self._fresh = 0.0, False
        self.node.create_subscription(Clock, "/clock", self._on_clock, QoSProfile(depth=1))
        self.executor = rclpy.executors.SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def _on_clock(self, msg) -> None:
        self._now = msg.clock.sec + 1e-9 * msg.clock.nanosec
        self._fresh = True

    @property
    def now(self) -> float:
        """The latest /clock [s] (simulated): waits (at most 0.5 s of wall time) for a /clock newer than the last
        one read, so that a window's start and end are both fresh (the 250 Hz /clock: a few ms)."""
        self._fresh = False
        deadline = time.monotonic() + 0.5
        while not self._fresh and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.05)
        return self._now

    def wait_for(self, seconds: float, wall_limit: float) -> None:
        """Sleep until ``seconds`` of simulated time passed (at most ``wall_limit`` wall seconds)."""
        start, deadline = self.now, time.monotonic() + wall_limit
        while self.now - start < seconds:
            assert time.monotonic() < deadline, f"simulated time stalled at {self._now:.2f} s"
            time.sleep(0.02)

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=0.0)
        self.node.destroy_node()
        self._rclpy.shutdown(context=self.context)


class Vehicle:
    """One MAVSDK instance (a ground station, system 245) connected to UAV ``index``'s emulated PX4."""

    def __init__(self, index: int) -> None:
        self.index = index
        self.mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
        self.mavsdk.add_any_connection(f"udpin://127.0.0.1:{REMOTE_BASE + index}")
        self.system = self.mavsdk.first_autopilot(20.0)
        assert self.system is not None, f"uav{index + 1}: MAVSDK found no autopilot on port {REMOTE_BASE + index}"
        self.telemetry = Telemetry(self.system)
        self.offboard = Offboard(self.system)
        self.action = Action(self.system)
        self.positions: list = []
        self.mode = FlightMode.UNKNOWN
        self.armed: bool | None = None
        self.telemetry.subscribe_position_velocity_ned(lambda value, _: self.positions.append(value.position))
        self.telemetry.subscribe_flight_mode(lambda value, _: setattr(self, "mode", value))
        self.telemetry.subscribe_armed(lambda value, _: setattr(self, "armed", value))

    @property
    def yaw_deg(self) -> float:
        """The latest ATTITUDE's yaw [deg], read once when needed: a subscription would run a Python callback per
        ATTITUDE (100 Hz per vehicle), which on a slow machine backs up MAVSDK's callback queue and delays the
        position callbacks the test counts."""
        return self.telemetry.attitude_euler().yaw_deg

    @property
    def down(self) -> float:
        return self.positions[-1].down_m

    def close(self) -> None:
        self.mavsdk.destroy()


def _wait(condition, what: str, wall_limit: float = 20.0) -> None:
    deadline = time.monotonic() + wall_limit
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.02)


@pytest.fixture
def simulator(request):
    from ament_index_python.packages import get_package_share_directory

    scenario = os.path.join(get_package_share_directory("fpr_sim"), "config", "scenarios", "ground_start.yaml")
    log = tempfile.TemporaryFile(mode="w+")
    process = subprocess.Popen(
        [sys.executable, "-m", "fpr_sim.simulator", "--ros-args", "-p", f"scenario_file:={scenario}",
         "-p", f"real_time_factor:={REAL_TIME_FACTOR}", "-p", f"lockstep:={str(request.param).lower()}",
         "-p", f"local_base_port:={LOCAL_BASE}", "-p", f"remote_base_port:={REMOTE_BASE}",
         "-p", "emulated_cameras:=true"], stdout=log, stderr=subprocess.STDOUT, text=True)
    clock = SimulatedClock()
    try:
        yield process, clock, log
    finally:
        clock.close()
        if process.poll() is None:
            process.terminate()
            process.wait(timeout=20.0)
        log.close()


def _simulator_log(log) -> str:
    log.flush()
    log.seek(0)
    return log.read()


@pytest.mark.parametrize("simulator", [True, False], ids=["lockstep", "free_running"], indirect=True)
def test_mavsdk_offboard_flow_and_telemetry_on_three_vehicles(simulator):
    process, clock, log = simulator
    vehicles = [Vehicle(i) for i in range(N)]
    try:
        # telemetry, and a message-interval request (SET_MESSAGE_INTERVAL) answered ACCEPTED
        for v in vehicles:
            v.telemetry.set_rate_position_velocity_ned(20.0)
        _wait(lambda: all(len(v.positions) > 10 and v.armed is not None for v in vehicles), "telemetry")
        assert not any(v.armed for v in vehicles)
        count, start, wall_start = [len(v.positions) for v in vehicles], clock.now, time.monotonic()
        clock.wait_for(RATE_WINDOW, wall_limit=40.0)
        counts, end, wall_end = [len(v.positions) - c for v, c in zip(vehicles, count, strict=True)], clock.now, \
            time.monotonic()
        rates = [c / (end - start) for c in counts]
        wall_rates = [c / (wall_end - wall_start) for c in counts]
        print(f"rate window: {counts} messages in {end - start:.3f} s simulated, {wall_end - wall_start:.3f} s wall")
        # Per simulated second (the emulator's schedule) or, on a machine so loaded that the window's simulated
        # and wall times part, per wall second: CI twice counted 50 messages in 4.0 s simulated and 2.0 s wall
        # while the simulator paces at real_time_factor 1 (cause not found; on a quiet machine and under two CPU
        # burners both clocks agree and 80 arrive; the wall band is wider: 25.2 Hz was counted there). Either fails
        # for an interval not honoured (the default 50 Hz, or the stream disabled).
        assert all(15.0 < rate < 25.0 for rate in rates) or all(15.0 < rate < 30.0 for rate in wall_rates), (
            f"LOCAL_POSITION_NED at {rates} Hz simulated, {wall_rates} Hz wall, asked 20 Hz ({counts} messages in "
            f"{end - start:.3f} s simulated, {wall_end - wall_start:.3f} s wall; /clock publishers: "
            f"{clock.node.count_publishers('/clock')})")

        # MAVSDK's offboard flow: one setpoint (1 m above the present position), start (OFFBOARD while disarmed:
        # PX4 needs only a setpoint younger than COM_OF_LOSS_T), arm, fly there
        ground = [v.positions[-1] for v in vehicles]
        for v, p in zip(vehicles, ground, strict=True):
            v.offboard.set_position_ned(PositionNedYaw(p.north_m, p.east_m, p.down_m - 1.0, v.yaw_deg))
        for v in vehicles:
            v.offboard.start()
        _wait(lambda: all(v.mode == FlightMode.OFFBOARD for v in vehicles), "OFFBOARD (disarmed) on every vehicle")
        for v in vehicles:
            v.action.arm()
        clock.wait_for(6.0, wall_limit=40.0)
        assert all(v.mode == FlightMode.OFFBOARD and v.armed for v in vehicles)
        for v, p in zip(vehicles, ground, strict=True):
            assert abs(v.down - (p.down_m - 1.0)) < 0.2, f"uav{v.index + 1} not at its offboard position setpoint"

        # Hold, offboard stop: PX4's AUTO.LOITER holds the altitude where it was entered
        for v in vehicles:
            v.action.hold()
        for v in vehicles:
            v.offboard.stop()
        _wait(lambda: all(v.mode == FlightMode.HOLD for v in vehicles), "HOLD on every vehicle")
        held = [v.down for v in vehicles]
        worst = [0.0] * N
        start = clock.now
        while clock.now - start < HOLD_SECONDS:
            assert process.poll() is None, _simulator_log(log)
            worst = [max(w, abs(v.down - h)) for w, v, h in zip(worst, vehicles, held, strict=True)]
            time.sleep(0.02)
        assert max(worst) < 0.3, f"altitude deviation in {HOLD_SECONDS:g} s of Hold: {worst} m"

        # Land: descends, touches down, disarms by itself (COM_DISARM_LAND); a disarm then is accepted
        for v in vehicles:
            v.action.land()
        _wait(lambda: all(v.armed is False for v in vehicles), "disarm on touchdown", wall_limit=60.0)
        for v in vehicles:
            v.action.disarm()
    finally:
        for v in vehicles:
            v.close()
    assert process.poll() is None, _simulator_log(log)
    output = _simulator_log(log)
    assert "Traceback" not in output, output
    if "lockstep:=true" in " ".join(process.args):
        # every MAVSDK link was recognised as keeping its own clock, said once per link, and never stalled
        assert output.count("its client keeps its own clock") == N, output
        assert "timed out waiting" not in output, output
