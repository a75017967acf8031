"""Helper process for test_msgs_roundtrip.py: publishes one filled sample of every fpr_msgs type, repeatedly.

Run as a separate process so the round trip crosses a process boundary through Fast DDS.
"""
import sys

import rclpy
from msg_samples import SAMPLES
from rclpy.qos import QoSDurabilityPolicy, QoSProfile, QoSReliabilityPolicy


def main() -> int:
    rclpy.init()
    node = rclpy.create_node('fpr_msgs_echo_publisher')
    qos = QoSProfile(depth=1, reliability=QoSReliabilityPolicy.RELIABLE,
                     durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
    publishers = [(node.create_publisher(type(msg), f'/fpr_test/{type(msg).__name__}', qos), msg)
                  for msg in (make() for make in SAMPLES.values())]

    def publish_all() -> None:
        for publisher, msg in publishers:
            publisher.publish(msg)

    node.create_timer(0.1, publish_all)
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
