"""REP-107 diagnostics: controller, px4_bridge and pose_estimator each publish their health on /diagnostics
(diagnostic_msgs/DiagnosticArray) once a second, with the level their situation calls for."""

from __future__ import annotations

import time

import pytest

rclpy = pytest.importorskip("rclpy")
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from fpr_model.diagnostics import ERROR, OK, WARN, StatusReport, to_diagnostic_array  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402


def test_report_conversion():
    from builtin_interfaces.msg import Time

    array = to_diagnostic_array([StatusReport("/fpr/uav1/controller", WARN, "NC fallback", "uav1",
                                              {"ages": [0.0, 0.31], "valid": True, "loop": 0.25})], Time(sec=3))
    (status,) = array.status
    assert status.level == DiagnosticStatus.WARN and status.name == "/fpr/uav1/controller"
    assert {kv.key: kv.value for kv in status.values} == {"ages": "0, 0.31", "valid": "True", "loop": "0.25"}
    assert array.header.stamp.sec == 3
    with pytest.raises(ValueError, match="REP-107"):
        StatusReport("x", 7, "bad level")
    assert (OK, WARN, ERROR) == (0, 1, 2)


def test_nodes_say_their_health_on_diagnostics():
    from fpr_control.controller_node import ControllerNode
    from fpr_estimation.pose_estimator import PoseEstimatorNode
    from fpr_px4_bridge.px4_bridge_node import Px4BridgeNode

    rclpy.init()
    nodes = []
    try:
        common = [Parameter("uav_id", value=1)]
        nodes = [ControllerNode(namespace="/fpr/uav1", parameter_overrides=common),
                 Px4BridgeNode(namespace="/fpr/uav1", parameter_overrides=[
                     *common, Parameter("connection_url", value="udp://127.0.0.1:0")]),
                 PoseEstimatorNode(namespace="/fpr/uav1", parameter_overrides=common)]
        listener = rclpy.create_node("diagnostics_listener")
        received: dict[str, DiagnosticStatus] = {}
        listener.create_subscription(DiagnosticArray, "/diagnostics",
                                     lambda m: received.update({s.name: s for s in m.status}), 50)
        executor = SingleThreadedExecutor()
        for node in [*nodes, listener]:
            executor.add_node(node)
        deadline = time.monotonic() + 15.0
        names = {"/fpr/uav1/controller", "/fpr/uav1/px4_bridge", "/fpr/uav1/pose_estimator"}
        while not names <= set(received) and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        assert names <= set(received), f"got diagnostics from {sorted(received)}"
        controller, estimator, bridge = (received[n] for n in sorted(names))
        # no local state, no PX4, no marker: what each one must say
        assert controller.level == DiagnosticStatus.WARN and "no valid local state" in controller.message
        assert bridge.level == DiagnosticStatus.ERROR and "PX4 not heard" in bridge.message, bridge
        assert estimator.level == DiagnosticStatus.WARN and "not initialised" in estimator.message
        assert all(s.hardware_id == "uav1" and s.values for s in (controller, bridge, estimator))
        # the platform tilt the bridges' envelope watches: unknown without a state
        assert {v.key: v.value for v in controller.values}["platform tilt [deg]"] == "nan"
    finally:
        for node in nodes:
            node.destroy_node()
        rclpy.shutdown()
