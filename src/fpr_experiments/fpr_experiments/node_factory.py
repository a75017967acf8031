"""Build the nodes of a :class:`~fpr_experiments.graph.NodeSpec` inside a process (rclpy): the node class of its
executable, constructed with the spec's ``--ros-args`` as the node's own ``cli_args`` — rcl then applies the
``--params-file`` files (only their ``/**`` and matching-node sections), the ``-p`` overrides and the remappings
to that node alone, exactly as for ``ros2 run``. Used by the in-process runner and by ``node_group``."""

from __future__ import annotations

import importlib
from collections.abc import Sequence

from rclpy.node import Node

from fpr_experiments.graph import NodeSpec

#: executable -> "module:NodeClass"; each module's ``main`` is the executable's console script (checked by a test)
NODE_CLASSES: dict[str, str] = {
    "simulator": "fpr_sim.simulator:SimulatorNode",
    "px4_bridge": "fpr_px4_bridge.px4_bridge_node:Px4BridgeNode",
    "aruco_detector": "fpr_estimation.aruco_detector:ArucoDetectorNode",
    "pose_estimator": "fpr_estimation.pose_estimator:PoseEstimatorNode",
    "controller": "fpr_control.controller_node:ControllerNode",
    "teleop": "fpr_control.teleop_node:TeleopNode",
    "joy_script": "fpr_control.joy_script_node:JoyScriptNode",
    "joystick": "fpr_control.joystick_node:JoystickNode",
    "pilot": "fpr_experiments.pilot_node:PilotNode",
    "info_link": "fpr_experiments.info_link_node:InfoLinkNode",
    "detection_fallback": "fpr_experiments.detection_fallback_node:DetectionFallbackNode",
}


def node_class(executable: str) -> type[Node]:
    try:
        module_name, class_name = NODE_CLASSES[executable].split(":")
    except KeyError:
        raise ValueError(f"no node class known for executable '{executable}'; known: {', '.join(NODE_CLASSES)}") \
            from None
    return getattr(importlib.import_module(module_name), class_name)


_LEAN_CLASSES: dict[type, type] = {}
#: the lean nodes' rcl arguments besides their spec's: rclpy's own read-only parameter switching the node's
#: ``~/get_type_description`` service off (one service per node, polled at every drain of the deterministic runner
#: although nothing in a simulation run asks it: ~1 % of the n = 6 graph's CPU, docs/benchmarks.md)
LEAN_ROS_ARGS = ("--ros-args", "-p", "start_type_description_service:=false")


def lean_class(cls: type[Node]) -> type[Node]:
    """``cls`` whose publishers and subscriptions get no default QoS event handlers (the "incompatible QoS" and
    "incompatible type" warnings rclpy attaches to every endpoint: two executor entities each, two thirds of the
    wait set of the simulated graph). For a graph whose QoS is fixed by its description (simulation runs); on the
    robot keep the warnings (build_node(lean=False), ros2 run, ros2 launch)."""
    if cls not in _LEAN_CLASSES:
        from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks

        def create_publisher(self, *args, event_callbacks=None, **kwargs):
            return cls.create_publisher(self, *args, event_callbacks=event_callbacks or PublisherEventCallbacks(
                use_default_callbacks=False), **kwargs)

        def create_subscription(self, *args, event_callbacks=None, **kwargs):
            return cls.create_subscription(self, *args, event_callbacks=event_callbacks or SubscriptionEventCallbacks(
                use_default_callbacks=False), **kwargs)

        _LEAN_CLASSES[cls] = type(f"Lean{cls.__name__}", (cls,), {
            "create_publisher": create_publisher, "create_subscription": create_subscription,
            "__doc__": f"{cls.__name__} without default QoS event handlers (fpr_experiments.node_factory.lean_class)"})
    return _LEAN_CLASSES[cls]


def build_node(spec: NodeSpec, context, lean: bool = False) -> Node:
    """One node of ``spec`` in ``context`` (its parameters, name, namespace and remappings from its ros_args).

    ``lean`` (simulation runs): no parameter services (``ros2 param`` cannot reach the node; its parameters are the
    description's), no type-description service (Jazzy's ``~/get_type_description``, REP 2011: tools asking a node
    for its topics' type definitions; :data:`LEAN_ROS_ARGS`) and no default QoS event handlers (:func:`lean_class`):
    the executor's wait set shrinks from ~350 to ~70 entities for n = 3 (see docs/benchmarks.md)."""
    cls = node_class(spec.executable)
    if lean:
        node = lean_class(cls)(context=context, cli_args=[*spec.ros_args(), *LEAN_ROS_ARGS],
                               use_global_arguments=False, start_parameter_services=False)
    else:
        node = cls(context=context, cli_args=spec.ros_args(), use_global_arguments=False)
    # rclpy ignores an override of a parameter the node does not declare: a misspelt one would fly unnoticed
    unknown = sorted(name for name in spec.parameters if not node.has_parameter(name))
    if unknown:
        node.destroy_node()
        raise ValueError(f"{spec.fully_qualified_name} ({spec.package} {spec.executable}): no parameter named "
                         f"{', '.join(unknown)}")
    return node


def build_nodes(specs: Sequence[NodeSpec], context, lean: bool = False) -> list[Node]:
    """All nodes of ``specs`` in order; on a failure the ones already built are destroyed, then it raises."""
    nodes: list[Node] = []
    try:
        for spec in specs:
            nodes.append(build_node(spec, context, lean))
    except BaseException:
        for node in reversed(nodes):
            try:
                node.destroy_node()
            except Exception:  # noqa: BLE001 - best effort before re-raising the real error
                pass
        raise
    return nodes
