"""info_link node: relays the information vectors ζ_i from ``/fpr/info`` to ``output_topic`` (the topic the
controllers read, their ``info_input_topic``), dropping those sent during a scheduled outage
(:class:`fpr_experiments.link.LinkOutage`). Logs when the link goes down and when it is back.

    ros2 run fpr_experiments info_link --ros-args -p output_topic:=/fpr/info_link -p outage_start:=10.0 \
        -p outage_end:=13.0 -p use_sim_time:=true
"""

from __future__ import annotations

import math

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from fpr_experiments.link import LinkOutage
from fpr_msgs.msg import InformationVector


class InfoLinkNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("info_link", **kwargs)

        def d(name, default, text):
            return self.declare_parameter(name, default, ParameterDescriptor(description=text, read_only=True)).value

        d("n", 3, "number of UAVs (informational)")
        output = d("output_topic", "/fpr/info_link", "where the relayed zeta go (the controllers' info_input_topic)")
        start = float(d("outage_start", math.inf, "[s] simulation time the link goes down (inf: never)"))
        end = float(d("outage_end", math.inf, "[s] simulation time the link is back"))
        self.outage = LinkOutage(start, end)
        qos = QoSProfile(depth=20, reliability=ReliabilityPolicy.BEST_EFFORT)  # as the controllers'
        self.pub = self.create_publisher(InformationVector, output, qos)
        self.create_subscription(InformationVector, "/fpr/info", self._on_info, qos)
        self._down = False
        self.relayed = self.dropped = 0
        self.get_logger().info(f"info_link: /fpr/info -> {output}, outage [{start}, {end}) s")

    def _on_info(self, msg: InformationVector) -> None:
        now = self.get_clock().now().nanoseconds * 1e-9
        passes = self.outage.passes(now)
        if passes == self._down:
            self._down = not passes
            self.get_logger().warning(f"inter-UAV link {'DOWN' if self._down else 'back up'} at t = {now:.2f} s "
                                      f"({self.relayed} relayed, {self.dropped} dropped so far)")
        if passes:
            self.pub.publish(msg)
            self.relayed += 1
        else:
            self.dropped += 1


def main(args=None) -> None:
    from fpr_control.node_utils import spin_node

    spin_node(InfoLinkNode, args)


if __name__ == "__main__":
    main()
