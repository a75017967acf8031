"""The shipped SROS2 policy (config/sros2/fpr_n3.policy.xml) is what the robot's graph needs and no more: it is
a fresh generation from the graph (not stale), and its content grants each safety-relevant topic to its one
writer (issue 12). SROS2 itself cannot run here (Fast DDS without security): what is tested is the policy."""

from __future__ import annotations

import os
import re
import xml.etree.ElementTree as ET

import pytest
from fpr_experiments.graph import describe_graph
from fpr_experiments.security import MONITOR_ENCLAVE, read_policy, robot_graph, robot_policy

POLICY_FILE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "config", "sros2",
                           "fpr_n3.policy.xml")
N = 3


@pytest.fixture(scope="module")
def shipped() -> str:
    with open(POLICY_FILE, encoding="utf-8") as stream:
        return stream.read()


@pytest.fixture(scope="module")
def generated():
    return robot_policy(N)


def _writers(policy: dict, topic: str) -> set[str]:
    return {enclave for enclave, rules in policy.items() if topic in rules["publish"]}


def test_the_shipped_policy_is_a_fresh_generation(shipped, generated):
    _, text = generated
    assert shipped == text, ("config/sros2/fpr_n3.policy.xml is stale: regenerate it with "
                             "`ros2 run fpr_experiments security_policy --output <that file>`")


def test_the_policy_has_the_sros2_structure(shipped):
    root = ET.fromstring(shipped)
    assert root.tag == "policy" and root.get("version") == "0.2.0"
    assert [child.tag for child in root] == ["enclaves"]
    for enclave in root.iter("enclave"):
        assert enclave.get("path", "").startswith("/")
        profiles = enclave.findall("profiles/profile")
        assert len(profiles) == 1 and profiles[0].get("ns") and profiles[0].get("node")
        for group in profiles[0]:
            assert group.tag in ("topics", "services")
            assert set(group.attrib) <= {"publish", "subscribe", "reply", "request"}
            assert set(group.attrib.values()) == {"ALLOW"}
            names = [child.text for child in group]
            assert names and all(name.startswith("/") and "*" not in name for name in names), names


def test_one_enclave_per_node_of_the_robot_and_one_per_external_input(shipped):
    policy = read_policy(shipped)
    nodes = {spec.fully_qualified_name for spec in robot_graph(N)}
    assert nodes <= set(policy)
    external = set(policy) - nodes
    assert external == {*(f"/fpr/uav{i}/camera_driver" for i in range(1, N + 1)), "/fpr/ground/motion_capture",
                        MONITOR_ENCLAVE}, external
    assert "/simulator" not in policy  # the robot's policy: no simulated hardware


def test_each_safety_topic_has_exactly_its_one_writer(shipped):
    policy = read_policy(shipped)
    assert _writers(policy, "/fpr/teleop") == {"/fpr/ground/teleop"}
    for i in range(1, N + 1):
        ns = f"/fpr/uav{i}"
        assert _writers(policy, f"{ns}/setpoint") == {f"{ns}/controller"}
        assert _writers(policy, f"{ns}/status") == {f"{ns}/px4_bridge"}
        assert _writers(policy, f"{ns}/local_state") == {f"{ns}/pose_estimator"}
        assert _writers(policy, f"{ns}/imu") == {f"{ns}/px4_bridge"}
        assert _writers(policy, f"{ns}/marker") == {f"{ns}/aruco_detector"}
        assert _writers(policy, f"{ns}/camera/image_raw") == {f"{ns}/camera_driver"}
        # no UAV's node may write another UAV's topics
        for enclave, rules in policy.items():
            other = re.match(r"^/fpr/uav(\d+)/", enclave)
            if other and int(other.group(1)) != i:
                assert not {t for t in rules["publish"] if t.startswith(ns + "/")}, (enclave, ns)
    # the shared zeta topic: the n controllers, nobody else (per-uav_id ownership is the controllers' check)
    assert _writers(policy, "/fpr/info") == {f"/fpr/uav{i}/controller" for i in range(1, N + 1)}
    assert _writers(policy, "/fpr/motion_capture") == {"/fpr/ground/motion_capture"}


def test_the_monitor_reads_everything_and_sets_nothing(shipped):
    policy = read_policy(shipped)
    monitor = policy[MONITOR_ENCLAVE]
    published = set().union(*(rules["publish"] for enclave, rules in policy.items() if enclave != MONITOR_ENCLAVE))
    assert monitor["subscribe"] == published
    assert monitor["publish"] == {"/rosout", "/parameter_events"}  # what every rcl node publishes
    assert monitor["request"] and not any(s.endswith(("/set_parameters", "/set_parameters_atomically"))
                                          for s in monitor["request"])
    assert not monitor["reply"]


def test_every_subscription_has_a_writer_in_the_policy(shipped):
    policy = read_policy(shipped)
    published = set().union(*(rules["publish"] for rules in policy.values()))
    for enclave, rules in policy.items():
        assert rules["subscribe"] <= published, (enclave, rules["subscribe"] - published)


def test_the_simulated_graph_has_no_enclave_left_out(generated):
    """Every node of the simulated graph except the simulator and the sim-only operators is a robot node."""
    from fpr_experiments.graph import GraphOptions

    enclaves, _ = generated
    sim = describe_graph(GraphOptions(n=N, cameras="images", operator="joystick"))
    robot_nodes = {s.fully_qualified_name for s in sim if s.executable != "simulator"}
    assert robot_nodes <= {e.enclave for e in enclaves}
