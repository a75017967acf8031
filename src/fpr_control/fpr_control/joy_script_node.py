"""joy_script node: plays a YAML timeline of Joy axes and buttons (scripted teleoperation for tests and demos).
Core: :mod:`fpr_control.joy_timeline`; examples in config/joy_scripts/.

    ros2 run fpr_control joy_script --ros-args -p script:=roll_and_legs.yaml
"""

from __future__ import annotations

import os

import rclpy
import yaml
from fpr_model.node_parameters import NodeParameters, node_seconds
from rclpy.node import Node
from sensor_msgs.msg import Joy

from fpr_control.joy_timeline import timeline_from_dict
from fpr_control.node_utils import spin_node
from fpr_control.teleop_node import default_mapping_file


def resolve_script(name: str) -> str:
    """An absolute/relative existing path, or a file name in the installed config/joy_scripts/."""
    if os.path.exists(name):
        return name
    return os.path.join(os.path.dirname(default_mapping_file()), "joy_scripts", name)


class JoyScriptNode(Node):
    def __init__(self, **node_kwargs) -> None:
        super().__init__("joy_script", **node_kwargs)
        d = NodeParameters(self)
        script = d("script", "takeoff_hover_land.yaml",
                   "timeline YAML (path or name in config/joy_scripts)")
        rate = float(d("rate", 50.0, "[Hz] Joy publishing rate", low=1.0, high=1000.0))
        self.start_delay = float(d("start_delay", 0.0, "[s] after the start condition"))
        self.wait_for_subscribers = bool(d("wait_for_subscribers", True,
            "start the timeline when 'joy' has a subscriber"))
        self.stop_at_end = bool(d("stop_at_end", False, "stop publishing after the last keyframe"))
        self.exit_at_end = bool(d("exit_at_end", False, (
            "exit the process exit_delay s after the last keyframe (a timeline that does not loop); false: publish "
            "the last keyframe until stopped (Ctrl-C)")))
        self.exit_delay = float(d("exit_delay", 5.0, (
            "[s] after the last keyframe, the last values still published (the robot finishes its landing), "
            "before exit_at_end exits"), low=0.0, high=3600.0))
        path = resolve_script(script)
        with open(path, encoding="utf-8") as stream:
            self.timeline = timeline_from_dict(yaml.safe_load(stream))
        self.pub = self.create_publisher(Joy, "joy", 10)
        self._start: float | None = None
        self._finished = False
        self.create_timer(1.0 / rate, self._on_tick)
        if self.timeline.loop:
            ending = "loops until stopped (Ctrl-C)"
        elif self.exit_at_end:
            ending = f"exits {self.exit_delay:g} s after its last keyframe"
        else:
            ending = "then publishes its last keyframe until stopped (Ctrl-C; -p exit_at_end:=true exits by itself)"
        self.get_logger().info(f"joy_script: {path}, {len(self.timeline.keyframes)} keyframes, "
                               f"{self.timeline.duration:.1f} s, {ending}")

    def _now(self) -> float:
        return node_seconds(self)

    def _on_tick(self) -> None:
        now = self._now()
        if self._start is None:
            if self.wait_for_subscribers and self.pub.get_subscription_count() == 0:
                return
            self._start = now + self.start_delay
        t = now - self._start
        if t < 0.0 or self._finished:
            return
        if self.exit_at_end and not self.timeline.loop and t > self.timeline.duration + self.exit_delay:
            self._finished = True
            self.get_logger().info("joy_script: timeline finished, exiting (exit_at_end)")
            rclpy.shutdown(context=self.context)  # spin() returns: main() ends, the process exits with status 0
            return
        if self.stop_at_end and not self.timeline.loop and t > self.timeline.duration:
            self._finished = True
            self.get_logger().info("joy_script: timeline finished")
            return
        axes, buttons = self.timeline.sample(t)
        msg = Joy()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = "joy_script"
        msg.axes, msg.buttons = axes, buttons
        self.pub.publish(msg)


def main(args=None) -> None:
    spin_node(JoyScriptNode, args)


if __name__ == "__main__":
    main()
