"""SROS2 access-control policy of the robot's node graph (issue 12), generated from the graph itself.

The PyPI Jazzy wheels' Fast DDS is built without DDS-Security, so the policy cannot be enforced here; it is
written here and enforced on a native Jazzy install (src/fpr_experiments/README.md, "Securing the ROS graph").

How it is made: :func:`introspect` starts every node of the ``real`` backend's graph (:mod:`fpr_experiments.graph`,
the description ``ros2 launch`` uses on the robot) in one process — bridges with their UDP ports only, no PX4
needed — and reads from rcl's graph what each node publishes, subscribes to, serves and calls, exactly as
``ros2 security generate_policy`` would from a running system. Topics the graph subscribes to and nobody in it
publishes are the robot's external inputs (camera drivers, motion capture, the joystick driver, a target source);
:data:`EXTERNAL_INPUTS` gives each one an enclave of its own, allowed to publish that input only. Every other
permission is exactly one node's endpoints: one enclave per node, path = the node's fully qualified name
(``--ros-args --enclave /fpr/uav1/controller``). So only the teleop may publish ``/fpr/teleop``, only UAV i's
controller its setpoint, only UAV i's bridge its status.

Limit: ``/fpr/info`` is one topic for every UAV's ζ (DESIGN.md §4); DDS permissions are per topic, so any of the n
controllers may publish on it. A UAV j's controller forging uav_id i is what the controllers' duplicate-publisher
check catches (two publishers of uav_id i: refused, said); SROS2 keeps everyone else out of the topic.

``ros2 run fpr_experiments security_policy [--n N] [--modes …] [--output FILE]`` writes the policy (sros2's policy
format, version 0.2.0: ``policy/enclaves/enclave[@path]/profiles/profile[@ns,@node]/topics|services``); the shipped
``config/sros2/fpr_n3.policy.xml`` is its output for n = 3, checked against a fresh generation by a test.
"""

from __future__ import annotations

import re
import time
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, field

__all__ = ["EXTERNAL_INPUTS", "MONITOR_ENCLAVE", "Endpoints", "introspect", "merge", "policy_enclaves", "policy_xml",
           "read_policy", "robot_graph", "robot_policy"]

#: the robot's inputs from outside the graph: topic pattern -> (enclave, what publishes it). ``{uav}`` in the
#: enclave takes the UAV number the pattern matched.
EXTERNAL_INPUTS: dict[str, tuple[str, str]] = {
    r"^/fpr/uav(?P<uav>\d+)/camera/(image_raw|camera_info)$":
        ("/fpr/uav{uav}/camera_driver", "UAV i's camera driver (image_raw + camera_info)"),
    r"^/fpr/motion_capture$": ("/fpr/ground/motion_capture", "the motion-capture bridge (centralized modes)"),
    r"^/fpr/target$": ("/fpr/ground/target_source", "an external target source for the teleop (optional)"),
    r"^/fpr/ground/joy$": ("/fpr/ground/joy_node", "a ROS joy driver (instead of fpr_control's joystick)"),
}
#: the read-only enclave of the ground's tools (Foxglove bridge, rqt, ``ros2 topic echo``, ``ros2 param get``): it
#: may subscribe to every topic and call the nodes' read-only parameter services, publish nothing but what every
#: rcl node does (its log, its parameter events)
MONITOR_ENCLAVE = "/fpr/ground/monitor"
READ_ONLY_PARAMETER_SERVICES = ("describe_parameters", "get_parameter_types", "get_parameters", "list_parameters",
                                "get_type_description")
#: topics every node may use whatever its role (rcl's own: logging, parameter events); time is not among them on
#: the robot (no /clock)
COMMON_PUBLISH = ("/rosout", "/parameter_events")
#: the modes whose endpoints the policy allows: the decentralized ones use the same topics as ``communicating``
#: (``non_communicating`` a subset), the centralized ones add the motion capture
DEFAULT_MODES = ("communicating", "centralized")


@dataclass
class Endpoints:
    """One enclave's permissions (fully qualified ROS names)."""

    enclave: str
    namespace: str
    node: str
    publish: set[str] = field(default_factory=set)
    subscribe: set[str] = field(default_factory=set)
    reply: set[str] = field(default_factory=set)     #: services it serves
    request: set[str] = field(default_factory=set)   #: services it calls
    external: str = ""                               #: an external input's description ("" for graph nodes)


def robot_graph(n: int = 3, mode: str = "communicating"):
    """The node specs the robot runs (backend ``real``, images, the joystick operator)."""
    from fpr_experiments.graph import GraphOptions, describe_graph

    return describe_graph(GraphOptions(n=n, mode=mode, backend="real", cameras="images", operator="joystick"))


def introspect(specs: Sequence, settle: float = 1.5, timeout: float = 30.0) -> list[Endpoints]:
    """Start ``specs``' nodes in this process (not spun: nothing runs, the endpoints exist) and read their
    endpoints from rcl's graph; waits until the graph has been stable for ``settle`` s."""
    import rclpy

    from fpr_experiments.node_factory import build_nodes

    context = rclpy.Context()
    rclpy.init(context=context, args=[])
    nodes = []
    try:
        nodes = build_nodes(specs, context)
        observer = rclpy.create_node("_fpr_policy_observer", context=context)
        try:
            def read() -> list[Endpoints]:
                out = []
                for spec in specs:
                    ns, name = spec.namespace or "/", spec.name
                    e = Endpoints(spec.fully_qualified_name, ns, name)
                    e.publish = {t for t, _ in observer.get_publisher_names_and_types_by_node(name, ns)}
                    e.subscribe = {t for t, _ in observer.get_subscriber_names_and_types_by_node(name, ns)}
                    e.reply = {s for s, _ in observer.get_service_names_and_types_by_node(name, ns)}
                    e.request = {s for s, _ in observer.get_client_names_and_types_by_node(name, ns)}
                    out.append(e)
                return out

            deadline = time.monotonic() + timeout
            last, stable_since = None, time.monotonic()
            while True:
                current = read()
                key = [(e.enclave, sorted(e.publish), sorted(e.subscribe), sorted(e.reply), sorted(e.request))
                       for e in current]
                now = time.monotonic()
                if key != last:
                    last, stable_since = key, now
                elif now - stable_since >= settle and all(e.publish for e in current):
                    return current
                if now > deadline:
                    raise TimeoutError(f"the graph's endpoints did not settle within {timeout:g} s")
                time.sleep(0.1)
        finally:
            observer.destroy_node()
    finally:
        for node in nodes:
            node.destroy_node()
        context.try_shutdown()


def merge(*graphs: Sequence[Endpoints]) -> list[Endpoints]:
    """The union, enclave by enclave, of the endpoints of several introspections (e.g. one per controller mode)."""
    out: dict[str, Endpoints] = {}
    for graph in graphs:
        for e in graph:
            into = out.setdefault(e.enclave, Endpoints(e.enclave, e.namespace, e.node))
            into.publish |= e.publish
            into.subscribe |= e.subscribe
            into.reply |= e.reply
            into.request |= e.request
    return list(out.values())


def robot_policy(n: int = 3, modes: Sequence[str] = DEFAULT_MODES) -> tuple[list[Endpoints], str]:
    """The robot's enclaves for every mode in ``modes`` and the policy's XML text."""
    enclaves = policy_enclaves(merge(*(introspect(robot_graph(n, mode)) for mode in modes)))
    # (an XML comment may not hold "--": the options in words)
    command = f"ros2 run fpr_experiments security_policy, n = {n}, modes {', '.join(modes)}"
    return enclaves, policy_xml(enclaves, comment=f"generated by {command}; do not edit by hand")


def policy_enclaves(nodes: Sequence[Endpoints]) -> list[Endpoints]:
    """``nodes`` plus one enclave per external input (:data:`EXTERNAL_INPUTS`); ValueError names an input that
    no pattern covers (a new subscription nobody publishes: decide who may)."""
    published = set().union(*(e.publish for e in nodes))
    inputs = sorted(set().union(*(e.subscribe for e in nodes)) - published)
    external: dict[str, Endpoints] = {}
    unknown = []
    for topic in inputs:
        for pattern, (enclave, description) in EXTERNAL_INPUTS.items():
            match = re.match(pattern, topic)
            if match:
                path = enclave.format(**match.groupdict())
                namespace, _, node = path.rpartition("/")
                e = external.setdefault(path, Endpoints(path, namespace or "/", node, external=description))
                e.publish |= {topic, *COMMON_PUBLISH}
                break
        else:
            unknown.append(topic)
    if unknown:
        raise ValueError(f"subscribed but published by no node of the graph and by no known external input: "
                         f"{unknown} (add them to fpr_experiments.security.EXTERNAL_INPUTS)")
    enclaves = [*nodes, *sorted(external.values(), key=lambda e: e.enclave)]
    monitor = Endpoints(MONITOR_ENCLAVE, "/fpr/ground", "monitor", external="read-only tools on the ground "
                        "(Foxglove bridge, rqt, ros2 topic echo, ros2 param get): subscribe to all, set nothing")
    monitor.publish = set(COMMON_PUBLISH)  # every rcl node creates these two publishers
    monitor.subscribe = set().union(*(e.publish for e in enclaves))
    monitor.request = {s for e in nodes for s in e.reply if s.rsplit("/", 1)[-1] in READ_ONLY_PARAMETER_SERVICES}
    return [*enclaves, monitor]


def policy_xml(enclaves: Sequence[Endpoints], comment: str = "") -> str:
    """The sros2 policy (format 0.2.0) of ``enclaves``, deterministic (sorted names)."""
    root = ET.Element("policy", version="0.2.0")
    if comment:
        root.append(ET.Comment(f" {comment} "))
    container = ET.SubElement(root, "enclaves")
    for e in enclaves:
        if e.external:
            container.append(ET.Comment(f" external input: {e.external} "))
        enclave = ET.SubElement(container, "enclave", path=e.enclave)
        profile = ET.SubElement(ET.SubElement(enclave, "profiles"), "profile", ns=e.namespace, node=e.node)
        for tag, item, attribute, names in (("topics", "topic", "publish", e.publish),
                                            ("topics", "topic", "subscribe", e.subscribe),
                                            ("services", "service", "reply", e.reply),
                                            ("services", "service", "request", e.request)):
            if names:
                group = ET.SubElement(profile, tag, {attribute: "ALLOW"})
                for name in sorted(names):
                    ET.SubElement(group, item).text = name
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def read_policy(text: str) -> dict[str, dict[str, set[str]]]:
    """enclave path -> {"publish"|"subscribe"|"reply"|"request": names} of a policy's XML text."""
    out: dict[str, dict[str, set[str]]] = {}
    for enclave in ET.fromstring(text).iter("enclave"):
        rules = out.setdefault(enclave.get("path"), {k: set() for k in ("publish", "subscribe", "reply", "request")})
        for group in enclave.iter():
            for attribute in rules:
                if group.get(attribute) == "ALLOW":
                    rules[attribute] |= {child.text for child in group}
    return out


def main(argv: list[str] | None = None) -> int:
    """``ros2 run fpr_experiments security_policy``: the robot's SROS2 policy (module doc)."""
    import argparse
    import sys

    from fpr_experiments.graph import MODES

    parser = argparse.ArgumentParser(prog="ros2 run fpr_experiments security_policy",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=3, help="number of UAVs")
    parser.add_argument("--modes", nargs="+", default=list(DEFAULT_MODES), choices=MODES,
                        help="controller modes the robot may fly (the policy allows the union of their endpoints)")
    parser.add_argument("--output", default="", help="write here (default: standard output)")
    args = parser.parse_args(argv)
    try:
        enclaves, text = robot_policy(args.n, args.modes)
    except (ValueError, TimeoutError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    if args.output:
        with open(args.output, "w", encoding="utf-8") as stream:
            stream.write(text)
        print(f"wrote {args.output}: {len(enclaves)} enclaves", file=sys.stderr)
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(main())
