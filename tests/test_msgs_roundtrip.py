"""fpr_msgs: every message type published by one process is received intact by another (real rclpy, Fast DDS).

Runs under the test runner's network isolation (unshare -n, ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST).
"""
import os
import subprocess
import sys
import time

import rclpy
from rclpy.qos import QoSDurabilityPolicy, QoSProfile, QoSReliabilityPolicy

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from msg_samples import SAMPLES  # noqa: E402


def test_isolation_is_active() -> None:
    assert os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE') == 'LOCALHOST'


def test_every_fpr_message_crosses_a_process_boundary() -> None:
    env = dict(os.environ, PYTHONPATH=HERE + os.pathsep + os.environ.get('PYTHONPATH', ''))
    publisher = subprocess.Popen([sys.executable, os.path.join(HERE, 'msg_echo_publisher.py')], env=env)
    rclpy.init()
    node = rclpy.create_node('fpr_msgs_roundtrip_test')
    received: dict[str, object] = {}
    qos = QoSProfile(depth=1, reliability=QoSReliabilityPolicy.RELIABLE,
                     durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
    try:
        for name, make in SAMPLES.items():
            node.create_subscription(type(make()), f'/fpr_test/{name}',
                                     lambda msg, name=name: received.setdefault(name, msg), qos)
        deadline = time.monotonic() + 30.0
        while len(received) < len(SAMPLES) and time.monotonic() < deadline and publisher.poll() is None:
            rclpy.spin_once(node, timeout_sec=0.1)
    finally:
        publisher.terminate()
        publisher.wait(timeout=10)
        node.destroy_node()
        rclpy.try_shutdown()
    assert sorted(received) == sorted(SAMPLES), f'missing: {sorted(set(SAMPLES) - set(received))}'
    for name, make in SAMPLES.items():
        assert received[name] == make(), name
