"""Small helpers shared by the fpr_control nodes (rclpy side only)."""

from __future__ import annotations

from collections.abc import Callable

import rclpy
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

LOG_THROTTLE_S = 2.0  # [s] per-cycle warnings: at most one per call site and period


def describe(text: str) -> ParameterDescriptor:
    """ParameterDescriptor with a description (every parameter is declared with one), read-only: the nodes read
    their parameters at start-up, so ``ros2 param set`` is refused ("read-only") instead of reporting a success
    that changes nothing (issue 14); set them with ``--ros-args -p name:=value`` or a params file."""
    return ParameterDescriptor(description=text, read_only=True)


def spin_node(node_factory: Callable[[], Node], args: list[str] | None = None) -> None:
    """The nodes' main(): init rclpy, build the node, spin until Ctrl-C / SIGTERM, shut down cleanly.

    A callback that races the shutdown (SIGINT/SIGTERM) and finds its context gone is not an error; any other
    exception propagates.
    """
    rclpy.init(args=args)
    node = None
    try:
        node = node_factory()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if rclpy.ok():
            raise
    finally:
        if node is not None:
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
