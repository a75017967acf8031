"""fpr_control nodes in process with real rclpy and fabricated inputs (run through scripts/run_tests.sh)."""

from __future__ import annotations

import math
import os
import threading
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
from fpr_control.controller_node import ControllerNode  # noqa: E402
from fpr_control.joy_script_node import JoyScriptNode  # noqa: E402
from fpr_control.joystick_device import JS_EVENT_AXIS, JS_EVENT_BUTTON, pack_event  # noqa: E402
from fpr_control.joystick_node import JoystickNode  # noqa: E402
from fpr_control.teleop_node import TeleopNode  # noqa: E402
from geometry_msgs.msg import Pose  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import Joy  # noqa: E402

from fpr_msgs.msg import (  # noqa: E402
    AttitudeThrustSetpoint,
    ControllerStatus,
    FprState,
    InformationVector,
    LocalState,
    TeleopCommand,
    WrenchEstimate,
)

BEST_EFFORT = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
CONFIG_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "config")


def wait_for(predicate, timeout=5.0, step=0.01):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(step)
    return predicate()


class Graph:
    """One node under test + a helper node, spun by a background executor in a private context."""

    def __init__(self, factory, **kwargs):
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = factory(context=self.context, **kwargs)
        self.helper = rclpy.create_node("fpr_control_test_helper", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.helper)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def close(self):
        self.executor.shutdown()
        self.thread.join(timeout=2.0)  # no callback may run on a node being destroyed
        self.node.destroy_node()
        self.helper.destroy_node()
        rclpy.shutdown(context=self.context)


def _local_state(uav_id=1, leg=0.8, nan=False):
    msg = LocalState()
    msg.uav_id = uav_id
    msg.leg_angle = float("nan") if nan else leg
    msg.relative_pose.orientation.w = 1.0
    msg.uav_attitude_flat.w = 1.0
    msg.relative_yaw, msg.uav_yaw, msg.valid = 0.1, 0.5, True
    return msg


def _info(uav_id, leg=0.8):
    msg = InformationVector()
    msg.uav_id, msg.leg_angle, msg.thrust, msg.valid = uav_id, leg, 11.0, True
    msg.attitude.w = 1.0
    return msg


def _teleop(n=3, roll=0.0, nan=False, pitch=0.0, contact_force=0.0):
    msg = TeleopCommand()
    msg.mode = TeleopCommand.MODE_FLY
    msg.roll = float("nan") if nan else roll
    msg.pitch, msg.contact_force = pitch, contact_force
    msg.leg_angles = [0.8] * n
    msg.leg_rates = [0.0] * n
    return msg


def _still_motion_capture(x: float, y: float, z: float) -> FprState:
    """A motionless FprState in F0: the platform level at (x, y, z) [m], legs 0.8 rad, UAVs at identity."""
    truth = FprState()
    truth.header.frame_id = "world"
    truth.platform_pose.position.x, truth.platform_pose.position.y, truth.platform_pose.position.z = x, y, z
    truth.platform_pose.orientation.w = 1.0
    truth.leg_angles, truth.leg_rates = [0.8] * 3, [0.0] * 3
    truth.uav_poses = [Pose() for _ in range(3)]
    for pose in truth.uav_poses:
        pose.orientation.w = 1.0
    return truth


def test_controller_node_fallback_and_bad_input():
    graph = Graph(ControllerNode, namespace="/fpr/uav1", parameter_overrides=[
        Parameter("uav_id", value=1), Parameter("mode", value="communicating"),
        Parameter("info_timeout", value=0.2)])
    try:
        helper = graph.helper
        setpoints, statuses, wrenches, infos = [], [], [], []
        helper.create_subscription(AttitudeThrustSetpoint, "/fpr/uav1/setpoint", setpoints.append, BEST_EFFORT)
        helper.create_subscription(ControllerStatus, "/fpr/uav1/controller_status", statuses.append, 10)
        helper.create_subscription(WrenchEstimate, "/fpr/uav1/wrench", wrenches.append, BEST_EFFORT)
        helper.create_subscription(InformationVector, "/fpr/info", infos.append, BEST_EFFORT)
        local_pub = helper.create_publisher(LocalState, "/fpr/uav1/local_state", 10)
        info_pub = helper.create_publisher(InformationVector, "/fpr/info", BEST_EFFORT)
        teleop_pub = helper.create_publisher(TeleopCommand, "/fpr/teleop", 10)
        assert wait_for(lambda: local_pub.get_subscription_count() > 0 and info_pub.get_subscription_count() > 0
                        and teleop_pub.get_subscription_count() > 0 and len(statuses) > 0)
        state = {"peers": (2, 3), "nan_local": False, "nan_teleop": False, "nan_info": False}

        first = statuses[0]  # before any input: no desired configuration yet
        assert math.isnan(first.desired_roll) and len(first.desired_leg_angles) == 3
        assert all(math.isnan(v) for v in first.desired_leg_angles)

        def feed():
            local_pub.publish(_local_state(nan=state["nan_local"]))
            teleop_pub.publish(_teleop(roll=0.04, pitch=-0.02, contact_force=2.0, nan=state["nan_teleop"]))
            for j in state["peers"]:
                info_pub.publish(_info(j, leg=float("nan") if state["nan_info"] else 0.8))

        timer = helper.create_timer(0.02, feed)
        assert wait_for(lambda: any(s.active_mode == ControllerStatus.MODE_COMMUNICATING
                                    and not s.fallback_active for s in statuses[-3:]), timeout=8.0)
        assert any(i.uav_id == 1 and i.valid for i in infos)  # own zeta_1 published
        # q^d tracked: the teleoperation roll/pitch/legs/force in F_Fp, no position, no yaw (4.25)
        st = statuses[-1]
        assert st.header.frame_id == "flat_platform"
        assert (st.desired_position.x, st.desired_position.y, st.desired_position.z) == (0.0, 0.0, 0.0)
        assert (st.desired_roll, st.desired_pitch, st.desired_yaw) == pytest.approx((0.04, -0.02, 0.0), abs=1e-12)
        assert list(st.desired_leg_angles) == pytest.approx([0.8] * 3, abs=1e-12)
        assert st.desired_contact_force == pytest.approx(2.0)
        assert wrenches and len(wrenches[-1].leg_moments) == 3
        # silence UAV 3: NC within info_timeout + a period (plus delivery jitter) and reported
        state["peers"] = (2,)
        silenced = time.monotonic()
        assert wait_for(lambda: statuses[-1].fallback_active
                        and statuses[-1].active_mode == ControllerStatus.MODE_NON_COMMUNICATING, timeout=3.0)
        assert time.monotonic() - silenced < 0.2 + 0.02 + 0.3
        assert statuses[-1].info_ages[2] > 0.2 and statuses[-1].configured_mode == ControllerStatus.MODE_COMMUNICATING
        state["peers"] = (2, 3)
        assert wait_for(lambda: not statuses[-1].fallback_active
                        and statuses[-1].active_mode == ControllerStatus.MODE_COMMUNICATING, timeout=3.0)
        # NaN everywhere: setpoints stay finite, unit, within [0, f_max]
        count = len(setpoints)
        state.update(nan_local=True, nan_teleop=True, nan_info=True)
        assert wait_for(lambda: len(setpoints) > count + 20, timeout=5.0)
        for sp in setpoints:
            q = np.array([sp.attitude.x, sp.attitude.y, sp.attitude.z, sp.attitude.w])
            assert np.all(np.isfinite(q)) and abs(np.linalg.norm(q) - 1.0) < 1e-9
            assert math.isfinite(sp.thrust) and 0.0 <= sp.thrust <= 25.0 and sp.uav_id == 1
        assert wait_for(lambda: not statuses[-1].local_state_valid, timeout=2.0)
        helper.destroy_timer(timer)
    finally:
        graph.close()


def test_controller_node_reports_the_centralized_desired_state():
    """Ground truth (F0): desired_position starts at the platform position and integrates the commanded F_Fp
    velocity (Rz(ψ) Fp v^d, ψ = 0 here); yaw from the ground truth; frame "world". The status's state validity is
    the motion capture's freshness."""
    graph = Graph(ControllerNode, namespace="/fpr/uav1", parameter_overrides=[
        Parameter("uav_id", value=1), Parameter("mode", value="centralized")])
    try:
        helper = graph.helper
        statuses = []
        helper.create_subscription(ControllerStatus, "/fpr/uav1/controller_status", statuses.append, 10)
        truth_pub = helper.create_publisher(FprState, "/fpr/motion_capture", BEST_EFFORT)
        teleop_pub = helper.create_publisher(TeleopCommand, "/fpr/teleop", 10)
        assert wait_for(lambda: truth_pub.get_subscription_count() > 0 and teleop_pub.get_subscription_count() > 0)
        truth = _still_motion_capture(0.2, -0.1, 1.0)
        teleop = _teleop(roll=0.03)
        teleop.platform_velocity.x = 0.2

        def feed():
            truth_pub.publish(truth)
            teleop_pub.publish(teleop)

        timer = helper.create_timer(0.02, feed)
        assert wait_for(lambda: statuses and statuses[-1].desired_position.x > 0.2 + 0.02, timeout=8.0)
        st = statuses[-1]
        assert st.header.frame_id == "world" and st.active_mode == ControllerStatus.MODE_CENTRALIZED
        assert st.desired_position.y == pytest.approx(-0.1, abs=1e-9)
        assert st.desired_position.z == pytest.approx(1.0, abs=1e-9)
        assert (st.desired_roll, st.desired_yaw) == pytest.approx((0.03, 0.0), abs=1e-12)
        assert list(st.desired_leg_angles) == pytest.approx([0.8] * 3)
        # the state it flies on is the motion capture: valid although no LocalState ever came (an unused onboard
        # estimator going blind must not trigger the swarm guard) ...
        assert st.local_state_valid
        helper.destroy_timer(timer)
        # ... and a motion capture that stops is reported (motion_capture_timeout 0.25 s): the guard's emergency
        assert wait_for(lambda: not statuses[-1].local_state_valid, timeout=3.0)
    finally:
        graph.close()


def test_teleop_node_maps_joy_and_ignores_bad_joy():
    graph = Graph(TeleopNode, parameter_overrides=[Parameter("n", value=3)])
    try:
        helper = graph.helper
        commands = []
        helper.create_subscription(TeleopCommand, "/fpr/teleop", commands.append, 10)
        joy_pub = helper.create_publisher(Joy, "/joy", 10)
        assert wait_for(lambda: joy_pub.get_subscription_count() > 0 and len(commands) > 0)
        state = {"axes": [0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 0.0], "buttons": [0] * 11}

        def publish():
            msg = Joy()
            msg.axes, msg.buttons = [float(a) for a in state["axes"]], state["buttons"]
            joy_pub.publish(msg)

        timer = helper.create_timer(0.02, publish)
        assert wait_for(lambda: commands[-1].platform_velocity.x > 0.49, timeout=5.0)  # v_x = 0.5 after the LPF
        c = commands[-1]
        assert len(c.leg_angles) == 3 and c.leg_angles[0] == pytest.approx(math.radians(60.0))  # no /fpr/info
        assert c.mode == TeleopCommand.MODE_IDLE
        state["axes"] = [float("nan")] * 8  # ignored: the last good sample holds
        time.sleep(0.2)
        assert commands[-1].platform_velocity.x > 0.49
        helper.destroy_timer(timer)  # Joy silent > 0.5 s: velocities to zero
        assert wait_for(lambda: abs(commands[-1].platform_velocity.x) < 0.01, timeout=5.0)
    finally:
        graph.close()


def test_joystick_node_reads_a_fifo(tmp_path):
    path = str(tmp_path / "js0")
    os.mkfifo(path)
    graph = Graph(JoystickNode, parameter_overrides=[Parameter("device", value=path),
                                                     Parameter("min_axes", value=8),
                                                     Parameter("min_buttons", value=11)])
    try:
        joys = []
        graph.helper.create_subscription(Joy, "/joy", joys.append, 10)
        with open(path, "wb") as writer:
            writer.write(pack_event(1, -32767, JS_EVENT_AXIS, 4) + pack_event(2, 1, JS_EVENT_BUTTON, 0))
            writer.flush()
            assert wait_for(lambda: joys and joys[-1].axes[4] == pytest.approx(1.0) and joys[-1].buttons[0] == 1,
                            timeout=5.0)
        assert len(joys[-1].axes) == 8 and len(joys[-1].buttons) == 11
    finally:
        graph.close()


def test_joy_script_node_plays_the_timeline(tmp_path):
    script = tmp_path / "s.yaml"
    script.write_text("axes_count: 8\nbuttons_count: 11\nkeyframes:\n"
                      "  - {t: 0.0, axes: {4: 0.25}}\n  - {t: 0.3, buttons: {0: 1}}\n")
    graph = Graph(JoyScriptNode, parameter_overrides=[Parameter("script", value=str(script))])
    try:
        joys = []
        graph.helper.create_subscription(Joy, "/joy", joys.append, 10)
        assert wait_for(lambda: joys and joys[-1].buttons[0] == 1, timeout=5.0)
        assert joys[0].axes[4] == pytest.approx(0.25) and joys[0].buttons[0] == 0
    finally:
        graph.close()


def test_joy_script_exits_after_its_timeline_with_exit_at_end(tmp_path):
    """Issue 14: `ros2 run fpr_control joy_script -p exit_at_end:=true` ends by itself exit_delay after its last
    keyframe, with status 0 and one line saying so (the README's by-hand section relies on it); without the option
    it says how it is stopped."""
    import subprocess
    import sys

    script = tmp_path / "s.yaml"
    script.write_text("axes_count: 8\nbuttons_count: 11\nkeyframes:\n"
                      "  - {t: 0.0, axes: {4: 0.25}}\n  - {t: 0.3, buttons: {0: 1}}\n")
    command = [sys.executable, "-m", "fpr_control.joy_script_node", "--ros-args", "-p", f"script:={script}",
               "-p", "wait_for_subscribers:=false", "-p", "exit_delay:=0.2"]
    done = subprocess.run([*command, "-p", "exit_at_end:=true"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert "exits 0.2 s after its last keyframe" in done.stderr
    assert "timeline finished, exiting (exit_at_end)" in done.stderr
    running = subprocess.Popen(command, stderr=subprocess.PIPE, text=True)
    try:
        first_line = running.stderr.readline()
        assert "until stopped (Ctrl-C; -p exit_at_end:=true exits by itself)" in first_line
        with pytest.raises(subprocess.TimeoutExpired):
            running.wait(timeout=1.5)  # 0.3 s of timeline + 0.2 s: still running
    finally:
        running.terminate()
        assert running.wait(timeout=10) == 0


def test_controller_node_bounds_teleop_and_refuses_a_second_zeta_publisher():
    """Issue 12: an absurd /fpr/teleop is refused (the last valid command is kept), a slightly-out-of-range one is
    clamped; a second publisher claiming uav_id 2 on /fpr/info is refused after the first one is established."""
    graph = Graph(ControllerNode, namespace="/fpr/uav1", parameter_overrides=[
        Parameter("uav_id", value=1), Parameter("mode", value="communicating")])
    try:
        helper = graph.helper
        statuses = []
        helper.create_subscription(ControllerStatus, "/fpr/uav1/controller_status", statuses.append, 10)
        local_pub = helper.create_publisher(LocalState, "/fpr/uav1/local_state", 10)
        info_pub = helper.create_publisher(InformationVector, "/fpr/info", BEST_EFFORT)
        teleop_pub = helper.create_publisher(TeleopCommand, "/fpr/teleop", 10)
        assert wait_for(lambda: local_pub.get_subscription_count() > 0 and teleop_pub.get_subscription_count() > 0
                        and info_pub.get_subscription_count() > 0)
        state = {"roll": 0.1, "legs": [0.8] * 3}

        def feed():
            local_pub.publish(_local_state())
            msg = _teleop(roll=state["roll"])
            msg.leg_angles = state["legs"]
            teleop_pub.publish(msg)
            for j in (2, 3):
                info_pub.publish(_info(j))

        timer = helper.create_timer(0.02, feed)
        assert wait_for(lambda: statuses and statuses[-1].desired_roll == pytest.approx(0.1), timeout=8.0)
        state.update(roll=math.radians(80.0), legs=[math.radians(150.0)] * 3)  # refused: the last valid holds
        time.sleep(0.3)
        assert graph.node._teleop_refused > 5
        assert statuses[-1].desired_roll == pytest.approx(0.1)
        assert list(statuses[-1].desired_leg_angles) == pytest.approx([0.8] * 3)
        state.update(roll=math.radians(35.0), legs=[0.8] * 3)  # within 2x the 30 deg limit: clamped
        assert wait_for(lambda: statuses[-1].desired_roll == pytest.approx(math.radians(30.0)), timeout=3.0)
        assert graph.node._teleop_refused == 0
        # an intruder claiming uav_id 2 (a fresh writer: its sequence numbers restart at 1)
        intruder = helper.create_publisher(InformationVector, "/fpr/info", BEST_EFFORT)
        assert wait_for(lambda: intruder.get_subscription_count() > 0)
        table = graph.node.controller.information
        forged = _info(2, leg=1.2)
        for _ in range(10):
            intruder.publish(forged)
            time.sleep(0.02)
        assert wait_for(lambda: table.intruder_messages >= 5, timeout=3.0)
        assert table.get(2).leg_angle == pytest.approx(0.8)
        helper.destroy_timer(timer)
    finally:
        graph.close()


def test_dynamic_max_thrust_caps_the_next_setpoint():
    """Issue 14: a dynamic parameter takes effect within one period. The controller flies (communicating, fed a
    steady state) at its hover share (~11 N); max_thrust set to 6 N caps every setpoint computed after the set
    (header stamp later than the set), and a refused value (NaN) changes nothing."""
    graph = Graph(ControllerNode, namespace="/fpr/uav1", parameter_overrides=[
        Parameter("uav_id", value=1), Parameter("mode", value="communicating")])
    try:
        helper = graph.helper
        setpoints = []
        helper.create_subscription(AttitudeThrustSetpoint, "/fpr/uav1/setpoint", setpoints.append, BEST_EFFORT)
        local_pub = helper.create_publisher(LocalState, "/fpr/uav1/local_state", 10)
        info_pub = helper.create_publisher(InformationVector, "/fpr/info", BEST_EFFORT)
        teleop_pub = helper.create_publisher(TeleopCommand, "/fpr/teleop", 10)

        def feed():
            local_pub.publish(_local_state())
            teleop_pub.publish(_teleop())
            for j in (2, 3):
                info_pub.publish(_info(j))

        timer = helper.create_timer(0.02, feed)
        assert wait_for(lambda: len(setpoints) > 20 and setpoints[-1].thrust > 8.0, timeout=8.0)
        (refused,) = graph.node.set_parameters([Parameter("max_thrust", value=float("nan"))])
        assert not refused.successful and graph.node.controller.config.max_thrust == 25.0
        set_at = graph.node.get_clock().now().nanoseconds
        (result,) = graph.node.set_parameters([Parameter("max_thrust", value=6.0)])
        assert result.successful, result.reason
        count = len(setpoints)
        assert wait_for(lambda: len(setpoints) > count + 10, timeout=3.0)
        after = [sp for sp in setpoints if sp.header.stamp.sec * 10**9 + sp.header.stamp.nanosec > set_at]
        assert len(after) >= 10 and all(sp.thrust <= 6.0 + 1e-9 for sp in after), [sp.thrust for sp in after[:5]]
        # the first setpoint stamped after the set is at most one period after it: the cap holds from there
        first = after[0].header.stamp.sec * 10**9 + after[0].header.stamp.nanosec
        assert first - set_at <= 2 * 20_000_000
        helper.destroy_timer(timer)
    finally:
        graph.close()


def test_read_only_parameters_refuse_a_runtime_set_and_keep_their_value():
    """Issue 14: `ros2 param set mode bogus_mode` / `rate -3` reported success and changed nothing; parameters
    read at start-up are read-only now (tests/test_node_parameters.py covers every parameter of every node)."""
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = ControllerNode(context=context)
        for name, bogus in (("mode", "bogus_mode"), ("rate", -3.0), ("uav_id", 2)):
            before = node.get_parameter(name).value
            result = node.set_parameters([Parameter(name, value=bogus)])[0]
            assert not result.successful and "read-only" in result.reason.lower(), (name, result.reason)
            assert node.get_parameter(name).value == before and node.describe_parameter(name).read_only
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def test_contact_guard_reported_and_said_without_breaking_the_tick():
    """Impedance on a frozen motion capture: the wrench observer reads the platform held in place as a contact
    building up (FOWO, K_O 2/s), so with min_fraction 1 the 10 N demand is unmet for max_unmet_time 0.3 s and
    declared lost (ControllerStatus.contact_guard LOST, applied 0 after the fade, the operator's 10 N still
    reported); the trigger's release re-arms it, and the control tick keeps running through both log lines (rclpy
    refuses two severities from one call site: that once raised inside the tick)."""
    graph = Graph(ControllerNode, namespace="/fpr/uav1", parameter_overrides=[
        Parameter("uav_id", value=1), Parameter("mode", value="impedance"),
        Parameter("state_source", value="ground_truth"), Parameter("contact_guard.max_unmet_time", value=0.3),
        Parameter("contact_guard.min_fraction", value=1.0)])
    try:
        helper = graph.helper
        statuses = []
        helper.create_subscription(ControllerStatus, "/fpr/uav1/controller_status", statuses.append, 10)
        truth_pub = helper.create_publisher(FprState, "/fpr/motion_capture", BEST_EFFORT)
        teleop_pub = helper.create_publisher(TeleopCommand, "/fpr/teleop", 10)
        assert wait_for(lambda: truth_pub.get_subscription_count() > 0 and teleop_pub.get_subscription_count() > 0)
        truth = _still_motion_capture(0.0, 0.0, 1.0)
        state = {"force": 10.0}

        def feed():
            truth_pub.publish(truth)
            teleop_pub.publish(_teleop(contact_force=state["force"]))

        timer = helper.create_timer(0.02, feed)
        assert wait_for(lambda: statuses and statuses[-1].contact_guard == ControllerStatus.CONTACT_GUARD_LOST
                        and statuses[-1].applied_contact_force == 0.0, timeout=8.0)
        assert statuses[-1].desired_contact_force == pytest.approx(10.0)
        assert any(s.contact_guard == ControllerStatus.CONTACT_GUARD_PUSHING and s.applied_contact_force == 10.0
                   for s in statuses)
        state["force"] = 0.0
        assert wait_for(lambda: statuses[-1].contact_guard == ControllerStatus.CONTACT_GUARD_IDLE, timeout=3.0)
        count = len(statuses)
        assert wait_for(lambda: len(statuses) > count + 10, timeout=3.0), "the tick stopped"
        helper.destroy_timer(timer)
    finally:
        graph.close()
