"""The `ros2` stand-in (scripts/ros2_standin.py, installed where no real ros2cli exists): topic, node, param and
interface commands against a running node, with ros2cli's output format."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

STANDIN = Path(__file__).resolve().parents[1] / "scripts" / "ros2_standin.py"

TALKER = """
import rclpy
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from std_msgs.msg import String

rclpy.init()
node = Node("standin_talker", namespace="/probe")
node.declare_parameter("rate", 20.0, ParameterDescriptor(read_only=True))
node.declare_parameter("gain", 1.5)
node.add_on_set_parameters_callback(lambda params: SetParametersResult(successful=True))
publisher = node.create_publisher(String, "/probe/chatter", 10)
count = [0]
def tick():
    count[0] += 1
    publisher.publish(String(data=f"hello {count[0]}"))
node.create_timer(0.05, tick)
print("ready", flush=True)
rclpy.spin(node)
"""


def _ros2(*args: str, timeout: float = 30.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(STANDIN), *args], capture_output=True, text=True, timeout=timeout,
                          check=False)


@pytest.fixture(scope="module")
def talker():
    process = subprocess.Popen([sys.executable, "-c", TALKER], env=dict(os.environ), stdout=subprocess.PIPE, text=True)
    assert process.stdout.readline().strip() == "ready"
    time.sleep(1.0)
    yield process
    process.terminate()
    process.wait(timeout=10)


def test_topic_list_info_echo(talker):
    listed = _ros2("topic", "list", "-t")
    assert listed.returncode == 0, listed.stderr
    assert "/probe/chatter [std_msgs/msg/String]" in listed.stdout.splitlines()
    info = _ros2("topic", "info", "/probe/chatter")
    assert "Type: std_msgs/msg/String" in info.stdout and "Publisher count: 1" in info.stdout
    echoed = _ros2("topic", "echo", "/probe/chatter", "--once")
    assert echoed.returncode == 0, echoed.stderr
    assert echoed.stdout.startswith("data: hello ") and echoed.stdout.rstrip().endswith("---")
    unknown = _ros2("topic", "echo", "/probe/nothing", "--spin-time", "0.5")
    assert unknown.returncode == 1 and "Could not determine the type" in unknown.stderr


def test_topic_hz_measures_the_rate(talker):
    hz = subprocess.Popen([sys.executable, str(STANDIN), "topic", "hz", "/probe/chatter"], stdout=subprocess.PIPE,
                          text=True)
    time.sleep(6.0)
    hz.send_signal(signal.SIGINT)   # as Ctrl-C: the stand-in leaves the graph cleanly
    output, _ = hz.communicate(timeout=10)
    assert hz.returncode == 0
    rates = [float(line.split(":")[1]) for line in output.splitlines() if line.startswith("average rate:")]
    assert rates, output
    assert 15.0 < rates[-1] < 25.0          # the talker's 20 Hz timer (wall clock)


def test_node_list(talker):
    listed = _ros2("node", "list")
    assert "/probe/standin_talker" in listed.stdout.splitlines()
    assert not any("_ros2cli_standin_" in line for line in listed.stdout.splitlines())


def test_param_get_set_list(talker):
    assert _ros2("param", "get", "/probe/standin_talker", "gain").stdout.strip() == "Double value is: 1.5"
    assert _ros2("param", "set", "/probe/standin_talker", "gain", "2.5").stdout.strip() == "Set parameter successful"
    assert _ros2("param", "get", "/probe/standin_talker", "gain").stdout.strip() == "Double value is: 2.5"
    refused = _ros2("param", "set", "/probe/standin_talker", "rate", "3.0")
    assert refused.returncode == 1 and refused.stdout.startswith("Setting parameter failed:")
    assert "read-only" in refused.stdout
    listed = _ros2("param", "list", "/probe/standin_talker").stdout.splitlines()
    assert listed[0] == "/probe/standin_talker:" and "  gain" in listed and "  rate" in listed
    missing = _ros2("param", "get", "/probe/nobody", "gain", "--spin-time", "0.5")
    assert missing.returncode == 1 and "Node not found" in missing.stderr


def test_interface_show():
    shown = _ros2("interface", "show", "std_msgs/msg/String")
    assert shown.returncode == 0 and "string data" in shown.stdout
    fpr = _ros2("interface", "show", "fpr_msgs/msg/InformationVector")
    assert fpr.returncode == 0 and fpr.stdout.strip()
    assert _ros2("interface", "show", "std_msgs/msg/Nope").returncode == 1
