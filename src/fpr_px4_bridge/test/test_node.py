"""px4_bridge node in process (real rclpy) against a fake PX4 on 127.0.0.1: the issue's acceptance at the peer.

Everything runs on simulation time (``use_sim_time``, as under the simulator): the test thread is the simulator.
It advances the time by CLOCK_STEP (250 Hz of /clock, DESIGN.md §5), lets the fake PX4 send what is due then,
publishes /clock, waits until the node's clock shows it and, at each control period, until the node's stream
timer has run (so what it sent is on the fake's socket before time moves on), then publishes the controller's
setpoint. Assertions are in simulation time; wall time only bounds waits (hang guards), it is never asserted on.
The simulation starts at START_TIME: the node joins a simulation that already runs.
"""

import math
import threading
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
from fpr_px4_bridge.px4_bridge_node import Px4BridgeNode  # noqa: E402
from rclpy.exceptions import InvalidParameterValueException  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.time import Time  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import Imu  # noqa: E402

from fpr_msgs.msg import AttitudeThrustSetpoint, ControllerStatus, TeleopCommand, UavStatus  # noqa: E402
from fpr_px4_bridge import px4_protocol as p  # noqa: E402

Q_NORTH = (math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4))  # w, x, y, z
SETPOINT_TIMEOUT = 0.2
STREAM_RATE = 50.0
CLOCK_STEP_NS = 4_000_000  # /clock period [ns] (250 Hz)
CONTROL_PERIOD_NS = 20_000_000  # the controller's and the stream timer's period [ns] (50 Hz)
START_TIME = 10.0  # [s] simulation time when the node gets its first /clock
WALL_LIMIT = 30.0  # [s] hang guard of every wait


def wait_for(predicate, timeout=WALL_LIMIT, step=0.0002):
    """Wall-clock wait (hang guard only), leaving the GIL to the executor thread."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(step)
    return predicate()


class SimTime:
    """The test thread as the simulator (see the module doc); ``setpoint``: what the controller publishes."""

    def __init__(self, node, fake, clock_pub, setpoint_pub, statuses) -> None:
        self.node, self.fake, self.clock_pub, self.setpoint_pub = node, fake, clock_pub, setpoint_pub
        self.statuses = statuses
        self.ns = int(START_TIME * 1e9)
        self.setpoint: AttitudeThrustSetpoint | None = None
        #: the own controller's status, published with each setpoint when set (the swarm guard's inputs)
        self.controller_status: ControllerStatus | None = None
        self.controller_status_pub = None
        self.last_publish: float | None = None  # [s] the controller's last setpoint
        self.published: list[float] = []  # [s] stamps of the controller's setpoints
        self.ticks: list[float] = []
        tick = node.bridge.tick

        def recorded_tick(now: float):
            self.ticks.append(now)
            return tick(now)

        node.bridge.tick = recorded_tick  # observed, not changed: step() waits for each tick
        self.sent: list[float] = []  # [s] the bridge's SET_ATTITUDE_TARGET send times (its clock)
        send = node.bridge._send_setpoint

        def recorded_send(now: float) -> bool:
            sent = send(now)
            if sent:
                self.sent.append(now)
            return sent

        node.bridge._send_setpoint = recorded_send  # observed, not changed

    @property
    def now(self) -> float:
        return self.ns * 1e-9

    def step(self) -> None:
        self.ns += CLOCK_STEP_NS
        self.fake.emit_due()
        stamp = Time(nanoseconds=self.ns)
        self.clock_pub.publish(Clock(clock=stamp.to_msg()))
        assert wait_for(lambda: self.node.get_clock().now().nanoseconds >= self.ns), f"node clock at {self.now}"
        if self.ns % CONTROL_PERIOD_NS == 0:
            assert wait_for(lambda: self.ticks and self.ticks[-1] >= self.now - 1e-6), f"tick at {self.now}"
            if self.setpoint is not None:
                self.setpoint.header.stamp = stamp.to_msg()  # the control instant, as the controller stamps it
                self.setpoint_pub.publish(self.setpoint)
                self.last_publish = self.now
                self.published.append(self.now)
            if self.controller_status is not None:
                self.controller_status.header.stamp = stamp.to_msg()
                self.controller_status_pub.publish(self.controller_status)

    def run_until(self, predicate, sim_timeout: float, what: str) -> float:
        deadline = self.now + sim_timeout
        while not predicate():
            last = self.statuses[-1] if self.statuses else None
            assert self.now < deadline, f"{what}: not within {sim_timeout} s of simulation (status {last})"
            self.step()
        return self.now

    def run_for(self, duration: float) -> None:
        end = self.now + duration - 1e-9
        self.run_until(lambda: self.now >= end, duration + 1.0, f"{duration} s")


@pytest.fixture
def graph(fake_px4_factory, free_port):
    """The bridge alone (no swarm guard: its former stale-setpoint FAILSAFE), a fake PX4, a /clock."""
    yield from _graph(fake_px4_factory, free_port, swarm_guard=False)


@pytest.fixture
def guarded_graph(fake_px4_factory, free_port):
    """The same with the swarm guard on."""
    yield from _graph(fake_px4_factory, free_port, swarm_guard=True)


def _graph(fake_px4_factory, free_port, swarm_guard: bool):
    context = rclpy.Context()
    rclpy.init(context=context)
    port = free_port
    sim_time = [Parameter("use_sim_time", value=True)]
    node = Px4BridgeNode(context=context, namespace="/fpr/uav1", parameter_overrides=sim_time + [
        Parameter("uav_id", value=1),
        Parameter("connection_url", value=f"udp://127.0.0.1:{port}"),
        Parameter("setpoint_timeout", value=SETPOINT_TIMEOUT),
        Parameter("stream_rate", value=STREAM_RATE),
        Parameter("offboard_warmup", value=1.0),
        Parameter("status_rate", value=20.0),
        Parameter("px4_boot_clock", value="estimate"),  # the time-sync estimate under test (auto: exact ros_time)
        Parameter("swarm_guard", value=swarm_guard),
    ])
    helper = rclpy.create_node("px4_bridge_test_helper", context=context, parameter_overrides=sim_time)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.add_node(helper)
    spinning = threading.Event()
    spinning.set()

    def spin() -> None:
        while spinning.is_set():
            executor.spin_once(timeout_sec=0.05)

    spinner = threading.Thread(target=spin, daemon=True)
    spinner.start()
    clock = {"sim": None}
    fake = fake_px4_factory(("127.0.0.1", port), clock=lambda: clock["sim"].now).start()
    qos = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
    clock_pub = helper.create_publisher(Clock, "/clock", 10)
    setpoint_pub = helper.create_publisher(AttitudeThrustSetpoint, "/fpr/uav1/setpoint", qos)
    teleop_pub = helper.create_publisher(TeleopCommand, "/fpr/teleop", qos)
    controller_status_pub = helper.create_publisher(ControllerStatus, "/fpr/uav1/controller_status", qos)
    statuses, imus = [], []
    helper.create_subscription(UavStatus, "/fpr/uav1/status", statuses.append, 10)
    helper.create_subscription(Imu, "/fpr/uav1/imu", imus.append, qos)
    sim = clock["sim"] = SimTime(node, fake, clock_pub, setpoint_pub, statuses)
    sim.controller_status_pub = controller_status_pub
    assert wait_for(lambda: setpoint_pub.get_subscription_count() > 0 and teleop_pub.get_subscription_count() > 0
                    and (not swarm_guard or controller_status_pub.get_subscription_count() > 0)
                    and clock_pub.get_subscription_count() >= 2 and node.status_pub.get_subscription_count() > 0
                    and node.imu_pub.get_subscription_count() > 0, timeout=10.0), "discovery"
    yield node, fake, sim, teleop_pub, statuses, imus
    spinning.clear()  # stop spinning before anything is destroyed (no callback on a destroyed handle)
    spinner.join(timeout=5.0)
    executor.shutdown()
    node.destroy_node()
    helper.destroy_node()
    rclpy.shutdown(context=context)


def setpoint(q=Q_NORTH, thrust=10.0, uav_id=1):
    msg = AttitudeThrustSetpoint()
    msg.uav_id = uav_id
    msg.attitude.w, msg.attitude.x, msg.attitude.y, msg.attitude.z = q
    msg.thrust = thrust
    return msg


def teleop(mode):
    msg = TeleopCommand()
    msg.mode = mode
    return msg


def test_mavlink_before_the_first_clock_is_dropped_and_stamps_are_simulation_time(graph):
    node, fake, sim, teleop_pub, statuses, imus = graph
    # the fake PX4 talks (HEARTBEAT, telemetry at time_boot_ms = 10 s) before the node has any /clock: with its
    # clock at 0 it must not use them (they would put the boot-time offset 10 s off for the next 200 samples)
    fake.emit_due()
    assert wait_for(lambda: node.link.counters.rx_frames >= 5)
    assert node.bridge.telemetry.mapper.offset is None and not node.bridge.machine.custom_mode_seen
    sim.run_until(lambda: statuses and statuses[-1].connected and imus, 1.0, "connected")
    # PX4's boot clock is the simulation clock here: offset ~0, IMU stamps are simulation times (a 50 ms grid)
    # the offset is biased by how far the /clock and the receive thread lag each other (either sign): bounded
    # by one control period, far from the 10 s a pre-/clock sample would have caused
    assert abs(node.bridge.telemetry.mapper.offset) <= 0.020
    stamp = Time.from_msg(imus[-1].header.stamp).nanoseconds * 1e-9
    assert sim.now - 0.1 <= stamp <= sim.now + 0.020
    assert stamp == pytest.approx(round(stamp / 0.05) * 0.05, abs=0.021)  # the 50 ms grid, shifted by the offset
    status = statuses[-1]
    assert Time.from_msg(status.header.stamp).nanoseconds * 1e-9 == pytest.approx(sim.now, abs=0.1)
    assert status.state == UavStatus.STATE_IDLE and status.link_age <= 0.2  # HEARTBEAT at 10 Hz


def test_fly_stream_rate_offboard_after_warmup_and_stale_stop(graph):
    node, fake, sim, teleop_pub, statuses, imus = graph
    sim.run_until(lambda: statuses and statuses[-1].connected, 1.0, "connected")
    teleop_pub.publish(teleop(TeleopCommand.MODE_FLY))
    sim.run_until(lambda: fake.armed, 2.0, "armed")
    # the controller publishes at 50 Hz (simulation time) for 2.5 s
    sim.setpoint = setpoint()
    sim.run_for(2.5)
    sim.setpoint = None
    last_publish = sim.last_publish
    sim.run_until(lambda: statuses[-1].offboard and statuses[-1].state == UavStatus.STATE_OFFBOARD, 0.2, "OFFBOARD")
    sim.run_for(SETPOINT_TIMEOUT + 1.5)
    # the bridge's send times (simulation time); every frame reached the peer
    times = np.array(sim.sent)
    with fake.lock:
        boot_ms = np.array([r.msg.time_boot_ms for r in fake.setpoints])
    assert len(boot_ms) == len(times)
    # time_boot_ms is the SETPOINT's instant (its header stamp) on PX4's boot clock (here the simulation clock,
    # mapped through the telemetry offset), the same on every repetition: one value per published setpoint
    offset = node.bridge.telemetry.mapper.offset
    # the fake's telemetry and the bridge's /clock lag each other by a /clock step (4 ms) or more when a thread
    # lags: the offset is biased by at most one control period, either sign (measured -8 and +8 ms)
    assert offset is not None and abs(offset) <= 0.020
    expected = np.round((np.array(sim.published) - offset) * 1000.0).astype(int)
    distinct = np.unique(boot_ms)
    # one stamp per published setpoint, each its header stamp mapped with the offset estimated at that moment:
    # the estimate may move by a /clock step or so while the executor lags (loaded machine), never by a period
    assert len(distinct) == len(expected), (distinct[:5], expected[:5])
    assert np.abs(distinct - expected).max() <= 1000.0 * 0.020, (distinct[:5], expected[:5])
    assert np.all(np.diff(boot_ms) >= 0) and len(boot_ms) > len(distinct)  # repetitions keep their stamp
    # exactly 50 Hz at the peer over the whole stream (simulation time): one frame per stream period, give or take
    # the one period the first repetition may add (+2 periods after the last setpoint, below); the span is counted in
    # whole periods (rounded) so that the float sum of 4 ms /clock steps cannot move the bound (CI: 1.0000000000000853)
    span = times[-1] - times[0]
    periods = int(round(STREAM_RATE * span))
    assert span > 2.5 and abs(len(times) - 1 - periods) <= 1, (len(times), span)
    # while the controller publishes at 50 Hz, each setpoint is sent once (no doubled frames), within a /clock
    # step of its publication; repetitions only after the last one (until setpoint_timeout)
    publishing = times < last_publish + 1.5 / STREAM_RATE  # the first repetition comes at +2 periods
    assert len(np.unique(boot_ms[publishing])) == publishing.sum() == len(sim.published)
    assert np.diff(times[publishing]).max() <= 1.0 / STREAM_RATE + CLOCK_STEP_NS * 1e-9 + 1e-9
    assert np.diff(times).max() <= 2.0 / STREAM_RATE + 1e-9  # the first repetition: within two periods
    # OFFBOARD requested only after >= 1 s of stream (received at the peer, simulation time)
    set_modes = [c for c in fake.command_list() if c.msg.command == 176 and int(c.msg.param2) == 6]
    assert set_modes and set_modes[0].t - times[0] >= 1.0
    # stale setpoints: the stream goes on for setpoint_timeout after the last published setpoint, then stops
    stopped_after = times[-1] - last_publish
    assert SETPOINT_TIMEOUT - 1.0 / STREAM_RATE - 0.0015 <= stopped_after <= SETPOINT_TIMEOUT + 1.0 / STREAM_RATE
    sim.run_until(lambda: statuses[-1].failsafe and statuses[-1].state == UavStatus.STATE_FAILSAFE, 0.2, "failsafe")
    # wire content: level, facing north -> identity in NED/FRD; thrust normalized with the 12.0 V telemetry
    with fake.lock:
        last = fake.setpoints[-1].msg
    np.testing.assert_allclose(last.q, [1.0, 0.0, 0.0, 0.0], atol=1e-6)
    assert last.thrust == pytest.approx(10.0 / 34.58, abs=1e-5)
    assert statuses[-1].setpoint_rate == 0.0  # stopped more than 1 s ago
    # telemetry made it to ROS in ENU/FLU
    assert imus and imus[-1].linear_acceleration.z == pytest.approx(9.81, abs=1e-5)
    assert imus[-1].orientation.z == pytest.approx(math.sin(math.pi / 4), abs=1e-6)


def test_swarm_guard_stale_setpoints_hold_then_rejoin_when_the_controller_is_back(guarded_graph):
    """Issue 12: the controller dies in OFFBOARD -> EMERGENCY (own), PX4 asked for Hold (AUTO.LOITER) at once and
    said in the status; the controller back -> rejoin: OFFBOARD requested again after rejoin_delay."""
    node, fake, sim, teleop_pub, statuses, imus = guarded_graph
    sim.run_until(lambda: statuses and statuses[-1].connected, 1.0, "connected")
    teleop_pub.publish(teleop(TeleopCommand.MODE_FLY))
    sim.run_until(lambda: fake.armed, 2.0, "armed")
    sim.setpoint = setpoint()
    sim.run_until(lambda: statuses[-1].state == UavStatus.STATE_OFFBOARD, 3.0, "OFFBOARD")
    sim.setpoint = None
    stopped = sim.now
    sim.run_until(lambda: statuses[-1].state == UavStatus.STATE_EMERGENCY, 1.0, "EMERGENCY")
    status = statuses[-1]
    assert status.emergency and status.emergency_own and "setpoints stale" in status.emergency_reason
    holds = [c for c in fake.command_list() if c.msg.command == 176 and int(c.msg.param2) == p.Px4MainMode.AUTO
             and int(c.msg.param3) == p.Px4AutoSubMode.LOITER]
    assert holds and holds[0].t - stopped <= SETPOINT_TIMEOUT + 2.0 / STREAM_RATE + 0.05
    sim.run_until(lambda: fake.custom_mode == p.encode_custom_mode(p.Px4MainMode.AUTO, p.Px4AutoSubMode.LOITER),
                  1.0, "PX4 in Hold")
    sim.run_for(1.0)
    assert statuses[-1].state == UavStatus.STATE_EMERGENCY  # still holding: no landing before the hold time
    sim.setpoint = setpoint()  # the controller restarted
    back = sim.now
    sim.run_until(lambda: statuses[-1].state == UavStatus.STATE_OFFBOARD, 3.0, "rejoined")
    offboard_requests = [c for c in fake.command_list() if c.msg.command == 176 and int(c.msg.param2) ==
                         p.Px4MainMode.OFFBOARD and c.t > back]
    assert offboard_requests and offboard_requests[0].t - back >= 0.5 - 0.05  # rejoin_delay
    assert not statuses[-1].emergency and statuses[-1].emergency_reason == ""


def test_swarm_guard_platform_envelope_from_the_controller_status(guarded_graph):
    """The platform's tilt the own controller reports (ControllerStatus.platform_tilt) above max_platform_tilt_deg
    (45°) for envelope_time (0.3 s) -> EMERGENCY (own, latched: a level platform afterwards does not rejoin); 40°
    for as long is nothing."""
    node, fake, sim, teleop_pub, statuses, imus = guarded_graph
    status = ControllerStatus()
    status.uav_id, status.local_state_valid, status.platform_tilt = 1, True, math.radians(40.0)
    sim.controller_status = status
    sim.run_until(lambda: statuses and statuses[-1].connected, 1.0, "connected")
    teleop_pub.publish(teleop(TeleopCommand.MODE_FLY))
    sim.run_until(lambda: fake.armed, 2.0, "armed")
    sim.setpoint = setpoint()
    sim.run_until(lambda: statuses[-1].state == UavStatus.STATE_OFFBOARD, 3.0, "OFFBOARD")
    sim.run_for(1.0)
    assert statuses[-1].state == UavStatus.STATE_OFFBOARD  # 40°: inside the envelope
    status.platform_tilt = math.radians(50.0)
    tilted = sim.now
    sim.run_until(lambda: statuses[-1].state == UavStatus.STATE_EMERGENCY, 1.0, "EMERGENCY")
    assert sim.now - tilted >= 0.3 - 0.03  # envelope_time
    assert statuses[-1].emergency_own and "platform tilt" in statuses[-1].emergency_reason
    status.platform_tilt = 0.0
    sim.run_for(1.5)
    assert statuses[-1].state == UavStatus.STATE_EMERGENCY  # latched: no rejoin


def test_bad_setpoints_never_reach_the_peer_and_garbage_is_counted(graph, corrupt_datagrams):
    node, fake, sim, teleop_pub, statuses, imus = graph
    sim.run_until(lambda: statuses and statuses[-1].connected, 1.0, "connected")
    teleop_pub.publish(teleop(TeleopCommand.MODE_ARM))
    sim.run_until(lambda: fake.armed, 2.0, "armed")
    for bad in (setpoint(q=(math.nan, 0.0, 0.0, 1.0)), setpoint(q=(0.5, 0.0, 0.0, 0.5)),
                setpoint(thrust=math.inf), setpoint(uav_id=2)):
        sim.setpoint_pub.publish(bad)
    sim.run_until(lambda: statuses[-1].rejected_setpoints == 4, 1.0, "4 refused setpoints")
    assert fake.setpoint_times() == []
    # streaming continues while 10,000 corrupted datagrams hit the bridge's socket (100 per clock step, each
    # batch read before the next: a full socket buffer would drop datagrams, whatever the machine's speed)
    sim.setpoint = setpoint()
    sim.run_until(lambda: len(fake.setpoint_times()) > 10, 1.0, "stream")
    datagrams = list(corrupt_datagrams(10_000, seed=5))
    read_before = node.link.counters.rx_datagrams
    for start in range(0, len(datagrams), 100):
        for data in datagrams[start:start + 100]:
            fake.send_raw(data)
        sent = start + 100
        assert wait_for(lambda: node.link.counters.rx_datagrams - read_before >= sent), "bridge reading"  # noqa: B023
        sim.step()
    count = len(fake.setpoint_times())
    sim.run_until(lambda: len(fake.setpoint_times()) > count + 20, 1.0, "stream after the garbage")
    sim.run_until(lambda: statuses[-1].rx_garbage > 7000, 2.0, "garbage counted")
    assert statuses[-1].connected and statuses[-1].state == UavStatus.STATE_WARMUP
    with fake.lock:
        for received in fake.setpoints:
            assert np.isfinite(received.msg.q).all() and math.isfinite(received.msg.thrust)


def test_kill_and_disconnect(graph):
    node, fake, sim, teleop_pub, statuses, imus = graph
    sim.run_until(lambda: statuses and statuses[-1].connected, 1.0, "connected")
    teleop_pub.publish(teleop(TeleopCommand.MODE_ARM))
    sim.run_until(lambda: fake.armed, 2.0, "armed")
    teleop_pub.publish(teleop(TeleopCommand.MODE_KILL))
    sim.run_until(lambda: not fake.armed, 1.0, "killed")
    kills = [c for c in fake.command_list() if c.msg.command == 400 and c.msg.param1 == 0.0]
    assert kills and kills[0].msg.param2 == 21196.0
    sim.run_until(lambda: statuses[-1].state == UavStatus.STATE_KILLED, 0.5, "KILLED")
    fake.send_heartbeats = False  # HEARTBEATs alone stopping is not silence: the telemetry (20 Hz) goes on
    sim.run_for(1.0)
    assert statuses[-1].connected and statuses[-1].state == UavStatus.STATE_KILLED
    fake.telemetry_rate = 0.0  # now PX4 is silent
    silent_at = sim.now
    lost_at = sim.run_until(lambda: statuses[-1].state == UavStatus.STATE_DISCONNECTED
                            and not statuses[-1].connected, 3.0, "DISCONNECTED")
    # heartbeat_timeout 0.45 s after the last frame (telemetry every 50 ms), seen in the next status (20 Hz)
    assert 0.45 - 0.05 - 0.004 <= lost_at - silent_at <= 0.45 + 0.05 + 0.004
    assert statuses[-1].link_age >= 0.45


@pytest.mark.parametrize("sim_time, setting, expected", [
    (True, "auto", "ros_time"), (False, "auto", "estimate"), (True, "estimate", "estimate"),
    (False, "ros_time", "ros_time")])
def test_px4_boot_clock_auto_follows_use_sim_time(free_port, sim_time, setting, expected):
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = Px4BridgeNode(context=context, namespace="/fpr/uav1", parameter_overrides=[
            Parameter("use_sim_time", value=sim_time), Parameter("px4_boot_clock", value=setting),
            Parameter("connection_url", value=f"udp://127.0.0.1:{free_port}")])
        assert node.bridge.config.px4_boot_clock == expected
        node.destroy_node()
        # refused at declaration (fpr_model.node_parameters: the parameter's choices), naming the parameter
        with pytest.raises((ValueError, InvalidParameterValueException), match="px4_boot_clock"):
            Px4BridgeNode(context=context, parameter_overrides=[
                Parameter("px4_boot_clock", value="wall"), Parameter("connection_url", value=f"udp://127.0.0.1:{free_port}")])
    finally:
        rclpy.shutdown(context=context)


def test_a_dead_simulator_is_reported_by_the_wall_clock_watchdog(graph):
    """The simulator dies: no MAVLink and no /clock any more, so every /clock-driven check stands still; the steady
    watchdog reports the lost link (one warning, a status with connected false) within about 1 s of wall time."""
    node, fake, sim, teleop_pub, statuses, imus = graph
    sim.run_until(lambda: statuses and statuses[-1].connected, 1.0, "connected")
    assert node._wall_silent_since is None
    frozen = time.monotonic()  # from now on nothing steps the simulation: no frame, no /clock
    assert wait_for(lambda: statuses and not statuses[-1].connected, timeout=5.0)
    reported = time.monotonic() - frozen
    status = statuses[-1]
    assert status.state == UavStatus.STATE_DISCONNECTED and status.link_age >= node.wall_silence_timeout
    assert node._wall_silent_since is not None
    assert reported < 3.0  # the watchdog's own bound is wall_silence_timeout + its 0.1 s period (generous: CI load)


def test_message_rates_parameter_defaults_switch_and_refusal(free_port):
    """message_rates (README "Telemetry rates"): the default list reaches the bridge core; configure_streams false
    asks for nothing; a bad entry stops the node at start, naming the entry."""
    from fpr_px4_bridge.streams import DEFAULT_MESSAGE_RATES, parse_message_rates

    context = rclpy.Context()
    rclpy.init(context=context)
    url = Parameter("connection_url", value=f"udp://127.0.0.1:{free_port}")
    try:
        node = Px4BridgeNode(context=context, parameter_overrides=[url])
        assert node.bridge.config.message_rates == parse_message_rates(DEFAULT_MESSAGE_RATES)
        node.destroy_node()
        node = Px4BridgeNode(context=context, parameter_overrides=[url, Parameter("configure_streams", value=False)])
        assert node.bridge.config.message_rates == () and node.bridge.streams.done
        node.destroy_node()
        with pytest.raises(ValueError, match="'HEARTBEAT=1'|HEARTBEAT"):
            Px4BridgeNode(context=context, parameter_overrides=[url, Parameter("message_rates", value=["HEARTBEAT=1"])])
    finally:
        rclpy.shutdown(context=context)
