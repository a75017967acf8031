"""Small helpers shared by the fpr_estimation nodes (rclpy side only)."""

from __future__ import annotations

from collections.abc import Callable

import rclpy
from fpr_model.node_parameters import settle_heap
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node


def spin_node(node_factory: Callable[[], Node], args: list[str] | None = None) -> None:
    """The nodes' main(): init rclpy, build the node, settle the heap (fpr_model.node_parameters.settle_heap: no
    garbage-collector pause walks the start-up's objects), spin until Ctrl-C / SIGTERM, shut down cleanly.

    A callback that races the shutdown (SIGINT/SIGTERM) and finds its context gone is not an error; any other
    exception propagates.
    """
    rclpy.init(args=args)
    node = None
    try:
        node = node_factory()
        settle_heap()
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
