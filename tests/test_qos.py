"""QoS as REP-2003 asks: every publisher of the simulated graph is reliable (the system default), so that a
subscriber with the default profile connects to every topic and receives the data; the graph's own readers of
sensor and control data stay best effort. The demo's graph with rendered images (simulator, aruco_detector,
pose_estimator, controller, px4_bridge, teleop, joy_script), checked while it flies."""

from __future__ import annotations

import importlib
import threading
import time

import pytest
import rclpy
from fpr_experiments.catalog import load_experiment
from fpr_experiments.graph import describe_graph
from fpr_experiments.inprocess import InProcessGraph
from fpr_experiments.resources import SCENARIOS
from fpr_experiments.runner import graph_options
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

#: topics every flight publishes periodically: a default-QoS subscriber must receive each of them
PERIODIC = ["/clock", "/fpr/ground_truth", "/fpr/motion_capture", "/fpr/teleop", "/fpr/info", "/tf", "/diagnostics",
            *[f"/fpr/uav{i}/{t}" for i in (1, 2, 3) for t in (
                "imu", "velocity_body", "status", "camera/image_raw", "camera/camera_info", "marker", "local_state",
                "setpoint", "wrench", "controller_status")]]


def _message_type(name: str):
    package, kind, type_name = name.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), type_name)


@pytest.fixture(scope="module")
def probed_flight():
    experiment = load_experiment("takeoff_landing")
    options = graph_options(experiment, experiment.variants[0], SCENARIOS.resolve(experiment.scenario), "images", 3,
                            realism="ideal")  # the QoS of the graph, not the realism (unit-level: issue 11)
    probe_context = rclpy.Context()
    rclpy.init(context=probe_context)
    probe = rclpy.create_node("qos_probe", context=probe_context)
    executor = SingleThreadedExecutor(context=probe_context)
    executor.add_node(probe)
    received: dict[str, int] = {}
    running = [True]

    def spin() -> None:
        while running[0]:
            executor.spin_once(timeout_sec=0.05)

    spinner = threading.Thread(target=spin, daemon=True)
    try:
        with InProcessGraph(describe_graph(options)) as swarm:
            swarm.wait_for_discovery()
            swarm.run_until(lambda: swarm.sim_time >= 2.0, wall_timeout=120.0)
            deadline = time.monotonic() + 10.0
            while not set(PERIODIC) <= {n for n, _ in probe.get_topic_names_and_types()}:
                executor.spin_once(timeout_sec=0.1)
                assert time.monotonic() < deadline, "the probe did not discover the graph's topics"
            topics = dict(probe.get_topic_names_and_types())
            publishers = {name: probe.get_publishers_info_by_topic(name) for name in topics}
            default = QoSProfile(depth=10)  # reliable, volatile: what `ros2 topic echo` or a user's node uses
            assert default.reliability == ReliabilityPolicy.RELIABLE
            for name, types in topics.items():
                probe.create_subscription(_message_type(types[0]), name,
                                          lambda _m, name=name: received.__setitem__(name, received.get(name, 0) + 1),
                                          default)
            spinner.start()
            time.sleep(1.0)  # matching
            swarm.run_until(lambda: swarm.sim_time >= 6.0, wall_timeout=120.0)
            time.sleep(0.5)
    finally:
        running[0] = False
        if spinner.is_alive():
            spinner.join(timeout=5.0)
        probe.destroy_node()
        rclpy.shutdown(context=probe_context)
    return publishers, received


def test_every_publisher_is_reliable(probed_flight):
    publishers, _ = probed_flight
    best_effort = sorted({f"{name} ({info.node_namespace}/{info.node_name})" for name, infos in publishers.items()
                          for info in infos if info.qos_profile.reliability != ReliabilityPolicy.RELIABLE
                          and info.node_name != "qos_probe"})
    assert not best_effort, f"best-effort publishers (a default subscriber cannot connect): {best_effort}"
    latched = {name for name, infos in publishers.items()
               if any(i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos)}
    assert {"/robot_description", "/tf_static"} <= latched


def test_a_default_subscriber_receives_every_periodic_topic(probed_flight):
    _, received = probed_flight
    missing = [name for name in PERIODIC if received.get(name, 0) == 0]
    assert not missing, f"nothing received with the default QoS on {missing}"
