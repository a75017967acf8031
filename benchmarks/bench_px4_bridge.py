"""Benchmarks of fpr_px4_bridge (run under network isolation):

    bash scripts/isolated.sh python benchmarks/bench_px4_bridge.py

1. encode + send of one SET_ATTITUDE_TARGET (validation, (C.1)-(C.2) thrust, ENU/FLU -> NED/FRD, pack, sendto),
   through Px4Bridge.submit_setpoint, on loopback UDP.
2. ROS setpoint -> datagram on the wire: an AttitudeThrustSetpoint published in one process (rclpy), the
   px4_bridge node in the same process (its own executor thread), a fake PX4 socket timing the arrival of the
   matching SET_ATTITUDE_TARGET. p50 / p99 over N samples.
"""

from __future__ import annotations

import math
import os
import socket
import statistics
import sys
import threading
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
for package in ("fpr_px4_bridge", "fpr_model"):
    sys.path.insert(0, os.path.join(ROOT, "src", package))

from fpr_px4_bridge.bridge import BridgeConfig, Px4Bridge  # noqa: E402
from fpr_px4_bridge.link import MavlinkLink  # noqa: E402
from fpr_px4_bridge.offboard import TeleopMode  # noqa: E402

from fpr_px4_bridge import px4_protocol as p  # noqa: E402

mavlink = p.import_mavlink()
Q_NORTH = (math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4))
ARMED = p.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | p.MAV_MODE_FLAG_SAFETY_ARMED


def percentile(values, q):
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(round(q / 100.0 * (len(ordered) - 1))))]


def fake_peer(address):
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    heartbeat = mav.heartbeat_encode(type=2, autopilot=12, base_mode=ARMED, custom_mode=393216 >> 0,
                                     system_status=4).pack(mav)
    sock.sendto(heartbeat, address)
    return sock, heartbeat


def bench_encode_send(n=20000):
    link = MavlinkLink("udp://127.0.0.1:0", system_id=1, target_system=1)
    bridge = Px4Bridge(BridgeConfig(uav_id=1), link)
    sock, heartbeat = fake_peer(link.local_address)
    bridge.poll(0.0, timeout=1.0)
    bridge.on_teleop(TeleopMode.ARM, 0.0)
    bridge.tick(0.0)
    mav = link.mav
    # encode only
    t0 = time.perf_counter()
    for k in range(n):
        p.encode_set_attitude_target(mav, k, 1, 1, Q_NORTH, 0.4).pack(mav)
    encode_us = (time.perf_counter() - t0) / n * 1e6
    # full path: validate + normalize + convert + pack + sendto (peer drains in between)
    samples = []
    for k in range(n):
        t = time.perf_counter()
        bridge.submit_setpoint(Q_NORTH, 10.0, 1, 0.001 * k)
        samples.append((time.perf_counter() - t) * 1e6)
        if k % 200 == 0:
            sock.setblocking(False)
            try:
                while True:
                    sock.recv(65535)
            except BlockingIOError:
                pass
    link.close()
    sock.close()
    print(f"encode only (frames + pack):         {encode_us:8.1f} us/setpoint")
    print(f"submit_setpoint (encode + send):     mean {statistics.fmean(samples):6.1f} us, "
          f"p50 {percentile(samples, 50):6.1f} us, p99 {percentile(samples, 99):6.1f} us  (n={n})")
    print(f"  budget share at 50 Hz: {statistics.fmean(samples) * 50 / 1e6 * 100:.3f} % of one core")


def bench_ros_latency(n=1000):
    import rclpy
    from fpr_px4_bridge.px4_bridge_node import Px4BridgeNode
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from fpr_msgs.msg import AttitudeThrustSetpoint

    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Px4BridgeNode(context=context, namespace="/fpr/uav1", parameter_overrides=[
        Parameter("connection_url", value=f"udp://127.0.0.1:{port}"),
        Parameter("setpoint_timeout", value=5.0)])
    helper = rclpy.create_node("bench_helper", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    pub = helper.create_publisher(AttitudeThrustSetpoint, "/fpr/uav1/setpoint",
                                  QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT))
    sock, heartbeat = fake_peer(("127.0.0.1", port))
    sock.settimeout(0.5)
    end = time.monotonic() + 5.0
    while pub.get_subscription_count() == 0 and time.monotonic() < end:
        time.sleep(0.01)
    with node._lock:
        node.bridge.on_teleop(TeleopMode.ARM, node._now())
    parser = mavlink.MAVLink(None)
    latencies = []
    lost = 0
    for k in range(n + 50):
        if k % 20 == 0:
            sock.sendto(heartbeat, ("127.0.0.1", port))
        thrust_newton = 5.0 + 0.01 * (k % 1000)
        expected = node.bridge.normalized_thrust(thrust_newton, node._now())
        msg = AttitudeThrustSetpoint()
        msg.uav_id = 1
        msg.attitude.w, msg.attitude.x, msg.attitude.y, msg.attitude.z = Q_NORTH
        msg.thrust = thrust_newton
        t_pub = time.perf_counter()
        pub.publish(msg)
        got = None
        deadline = t_pub + 0.5
        while time.perf_counter() < deadline:
            try:
                data = sock.recv(65535)
            except TimeoutError:
                break
            t_rx = time.perf_counter()
            try:
                m = parser.decode(bytearray(data))
            except Exception:  # noqa: BLE001
                continue
            if m.get_type() == "SET_ATTITUDE_TARGET" and abs(m.thrust - expected) < 1e-6:
                got = t_rx
                break
        if got is None:
            lost += 1
        elif k >= 50:  # warm-up
            latencies.append((got - t_pub) * 1e3)
        time.sleep(0.01)
    executor.shutdown()
    node.destroy_node()
    helper.destroy_node()
    rclpy.shutdown(context=context)
    sock.close()
    print(f"ROS setpoint -> datagram on the wire: p50 {percentile(latencies, 50):.3f} ms, "
          f"p99 {percentile(latencies, 99):.3f} ms, max {max(latencies):.3f} ms "
          f"(n={len(latencies)}, lost {lost}; target p99 <= 2 ms)")


if __name__ == "__main__":
    bench_encode_send()
    bench_ros_latency()
