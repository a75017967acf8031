"""Process entry points of the simulated swarm run as SEPARATE processes (DESIGN.md §7): one process per UAV with
its on-board nodes in one executor (as on its companion computer), one ground-station process (teleop +
joy_script). The simulator is its own process: ``ros2 run fpr_sim simulator`` (see :func:`simulator_command`).

    python tests/swarm_processes.py uav 1 --n 3 --mode communicating
    python tests/swarm_processes.py ground --n 3 --script integration_hover.yaml

Each prints ``READY`` on stdout once its nodes exist, and shuts down cleanly on SIGINT / SIGTERM. Parameters
come from the packages' config YAMLs exactly as in the one-process graph (:mod:`swarm_graph`).
"""

from __future__ import annotations

import argparse
import os
import signal
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import rclpy  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from swarm_graph import (  # noqa: E402
    SwarmOptions,
    _resolve,
    build_ground_nodes,
    build_uav_nodes,
    config_path,
)


def simulator_command(scenario: str, real_time_factor: float, duration: float,
                      emulated_cameras: bool = True) -> list[str]:
    """``ros2 run fpr_sim simulator`` with its config YAML and the run's values."""
    return ["ros2", "run", "fpr_sim", "simulator", "--ros-args",
            "--params-file", config_path("fpr_sim", "simulator.yaml"),
            "-p", f"scenario_file:={_resolve(scenario, 'fpr_sim', 'scenarios')}",
            "-p", f"real_time_factor:={float(real_time_factor)}",
            "-p", f"duration:={float(duration)}",
            "-p", f"emulated_cameras:={'true' if emulated_cameras else 'false'}"]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="role", required=True)
    uav = sub.add_parser("uav", help="px4_bridge + pose_estimator + controller of one UAV")
    uav.add_argument("uav_id", type=int)
    uav.add_argument("--n", type=int, default=3)
    uav.add_argument("--mode", default="communicating")
    ground = sub.add_parser("ground", help="teleop + joy_script")
    ground.add_argument("--n", type=int, default=3)
    ground.add_argument("--script", default="takeoff_hover_land.yaml")
    args = parser.parse_args(argv)

    context = rclpy.Context()
    rclpy.init(context=context)
    if args.role == "uav":
        nodes = build_uav_nodes(context, SwarmOptions(controller_mode=args.mode), args.uav_id, args.n).nodes
    else:
        nodes = list(build_ground_nodes(context, SwarmOptions(joy_script=args.script), args.n))
    executor = SingleThreadedExecutor(context=context)
    for node in nodes:
        executor.add_node(node)
    running = True

    def stop(*_) -> None:
        nonlocal running
        running = False

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    print("READY", flush=True)
    try:
        while running and context.ok():
            executor.spin_once(timeout_sec=0.05)
    finally:
        executor.shutdown(timeout_sec=1.0)
        for node in nodes:
            node.destroy_node()
        context.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
