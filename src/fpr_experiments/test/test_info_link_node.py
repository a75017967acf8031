"""info_link node in process (real rclpy, scripts/run_tests.sh): a ζ delayed by L by the scenario's link is
delivered L later in simulation time (released on /clock), to each receiver's own topic, the own echo at once; the
scheduled outage still drops every ζ, on top of the channel. Driven like the in-process runner: publish /clock,
drain the executor."""

from __future__ import annotations

import time

import pytest
import yaml

rclpy = pytest.importorskip("rclpy")
from fpr_experiments.info_link_node import InfoLinkNode, output_topics  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402

from fpr_msgs.msg import InformationVector  # noqa: E402

BEST_EFFORT = QoSProfile(depth=20, reliability=ReliabilityPolicy.BEST_EFFORT)
LATENCY = 0.05  # [s]


class Bench:
    """The node, a helper publishing /clock and /fpr/info, and one recording subscription per receiver."""

    def __init__(self, parameters: dict) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        overrides = [Parameter("use_sim_time", value=True)] + [Parameter(k, value=v) for k, v in parameters.items()]
        self.node = InfoLinkNode(context=self.context, parameter_overrides=overrides)
        self.helper = rclpy.create_node("info_link_test_helper", context=self.context)
        self.clock_pub = self.helper.create_publisher(Clock, "/clock", 10)
        self.info_pub = self.helper.create_publisher(InformationVector, "/fpr/info", BEST_EFFORT)
        self.now = 0.0
        self.received: dict[int, list[tuple[float, int]]] = {j: [] for j in (1, 2, 3)}
        for j, topic in output_topics("/fpr/uav{uav}/info_link", 3).items():
            self.helper.create_subscription(InformationVector, topic, lambda m, j=j: self.received[j].append(
                (self.now, m.uav_id)), BEST_EFFORT)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.helper)
        deadline = time.monotonic() + 10.0
        while not self._matched():
            assert time.monotonic() < deadline, "discovery"
            self.drain()
            time.sleep(0.01)

    def _matched(self) -> bool:
        return self.clock_pub.get_subscription_count() >= 2 and self.info_pub.get_subscription_count() >= 1 and \
            all(p.get_subscription_count() >= 1 for p in self.node.pubs.values())

    def drain(self) -> None:
        for _ in range(30):
            self.executor.spin_once(timeout_sec=0.002)

    def clock(self, t: float) -> None:
        self.now = t
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = int(t), round((t - int(t)) * 1e9)
        self.clock_pub.publish(msg)
        self.drain()

    def send(self, uav_id: int) -> None:
        msg = InformationVector()
        msg.uav_id = uav_id
        self.info_pub.publish(msg)
        self.drain()

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.helper.destroy_node()
        self.context.try_shutdown()


@pytest.fixture()
def scenario_file(tmp_path):
    path = tmp_path / "scenario.yaml"
    path.write_text(yaml.safe_dump({"seed": 3, "link": {"enabled": True, "latency_min": LATENCY}}))
    return str(path)


def test_a_zeta_delayed_by_the_link_arrives_that_much_later_in_sim_time(scenario_file):
    bench = Bench({"n": 3, "scenario_file": scenario_file})
    try:
        assert bench.node.relay.model is not None
        bench.clock(1.0)
        bench.send(1)
        assert bench.received == {1: [(1.0, 1)], 2: [], 3: []}  # the own echo at once
        for t in (1.004, 1.02, 1.048):
            bench.clock(t)
        assert bench.received[2] == [] and bench.received[3] == []
        bench.clock(1.052)  # the first /clock at or after 1.05
        assert bench.received[2] == [(1.052, 1)] and bench.received[3] == [(1.052, 1)]
        assert len(bench.received[1]) == 1  # nothing else reached UAV 1
    finally:
        bench.close()


def test_the_outage_still_drops_on_top_of_the_channel(scenario_file):
    bench = Bench({"n": 3, "scenario_file": scenario_file, "outage_start": 2.0, "outage_end": 3.0})
    try:
        bench.clock(2.5)
        bench.send(2)
        for t in (2.6, 3.0, 3.2):
            bench.clock(t)
        assert bench.received == {1: [], 2: [], 3: []} and bench.node.relay.counters.dropped == 1
        bench.send(2)  # at 3.2: back up
        bench.clock(3.26)
        assert [len(bench.received[j]) for j in (1, 2, 3)] == [1, 1, 1]
    finally:
        bench.close()


def test_without_a_scenario_it_is_a_pure_relay_to_every_receiver():
    bench = Bench({"n": 3})
    try:
        assert bench.node.relay.model is None
        bench.clock(1.0)
        bench.send(3)
        assert [bench.received[j] for j in (1, 2, 3)] == [[(1.0, 3)]] * 3
    finally:
        bench.close()
