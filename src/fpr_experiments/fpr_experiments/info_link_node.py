"""info_link node: relays the information vectors ζ_i from ``/fpr/info`` to one topic per receiving UAV j
(``output_topic`` with ``{uav}`` = j, each controller's ``info_input_topic``), through the link of
:mod:`fpr_experiments.link`: a scheduled outage (``outage_start`` / ``outage_end``) and, when the scenario's
realism profile enables it (``scenario.link``, read from the same ``scenario_file`` and ``realism`` as the
simulator's), the Wi-Fi channel: per-pair latency, loss and bursts in simulation time. ζ in flight are released on
every ``/clock`` message at or after their due time (with ``use_sim_time``; else by a 1 ms wall timer). Logs when
the outage starts and ends.

    ros2 run fpr_experiments info_link --ros-args -p n:=3 -p scenario_file:=reports/x/scenario.yaml \
        -p realism:=hardware -p outage_start:=10.0 -p outage_end:=13.0 -p use_sim_time:=true
"""

from __future__ import annotations

import math

from fpr_model.node_parameters import NodeParameters, node_seconds
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from fpr_experiments.link import LinkOutage, LinkRelay, expected_latency, expected_loss
from fpr_msgs.msg import InformationVector

#: the receivers' topics; ``{uav}`` is the receiving UAV's id
DEFAULT_OUTPUT_TOPIC = "/fpr/uav{uav}/info_link"


def output_topics(pattern: str, n: int) -> dict[int, str]:
    """Receiver id -> topic, from ``pattern`` (must contain ``{uav}``)."""
    if "{uav}" not in pattern:
        raise ValueError(f"output_topic '{pattern}' needs '{{uav}}' (the receiving UAV's id), e.g. "
                         f"{DEFAULT_OUTPUT_TOPIC}")
    return {j: pattern.format(uav=j) for j in range(1, n + 1)}


class InfoLinkNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("info_link", **kwargs)

        d = NodeParameters(self)

        n = int(d("n", 3, "number of UAVs (receivers 1..n)", low=3, high=64))
        pattern = d("output_topic", DEFAULT_OUTPUT_TOPIC, "receivers' topics, {uav} = the receiver's id (each "
                    "controller's info_input_topic)")
        start = float(d("outage_start", math.inf, "[s] simulation time the link goes down (inf: never)", high=math.inf))
        end = float(d("outage_end", math.inf, "[s] simulation time the link is back", high=math.inf))
        scenario_file = d("scenario_file", "", "the simulator's scenario (its 'link' section and seed); empty: "
                          "no channel model, only the outage")
        realism = d("realism", "", "realism profile, as the simulator's: ideal | hardware; empty: the scenario's")
        link, seed = None, 0
        if scenario_file:
            from fpr_sim.scenario import load_scenario

            scenario = load_scenario(scenario_file, realism=str(realism) or None)
            link, seed = scenario.link, scenario.seed
        self.relay = LinkRelay(n, LinkOutage(start, end), link, seed)
        qos = QoSProfile(depth=20, reliability=ReliabilityPolicy.BEST_EFFORT)  # as the controllers'
        # publishers reliable (REP-2003: any subscriber can connect); the controllers read best effort
        self.pubs = {j: self.create_publisher(InformationVector, topic, 20)
                     for j, topic in output_topics(pattern, n).items()}
        self.create_subscription(InformationVector, "/fpr/info", self._on_info, qos)
        if self.get_parameter("use_sim_time").value:
            self.create_subscription(Clock, "/clock", self._on_clock, 10)
        else:
            self.create_timer(0.001, lambda: self._deliver(self.relay.release(self._now())))
        self._down = False
        channel = "none (ideal)" if self.relay.model is None else (
            f"Wi-Fi, mean latency {expected_latency(link) * 1e3:.1f} ms, loss {expected_loss(link) * 100:.1f} % "
            f"(seed {seed})")
        self.get_logger().info(f"info_link: /fpr/info -> {pattern}, outage [{start}, {end}) s, channel {channel}")

    def _now(self) -> float:
        return node_seconds(self)

    def _deliver(self, deliveries) -> None:
        for receiver, msg in deliveries:
            self.pubs[receiver].publish(msg)

    def _on_clock(self, msg: Clock) -> None:
        self._deliver(self.relay.release(msg.clock.sec + 1e-9 * msg.clock.nanosec))

    def _on_info(self, msg: InformationVector) -> None:
        now = self._now()
        passes = self.relay.outage.passes(now)
        if passes == self._down:
            self._down = not passes
            c = self.relay.counters
            self.get_logger().warning(f"inter-UAV link {'DOWN' if self._down else 'back up'} at t = {now:.2f} s "
                                      f"({c.relayed} relayed, {c.lost} lost, {c.dropped} dropped so far)")
        self._deliver(self.relay.send(int(msg.uav_id), now, msg))


def main(args=None) -> None:
    from fpr_control.node_utils import spin_node

    spin_node(InfoLinkNode, args)


if __name__ == "__main__":
    main()
