"""node_group: the nodes of ONE process group of a graph description in one process and one executor, as on
the robot's companion computers (``uav<i>``: bridge, detector, estimator, controller) and ground station
(``ground``: teleop + operator). The multi-process runner starts one per group::

    ros2 run fpr_experiments node_group --graph reports/<experiment>/<variant>/graph.json --group uav1

``graph.json`` is the description written by :func:`fpr_experiments.graph.write_graph_file`; every node gets its
spec's ``--ros-args`` (rcl's parameter files and overrides). Prints ``READY <group> <n> nodes`` on stdout once
the nodes exist; SIGINT / SIGTERM stop it cleanly. A wrong group or file: one line on stderr, exit status 2.
"""

from __future__ import annotations

import argparse
import signal
import sys

from fpr_experiments.graph import groups, read_graph_file


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="node_group", description=__doc__.split("\n\n")[0])
    parser.add_argument("--graph", required=True, help="graph.json (fpr_experiments.graph.write_graph_file)")
    parser.add_argument("--group", required=True, help="process group: uav<i>, ground, link, simulator")
    parser.add_argument("--lean", action="store_true",
                        help="no parameter services / default QoS event handlers (simulation runs, node_factory)")
    args, _ros_args = parser.parse_known_args(argv)
    try:
        specs = groups(read_graph_file(args.graph))
    except (OSError, ValueError, KeyError) as error:
        print(f"node_group: cannot read {args.graph}: {error}", file=sys.stderr)
        return 2
    if args.group not in specs:
        print(f"node_group: no group '{args.group}' in {args.graph}; groups: {', '.join(specs)}", file=sys.stderr)
        return 2

    import rclpy
    from fpr_model.node_parameters import settle_heap
    from rclpy.executors import SingleThreadedExecutor

    from fpr_experiments.node_factory import build_nodes

    context = rclpy.Context()
    rclpy.init(context=context, args=[])
    nodes = build_nodes(specs[args.group], context, lean=args.lean)
    settle_heap()  # no garbage-collector pause walks the start-up's objects (fpr_model.node_parameters)
    executor = SingleThreadedExecutor(context=context)
    for node in nodes:
        executor.add_node(node)
    running = True

    def stop(*_) -> None:
        nonlocal running
        running = False

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    print(f"READY {args.group} {len(nodes)} nodes", flush=True)
    try:
        while running and context.ok():
            try:
                executor.spin_once(timeout_sec=0.05)
            except Exception as error:  # noqa: BLE001 - one failing callback must not take the group down
                if not running or not context.ok():
                    break
                print(f"CALLBACK_ERROR {args.group}: {error!r}", file=sys.stderr, flush=True)
    finally:
        executor.shutdown(timeout_sec=1.0)
        for node in nodes:
            try:
                node.destroy_node()
            except Exception:  # noqa: BLE001 - best effort at exit
                pass
        context.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
