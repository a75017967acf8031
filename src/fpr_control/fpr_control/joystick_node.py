"""joystick node: reads a gamepad through the Linux joystick API (/dev/input/js*) and publishes sensor_msgs/Joy
on ``joy`` — for machines without the ROS ``joy`` package. Core: :mod:`fpr_control.joystick_device`.

    ros2 run fpr_control joystick --ros-args -p device:=/dev/input/js0
"""

from __future__ import annotations

from fpr_model.node_parameters import NodeParameters, node_seconds
from rclpy.node import Node
from sensor_msgs.msg import Joy

from fpr_control.joystick_device import JoystickDevice
from fpr_control.node_utils import spin_node

DEVICE_LOG_THROTTLE_S = 10.0  # [s] device errors repeat while unplugged: log rarely

class JoystickNode(Node):
    def __init__(self, **node_kwargs) -> None:
        super().__init__("joystick", **node_kwargs)
        d = NodeParameters(self)
        self.device_path = d("device", "/dev/input/js0",
                             "joystick device (or a FIFO of js_event records)")
        self.poll_rate = float(d("poll_rate", 100.0, "[Hz] device polling rate", low=1.0, high=10000.0))
        autorepeat = float(d("autorepeat_rate", 20.0,
                             "[Hz] republish the state without events (0: off)", high=1000.0))
        invert = bool(d("invert_axes", True, "publish -value/32767 (ROS joy convention: up/left = +1)"))
        self.min_axes = int(d("min_axes", 0, "pad Joy.axes with zeros to at least this length", high=64))
        self.min_buttons = int(d("min_buttons", 0,
                                 "pad Joy.buttons with zeros to at least this length", high=64))
        self.reconnect_period = float(d("reconnect_period", 1.0, "[s] between open attempts", low=0.01, high=3600.0))
        self.device = JoystickDevice(self.device_path, invert_axes=invert)
        self.pub = self.create_publisher(Joy, "joy", 10)
        self._next_open = 0.0
        self._since_publish = 0.0
        self._repeat_period = 1.0 / autorepeat if autorepeat > 0.0 else float("inf")
        self.create_timer(1.0 / self.poll_rate, self._on_poll)

    def _now(self) -> float:
        return node_seconds(self)

    def _on_poll(self) -> None:
        now = self._now()
        if not self.device.is_open:
            if now < self._next_open:
                return
            try:
                self.device.open()
                self.get_logger().info(f"joystick {self.device_path} opened")
            except OSError as error:
                self._next_open = now + self.reconnect_period
                self.get_logger().warning(f"cannot open {self.device_path}: {error.strerror}; retrying",
                                          throttle_duration_sec=DEVICE_LOG_THROTTLE_S)
                return
        try:
            changed = self.device.poll()
        except OSError as error:
            self.get_logger().warning(f"joystick {self.device_path} lost ({error.strerror}); reconnecting",
                                      throttle_duration_sec=DEVICE_LOG_THROTTLE_S)
            self.device.close()
            self._next_open = now + self.reconnect_period
            return
        self._since_publish += 1.0 / self.poll_rate
        if changed or self._since_publish >= self._repeat_period:
            self._publish()

    def destroy_node(self) -> None:
        self.device.close()
        super().destroy_node()

    def _publish(self) -> None:
        self._since_publish = 0.0
        state = self.device.state
        msg = Joy()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = "joystick"
        axes = list(state.axes) + [0.0] * max(0, self.min_axes - len(state.axes))
        buttons = list(state.buttons) + [0] * max(0, self.min_buttons - len(state.buttons))
        msg.axes = [float(a) for a in axes]
        msg.buttons = [int(b) for b in buttons]
        self.pub.publish(msg)


def main(args=None) -> None:
    spin_node(JoystickNode, args)


if __name__ == "__main__":
    main()
