"""Benchmarks of fpr_px4_bridge (run under network isolation):

    bash scripts/isolated.sh python benchmarks/bench_px4_bridge.py

1. encode + send of one SET_ATTITUDE_TARGET (validation, (C.1)-(C.2) thrust, ENU/FLU -> NED/FRD, pack, sendto),
   through Px4Bridge.submit_setpoint, on loopback UDP.
2. ROS setpoint -> datagram on the wire: an AttitudeThrustSetpoint published in one process (rclpy), the
   px4_bridge node in the same process (its own executor thread), a fake PX4 socket timing the arrival of the
   matching SET_ATTITUDE_TARGET. p50 / p99 over N samples.
3. SET_ATTITUDE_TARGET stream at the peer: the px4_bridge node (wall clock, its own executor thread) gets
   setpoints from a 50 Hz ROS timer in another executor thread (as the controller publishes them) for
   ``--stream-seconds`` (20 s) per phase; a pymavlink/UDP peer on 127.0.0.1 (its own thread) timestamps every
   frame. Reported: the rate at the peer (target 50 +- 1 Hz), the interval histogram (p50, p99, max gap;
   target p99 <= 25 ms on an idle machine), duplicated frames (a frame carrying the same setpoint as the frame
   before it: same time_boot_ms and thrust; every published setpoint has a thrust of its own) and the delay
   publish -> first frame of that setpoint on the wire. Two phases of the controller's timer against the
   bridge's stream timer: mid-period (+10 ms) and in phase (+0.5 ms, the worst case for any rate limiter).
"""

from __future__ import annotations

import argparse
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




def _free_port() -> int:
    """A UDP port on 127.0.0.1 that is free now (for the bridge's connection_url)."""
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    return port

def _receive_frame(sock, parser, clock):
    """One datagram from ``sock``: (arrival time on ``clock``, decoded message or None if undecodable); None on a
    socket timeout."""
    try:
        data = sock.recv(65535)
    except TimeoutError:
        return None
    arrival = clock()
    try:
        return arrival, parser.decode(bytearray(data))
    except Exception:  # noqa: BLE001 - a bad frame is counted as no message
        return arrival, None

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

    port = _free_port()
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
            received = _receive_frame(sock, parser, time.perf_counter)
            if received is None:
                break
            t_rx, m = received
            if m is not None and m.get_type() == "SET_ATTITUDE_TARGET" and abs(m.thrust - expected) < 1e-6:
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


def _stream_timer(node):
    """The px4_bridge node's stream timer (period 1 / stream_rate)."""
    period_ns = int(round(1e9 / node.config.stream_rate))
    return min(node.timers, key=lambda timer: abs(timer.timer_period_ns - period_ns))


def bench_stream(seconds=20.0, phase=0.010, rate=50.0):
    """Rate, intervals and duplicates of the SET_ATTITUDE_TARGET stream at a UDP peer (module doc, 3.)."""
    import rclpy
    from fpr_px4_bridge.px4_bridge_node import Px4BridgeNode
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from fpr_msgs.msg import AttitudeThrustSetpoint

    port = _free_port()
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Px4BridgeNode(context=context, namespace="/fpr/uav1", parameter_overrides=[
        Parameter("connection_url", value=f"udp://127.0.0.1:{port}"), Parameter("stream_rate", value=rate)])
    helper = rclpy.create_node("bench_controller", context=context)
    executors = [SingleThreadedExecutor(context=context), SingleThreadedExecutor(context=context)]
    executors[0].add_node(node)
    executors[1].add_node(helper)
    pub = helper.create_publisher(AttitudeThrustSetpoint, "/fpr/uav1/setpoint",
                                  QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT))
    sock, heartbeat = fake_peer(("127.0.0.1", port))
    sock.settimeout(0.05)
    frames: list[tuple[float, int, float]] = []  # (arrival monotonic [s], time_boot_ms, thrust)
    ticks: list[float] = []  # the bridge's stream ticks and setpoint arrivals (its clock [s]), observed only
    arrivals: list[float] = []
    tick, submit = node.bridge.tick, node.bridge.submit_setpoint

    def observed_tick(now):
        ticks.append(now)
        return tick(now)

    def observed_submit(*args, **kwargs):
        arrivals.append(args[3])
        return submit(*args, **kwargs)

    node.bridge.tick, node.bridge.submit_setpoint = observed_tick, observed_submit
    running = threading.Event()
    running.set()

    def peer() -> None:
        parser = mavlink.MAVLink(None)
        next_heartbeat = 0.0
        while running.is_set():
            now = time.monotonic()
            if now >= next_heartbeat:  # 10 Hz HEARTBEAT (the bridge's silence rule: any frame within 0.5 s)
                sock.sendto(heartbeat, ("127.0.0.1", port))
                next_heartbeat = now + 0.1
            received = _receive_frame(sock, parser, time.monotonic)
            if received is None:
                continue
            t_rx, m = received
            if m is not None and m.get_type() == "SET_ATTITUDE_TARGET":
                frames.append((t_rx, m.time_boot_ms, m.thrust))

    threads = [threading.Thread(target=peer, daemon=True)]
    threads += [threading.Thread(target=e.spin, daemon=True) for e in executors]
    for thread in threads:
        thread.start()
    end = time.monotonic() + 5.0
    while (pub.get_subscription_count() == 0 or node.link.peer is None) and time.monotonic() < end:
        time.sleep(0.01)
    with node._lock:
        node.bridge.on_teleop(TeleopMode.ARM, node._now())  # the peer reports armed: WARMUP streams
    published: dict[float, float] = {}  # normalized thrust -> publish time (monotonic)
    count = [0]

    def publish() -> None:
        k = count[0]
        count[0] += 1
        thrust_newton = 5.0 + 0.001 * (k % 5000)
        msg = AttitudeThrustSetpoint()
        msg.header.stamp = helper.get_clock().now().to_msg()
        msg.uav_id = 1
        msg.attitude.w, msg.attitude.x, msg.attitude.y, msg.attitude.z = Q_NORTH
        msg.thrust = thrust_newton
        published[round(node.bridge.normalized_thrust(thrust_newton, 0.0), 6)] = time.monotonic()
        pub.publish(msg)

    # the controller's timer: created `phase` s after a tick of the bridge's stream timer (rclpy timers keep the
    # phase of their creation)
    time.sleep(_stream_timer(node).time_until_next_call() * 1e-9 + phase)
    helper.create_timer(1.0 / 50.0, publish)
    start = time.monotonic()
    time.sleep(seconds + 1.0)
    running.clear()
    for executor in executors:
        executor.shutdown()
    for thread in threads:
        thread.join(timeout=2.0)
    node.destroy_node()
    helper.destroy_node()
    rclpy.shutdown(context=context)
    sock.close()
    window = [f for f in frames if start + 0.5 <= f[0] <= start + 0.5 + seconds]  # steady state
    times = [f[0] for f in window]
    gaps = [(b - a) * 1e3 for a, b in zip(times, times[1:], strict=False)]
    duplicates = sum(1 for a, b in zip(window, window[1:], strict=False) if (a[1], a[2]) == (b[1], b[2]))
    delays = []
    seen = set()
    for t_rx, _, thrust in window:
        key = round(thrust, 6)
        if key in published and key not in seen:
            seen.add(key)
            delays.append((t_rx - published[key]) * 1e3)
    measured = (len(times) - 1) / (times[-1] - times[0])
    # where the setpoints land in the stream period: arrival − the last tick before it, at the bridge
    offsets = []
    i = 0
    for arrival in arrivals:
        while i + 1 < len(ticks) and ticks[i + 1] <= arrival:
            i += 1
        if ticks and ticks[i] <= arrival:
            offsets.append((arrival - ticks[i]) * 1e3)
    print(f"stream at the peer, controller timer +{phase * 1e3:.1f} ms after the stream timer (setpoints arrive "
          f"{percentile(offsets, 50):.1f} ms after a tick, p1-p99 {percentile(offsets, 1):.1f}-"
          f"{percentile(offsets, 99):.1f} ms; {seconds:.0f} s, "
          f"{len(window)} frames): rate {measured:.2f} Hz (target {rate:.0f} +- 1), intervals p50 "
          f"{percentile(gaps, 50):.2f} ms, p99 {percentile(gaps, 99):.2f} ms, max gap {max(gaps):.2f} ms, "
          f"min {min(gaps):.2f} ms; duplicated frames {duplicates}; publish -> wire p50 "
          f"{percentile(delays, 50):.2f} ms, p99 {percentile(delays, 99):.2f} ms, max {max(delays):.2f} ms "
          f"({len(delays)} setpoints)")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", choices=("encode", "latency", "stream"), help="run one benchmark")
    parser.add_argument("--stream-seconds", type=float, default=20.0, help="[s] stream measured per phase")
    args = parser.parse_args()
    if args.only in (None, "encode"):
        bench_encode_send()
    if args.only in (None, "latency"):
        bench_ros_latency()
    if args.only in (None, "stream"):
        for offset in (0.010, 0.0005):
            bench_stream(args.stream_seconds, offset)
