"""Does a publisher's ``publish()`` block when a matched subscriber's process dies or hangs? (Fast DDS, rclpy)

A finding of the fault matrix (docs/safety.md, px4_bridge dead, seed 1): the simulator sent no MAVLink frame for
0.8 s of wall time right at the kill of a node process. This script isolates the middleware's part: a subscriber
process is SIGKILLed (``kill``) or SIGSTOPped (``hang``, a frozen process: its DDS threads stop too) 2 s into a
1 kHz stream, and the slowest ``publish()`` calls of the 4 s after are listed, per trial.

    bash scripts/isolated.sh python benchmarks/dds_hung_subscriber.py --mode hang --type bounded --trials 8

``--type bounded`` publishes std_msgs/Float64 (a fixed-size type), ``unbounded`` std_msgs/Float64MultiArray.
Run it alone (it measures wall time), under scripts/isolated.sh like every ROS run. UDP only, no shared memory
(inside the isolated namespace, where SUBNET is this machine's loopback):

    bash scripts/isolated.sh env ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET FASTDDS_BUILTIN_TRANSPORTS=UDPv4 \
        python benchmarks/dds_hung_subscriber.py --trials 10
"""

from __future__ import annotations

import argparse
import signal
import subprocess
import sys
import time

STREAM_S, FAULT_AT_S = 6.0, 2.0


def _qos(reliability: str):
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    return QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE if reliability == "reliable"
                      else ReliabilityPolicy.BEST_EFFORT)


def _message_type(kind: str):
    from std_msgs.msg import Float64, Float64MultiArray

    return Float64 if kind == "bounded" else Float64MultiArray


def subscriber(kind: str, reliability: str) -> None:
    import rclpy
    from rclpy.node import Node

    rclpy.init()
    node = Node("dds_hung_subscriber_victim")
    node.create_subscription(_message_type(kind), "/dds_hung_subscriber", lambda _: None, _qos(reliability))
    print("READY", flush=True)
    rclpy.spin(node)


def trial(mode: str, kind: str, reliability: str) -> list[tuple[float, float]]:
    """The five slowest publish() calls [(ms, s since the stream's start)] of one trial."""
    import rclpy
    from rclpy.node import Node

    victim = subprocess.Popen([sys.executable, __file__, "--subscriber", "--type", kind, "--reliability",
                               reliability], stdout=subprocess.PIPE, text=True)
    victim.stdout.readline()
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node("dds_hung_subscriber_publisher", context=context)
    try:
        publisher = node.create_publisher(_message_type(kind), "/dds_hung_subscriber", _qos(reliability))
        deadline = time.monotonic() + 30.0
        while publisher.get_subscription_count() == 0:
            if victim.poll() is not None or time.monotonic() > deadline:
                raise SystemExit("dds_hung_subscriber: the subscriber process did not come up or was not discovered "
                                 "within 30 s (run it under scripts/isolated.sh)")
            time.sleep(0.05)
        message = _message_type(kind)()
        if kind != "bounded":
            message.data = [0.0] * 20
        start, faulted, calls = time.monotonic(), False, []
        while time.monotonic() - start < STREAM_S:
            if not faulted and time.monotonic() - start > FAULT_AT_S:
                victim.send_signal(signal.SIGKILL if mode == "kill" else signal.SIGSTOP)
                faulted = True
            before = time.monotonic()
            publisher.publish(message)
            calls.append((1e3 * (time.monotonic() - before), before - start))
            time.sleep(0.001)
        return sorted(calls, reverse=True)[:5]
    finally:
        victim.kill()
        victim.wait()
        node.destroy_node()
        rclpy.shutdown(context=context)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mode", choices=("kill", "hang"), default="hang")
    parser.add_argument("--type", choices=("bounded", "unbounded"), default="bounded")
    parser.add_argument("--reliability", choices=("reliable", "best_effort"), default="best_effort")
    parser.add_argument("--trials", type=int, default=8)
    parser.add_argument("--subscriber", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.subscriber:
        subscriber(args.type, args.reliability)
        return
    blocked = 0
    for k in range(args.trials):
        slowest = trial(args.mode, args.type, args.reliability)
        blocked += slowest[0][0] > 100.0
        print(f"trial {k + 1}: slowest publish() calls [ms at s]: "
              + ", ".join(f"{ms:.1f} at {at:.3f}" for ms, at in slowest), flush=True)
    print(f"{args.mode}, {args.type}, {args.reliability}: a publish() blocked > 100 ms in {blocked} of {args.trials} "
          f"trials (the subscriber {'SIGKILLed' if args.mode == 'kill' else 'SIGSTOPped'} at {FAULT_AT_S:g} s)")


if __name__ == "__main__":
    main()
