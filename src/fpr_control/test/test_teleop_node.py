"""teleop node in process (real rclpy, run through scripts/run_tests.sh): before FLY the command follows the leg
angles the UAVs report on /fpr/info (best-effort, as the controllers publish them); FLY hands over to the
operator from there; without /fpr/info, or with ``initial_legs_from_info`` false, the mapping's initial value.
With ``target_approach``, x/y velocity and yaw rate follow (4.39) on /fpr/target in FLY."""

from __future__ import annotations

import math
import threading
import time

import pytest

rclpy = pytest.importorskip("rclpy")
from fpr_control.teleop_filter import LEG_SOURCE_CONFIGURED, LEG_SOURCE_INFO  # noqa: E402
from fpr_control.teleop_node import TeleopNode  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data  # noqa: E402
from sensor_msgs.msg import Joy  # noqa: E402

from fpr_msgs.msg import InformationVector, TeleopCommand  # noqa: E402

BEST_EFFORT = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)  # the controllers' /fpr/info QoS
A, X, RB = 0, 2, 5


def wait_for(predicate, timeout=5.0, step=0.01):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(step)
    return predicate()


class Bench:
    """A teleop node plus a helper publishing Joy (50 Hz) and, optionally, /fpr/info of three UAVs (50 Hz)."""

    def __init__(self, parameters, with_info=True, with_target=False):
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = TeleopNode(context=self.context, parameter_overrides=parameters)
        self.helper = rclpy.create_node("teleop_test_helper", context=self.context)
        self.commands: list[TeleopCommand] = []
        self.helper.create_subscription(TeleopCommand, "/fpr/teleop", self.commands.append, 10)
        self.joy_pub = self.helper.create_publisher(Joy, "/joy", 10)
        self.info_pub = self.helper.create_publisher(InformationVector, "/fpr/info", BEST_EFFORT) if with_info \
            else None
        self.target_pub = self.helper.create_publisher(PoseStamped, "/fpr/target", qos_profile_sensor_data) \
            if with_target else None
        self.target = None  # (x, y, z, yaw, frame_id) published at 50 Hz when set
        self.axes = [0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0]
        self.buttons = [0] * 11
        self.leg_angles = {1: 1.00, 2: 1.03, 3: 1.06}  # θ_i [rad] the UAVs report
        self.valid = True
        self.lock = threading.Lock()
        self.helper.create_timer(0.02, self._publish)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.helper)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def _publish(self):
        with self.lock:
            joy = Joy()
            joy.axes, joy.buttons = [float(a) for a in self.axes], list(self.buttons)
            self.joy_pub.publish(joy)
            if self.target_pub is not None and self.target is not None:
                x, y, z, yaw, frame = self.target
                pose = PoseStamped()
                pose.header.frame_id = frame
                pose.header.stamp = self.helper.get_clock().now().to_msg()
                pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = x, y, z
                pose.pose.orientation.w, pose.pose.orientation.z = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
                self.target_pub.publish(pose)
            if self.info_pub is None:
                return
            for uav_id, leg in self.leg_angles.items():
                info = InformationVector()
                info.uav_id, info.leg_angle, info.thrust, info.valid = uav_id, leg, 9.0, self.valid
                info.attitude.w = 1.0
                self.info_pub.publish(info)

    def press(self, button):
        """Hold a button until the command reflects it, then release it."""
        mode = {A: TeleopCommand.MODE_ARM, X: TeleopCommand.MODE_FLY}[button]
        with self.lock:
            self.buttons[button] = 1
        assert wait_for(lambda: self.commands[-1].mode == mode)
        with self.lock:
            self.buttons[button] = 0

    def latest(self):
        return self.commands[-1]

    def close(self):
        self.executor.shutdown()
        self.thread.join(timeout=2.0)  # no callback may run on a node being destroyed
        self.node.destroy_node()
        self.helper.destroy_node()
        rclpy.shutdown(context=self.context)


def _legs_near(bench, value, tolerance=1e-3):
    return lambda: bench.commands and all(abs(v - value) < tolerance for v in bench.latest().leg_angles)


def test_teleop_node_starts_from_the_reported_leg_angles_and_hands_over_at_fly():
    bench = Bench([Parameter("n", value=3), Parameter("info_smoothing", value=0.2)])
    try:
        assert wait_for(lambda: bench.joy_pub.get_subscription_count() > 0
                        and bench.info_pub.get_subscription_count() > 0 and len(bench.commands) > 0)
        assert wait_for(_legs_near(bench, 1.03))  # mean of 1.00, 1.03, 1.06
        c = bench.latest()
        assert c.mode == TeleopCommand.MODE_IDLE and c.leg_rates == pytest.approx([0.0] * 3, abs=1e-12)
        assert bench.node.filter.leg_source == LEG_SOURCE_INFO
        with bench.lock:
            bench.buttons[RB] = 1  # leg button on the ground: no effect, the command is the robot's
        time.sleep(0.3)
        assert all(abs(v - 1.03) < 1e-3 for v in bench.latest().leg_angles)
        with bench.lock:
            bench.buttons[RB] = 0
            bench.leg_angles[4] = 0.2  # no UAV 4 in a 3-UAV robot: ignored with a warning
            bench.leg_angles[2] = float("nan")  # malformed: ignored, UAV 2's last value holds
        time.sleep(0.2)
        assert all(abs(v - 1.03) < 1e-3 for v in bench.latest().leg_angles)
        with bench.lock:
            del bench.leg_angles[4]
            bench.leg_angles[2] = 1.03
        bench.press(A)
        with bench.lock:
            bench.leg_angles = {1: 1.10, 2: 1.10, 3: 1.10}  # armed, still on the ground: follows
        assert wait_for(_legs_near(bench, 1.10))
        assert bench.latest().mode == TeleopCommand.MODE_ARM
        bench.press(X)
        start = bench.latest().leg_angles[0]
        assert start == pytest.approx(1.10, abs=1e-3)
        with bench.lock:
            bench.leg_angles = {1: 0.7, 2: 0.7, 3: 0.7}  # flying: the reports no longer move the command
        time.sleep(0.3)
        assert bench.latest().leg_angles[0] == pytest.approx(start, abs=1e-9)
        with bench.lock:
            bench.buttons[RB] = 1  # the operator raises the legs from there
        assert wait_for(lambda: bench.latest().leg_angles[0] > start + math.radians(1.0))
        assert bench.latest().leg_rates[0] > 0.0
    finally:
        bench.close()


def test_teleop_node_falls_back_to_the_mapping_without_info_or_when_disabled():
    bench = Bench([Parameter("n", value=3)], with_info=False)
    try:
        assert wait_for(lambda: bench.joy_pub.get_subscription_count() > 0 and len(bench.commands) > 10)
        assert bench.latest().leg_angles == pytest.approx([math.radians(60.0)] * 3)  # config/teleop.yaml
        assert bench.node.filter.leg_source == LEG_SOURCE_CONFIGURED
    finally:
        bench.close()
    bench = Bench([Parameter("n", value=3), Parameter("initial_legs_from_info", value=False)])
    try:
        assert wait_for(lambda: bench.joy_pub.get_subscription_count() > 0 and len(bench.commands) > 10)
        assert bench.info_pub.get_subscription_count() == 0  # not even subscribed
        time.sleep(0.3)
        assert bench.latest().leg_angles == pytest.approx([math.radians(60.0)] * 3)
    finally:
        bench.close()


def test_teleop_node_ignores_vectors_their_senders_mark_invalid():
    bench = Bench([Parameter("n", value=3)])
    try:
        with bench.lock:
            bench.valid = False
        assert wait_for(lambda: bench.info_pub.get_subscription_count() > 0 and len(bench.commands) > 10)
        time.sleep(0.3)
        assert bench.latest().leg_angles == pytest.approx([math.radians(60.0)] * 3)
        with bench.lock:
            bench.valid = True
        assert wait_for(_legs_near(bench, 1.03, tolerance=0.01), timeout=8.0)  # smoothing τ = 1 s
    finally:
        bench.close()


def _velocity_near(bench, vx, vy, vz, yaw_rate, tolerance=5e-3):
    def check():
        c = bench.latest()
        return (abs(c.platform_velocity.x - vx) < tolerance and abs(c.platform_velocity.y - vy) < tolerance
                and abs(c.platform_velocity.z - vz) < tolerance and abs(c.yaw_rate - yaw_rate) < tolerance)
    return check


def test_teleop_node_target_approach_hybrid_scheme():
    """Scenario II: in FLY with a fresh /fpr/target, v_x, v_y and the yaw rate follow (4.39)
    (λ_p = 0.4, λ_ψ = 0.25 1/s) through the low-pass; v_z, f^d_c, roll, pitch, legs stay the operator's. Stale
    or refused target: the sticks again."""
    bench = Bench([Parameter("n", value=3), Parameter("target_approach", value=True),
                   Parameter("target_timeout", value=0.3)], with_info=False, with_target=True)
    try:
        assert wait_for(lambda: bench.joy_pub.get_subscription_count() > 0
                        and bench.target_pub.get_subscription_count() > 0 and len(bench.commands) > 0)
        with bench.lock:
            bench.axes[4] = 1.0  # stick v_x = +0.5 m/s
            bench.axes[1] = 1.0  # stick v_z = +0.3 m/s
            bench.axes[2] = 0.0  # trigger half pressed: f^d_c = 5 N
            bench.target = (-0.5, 1.0, 0.2, -0.8, "flat_platform")
        assert wait_for(_velocity_near(bench, 0.5, 0.0, 0.3, 0.0))  # not flying: the sticks
        bench.press(A)
        bench.press(X)
        assert wait_for(_velocity_near(bench, -0.2, 0.4, 0.3, -0.2))  # (4.39) + the operator's v_z
        c = bench.latest()
        assert c.contact_force == pytest.approx(5.0, abs=0.05) and c.mode == TeleopCommand.MODE_FLY
        assert c.roll == pytest.approx(0.0) and c.leg_angles == pytest.approx([math.radians(60.0)] * 3)
        assert all(math.isfinite(v) for v in (c.platform_acceleration.x, c.yaw_acceleration))
        with bench.lock:
            bench.target = None  # silent: stale after 0.3 s, back to the sticks
        assert wait_for(_velocity_near(bench, 0.5, 0.0, 0.3, 0.0))
        assert not bench.node.target.fresh(bench.node._now())
        with bench.lock:
            bench.target = (1.0, 0.0, 0.0, 0.0, "flat_platform")  # back
        assert wait_for(_velocity_near(bench, 0.4, 0.0, 0.3, 0.0))
        with bench.lock:
            bench.target = (float("nan"), 0.0, 0.0, 0.0, "flat_platform")  # refused: the sticks at once
        assert wait_for(_velocity_near(bench, 0.5, 0.0, 0.3, 0.0))
        with bench.lock:
            bench.target = (1.0, 0.0, 0.0, 0.0, "flat_platform")
        assert wait_for(_velocity_near(bench, 0.4, 0.0, 0.3, 0.0))
        with bench.lock:
            bench.target = (250.0, 0.0, 0.0, 0.0, "flat_platform")  # absurd: refused
        assert wait_for(_velocity_near(bench, 0.5, 0.0, 0.3, 0.0))
        with bench.lock:
            bench.target = (1.0, 0.0, 0.0, 0.0, "world")  # wrong frame: refused
        time.sleep(0.5)
        assert _velocity_near(bench, 0.5, 0.0, 0.3, 0.0)()
    finally:
        bench.close()


def test_teleop_node_target_approach_is_off_by_default():
    bench = Bench([Parameter("n", value=3)], with_info=False, with_target=True)
    try:
        assert wait_for(lambda: bench.joy_pub.get_subscription_count() > 0 and len(bench.commands) > 0)
        assert bench.target_pub.get_subscription_count() == 0 and bench.node.target is None
        names = {p.name: p for p in bench.node.describe_parameters(
            ["target_approach", "target_lambda_p", "target_lambda_psi", "target_timeout"])}
        assert all(p.description for p in names.values())
        assert bench.node.get_parameter("target_approach").value is False
        assert bench.node.get_parameter("target_lambda_p").value == pytest.approx(0.4)
        assert bench.node.get_parameter("target_lambda_psi").value == pytest.approx(0.25)
        assert bench.node.get_parameter("target_timeout").value == pytest.approx(0.5)
    finally:
        bench.close()
