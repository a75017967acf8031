"""pilot node (ground station, simulation): the scripted human operator of :mod:`fpr_experiments.pilot`.

Plays a pilot script — a joy script's keyframes (buttons, scripted axes) with the operator's closed-loop tasks on
top — as sensor_msgs/Joy on ``joy`` for the teleop node, watching the platform on ``/fpr/ground_truth`` (the
motion capture stands in for the operator's eyes), and publishes each task event (start, criterion reached,
contact, end with success or failure) as JSON (std_msgs/String) on ``/fpr/pilot/events``.

    ros2 run fpr_experiments pilot --ros-args -r __ns:=/fpr/ground -p use_sim_time:=true \
        -p script:=table_4_3_tennis.yaml
"""

from __future__ import annotations

import json
import math

import numpy as np
import yaml
from fpr_model.node_parameters import NodeParameters, node_seconds
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Joy
from std_msgs.msg import String

from fpr_experiments.pilot import Observation, Pilot, channels_from_mapping, pilot_from_script
from fpr_experiments.resources import JOY_SCRIPTS, config_path
from fpr_msgs.msg import FprState

EVENTS_TOPIC = "/fpr/pilot/events"


class PilotNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("pilot", **kwargs)
        from fpr_control.joy_timeline import timeline_from_dict

        d = NodeParameters(self)

        script = d("script", "", "pilot script: a joy script with `pilot` and `tasks` sections (name or path)")
        mapping_file = d("mapping_file", "", "teleop mapping YAML (empty: fpr_control's config/teleop.yaml)")
        rate = float(d("rate", 50.0, "[Hz] Joy publishing rate", low=1.0, high=1000.0))
        seed = int(d("seed", -1, "operator noise seed (-1: the script's pilot.seed)", low=-1, high=2**31 - 1))
        path = JOY_SCRIPTS.resolve(script)
        with open(path, encoding="utf-8") as stream:
            document = yaml.safe_load(stream) or {}
        with open(mapping_file or config_path("fpr_control", "teleop.yaml"), encoding="utf-8") as stream:
            mapping = yaml.safe_load(stream) or {}
        self.timeline = timeline_from_dict(document)
        config, plan = pilot_from_script(document)
        if seed >= 0:
            from dataclasses import replace

            config = replace(config, seed=seed)
        self.pilot = Pilot(config, plan, channels_from_mapping(mapping))
        self.pub = self.create_publisher(Joy, "joy", 10)
        self.events_pub = self.create_publisher(String, EVENTS_TOPIC, QoSProfile(
            depth=100, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self.create_subscription(FprState, "/fpr/ground_truth", self._on_truth, 10)
        self._start: float | None = None
        self.create_timer(1.0 / rate, self._on_tick)
        self.get_logger().info(f"pilot: {path}, {len(plan.tasks)} tasks in [{plan.start}, {plan.end}] s, "
                               f"reaction {config.reaction_delay} s, seed {config.seed}")

    def _now(self) -> float:
        return node_seconds(self)

    def _on_truth(self, msg: FprState) -> None:
        if self._start is None:
            return
        p, q = msg.platform_pose.position, msg.platform_pose.orientation
        values = [p.x, p.y, p.z, q.w, q.x, q.y, q.z, msg.contact_force]
        if not all(math.isfinite(v) for v in values):
            return
        yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
        t = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec - self._start
        self.pilot.observe(Observation(t, np.array([p.x, p.y, p.z]), yaw, float(msg.contact_force)))

    def _on_tick(self) -> None:
        now = self._now()
        if self._start is None:
            if self.pub.get_subscription_count() == 0:
                return
            self._start = now
        t = now - self._start
        axes, buttons = self.timeline.sample(t)
        for index, value in self.pilot.axes(t).items():
            if 0 <= index < len(axes):
                axes[index] = value
        for event in self.pilot.take_events():
            event["t_script"], event["t"] = event["t"], round(now, 4)  # t: simulation time (as the records)
            self.get_logger().info(f"pilot task {event['task']} {event['event']}"
                                   + (f": {'success' if event.get('success') else 'failure'} ({event['reason']})"
                                      if event["event"] == "task_end" else ""))
            self.events_pub.publish(String(data=json.dumps(event)))
        msg = Joy()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = "pilot"
        msg.axes, msg.buttons = axes, buttons
        self.pub.publish(msg)


def main(args=None) -> None:
    from fpr_control.node_utils import spin_node

    spin_node(PilotNode, args)


if __name__ == "__main__":
    main()
