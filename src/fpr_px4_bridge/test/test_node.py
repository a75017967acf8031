"""px4_bridge node in process (real rclpy) against a fake PX4 on 127.0.0.1: the issue's acceptance at the peer."""

import math
import threading
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
from fpr_px4_bridge.px4_bridge_node import Px4BridgeNode  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import Imu  # noqa: E402

from fpr_msgs.msg import AttitudeThrustSetpoint, TeleopCommand, UavStatus  # noqa: E402

Q_NORTH = (math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4))  # w, x, y, z
SETPOINT_TIMEOUT = 0.2
STREAM_RATE = 50.0


def wait_for(predicate, timeout=5.0, step=0.01):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(step)
    return predicate()


@pytest.fixture
def graph(fake_px4_factory, free_port):
    context = rclpy.Context()
    rclpy.init(context=context)
    port = free_port
    node = Px4BridgeNode(context=context, namespace="/fpr/uav1", parameter_overrides=[
        Parameter("uav_id", value=1),
        Parameter("connection_url", value=f"udp://127.0.0.1:{port}"),
        Parameter("setpoint_timeout", value=SETPOINT_TIMEOUT),
        Parameter("stream_rate", value=STREAM_RATE),
        Parameter("offboard_warmup", value=1.0),
        Parameter("status_rate", value=20.0),
    ])
    helper = rclpy.create_node("px4_bridge_test_helper", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.add_node(helper)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    fake = fake_px4_factory(("127.0.0.1", port)).start()
    qos = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
    setpoint_pub = helper.create_publisher(AttitudeThrustSetpoint, "/fpr/uav1/setpoint", qos)
    teleop_pub = helper.create_publisher(TeleopCommand, "/fpr/teleop", qos)
    statuses, imus = [], []
    helper.create_subscription(UavStatus, "/fpr/uav1/status", statuses.append, 10)
    helper.create_subscription(Imu, "/fpr/uav1/imu", imus.append, qos)
    assert wait_for(lambda: setpoint_pub.get_subscription_count() > 0 and teleop_pub.get_subscription_count() > 0
                    and len(statuses) > 0)
    yield node, fake, setpoint_pub, teleop_pub, statuses, imus
    executor.shutdown()
    node.destroy_node()
    helper.destroy_node()
    rclpy.shutdown(context=context)
    spinner.join(timeout=2.0)


def setpoint(q=Q_NORTH, thrust=10.0, uav_id=1):
    msg = AttitudeThrustSetpoint()
    msg.uav_id = uav_id
    msg.attitude.w, msg.attitude.x, msg.attitude.y, msg.attitude.z = q
    msg.thrust = thrust
    return msg


def teleop(mode):
    msg = TeleopCommand()
    msg.mode = mode
    return msg


def test_fly_stream_rate_offboard_after_warmup_and_stale_stop(graph):
    node, fake, setpoint_pub, teleop_pub, statuses, imus = graph
    assert wait_for(lambda: statuses and statuses[-1].connected)
    teleop_pub.publish(teleop(TeleopCommand.MODE_FLY))
    assert wait_for(lambda: fake.armed, timeout=5.0)
    # the controller publishes at 50 Hz for 2.5 s
    end = time.monotonic() + 2.5
    while time.monotonic() < end:
        setpoint_pub.publish(setpoint())
        time.sleep(0.02)
    last_publish = time.monotonic()
    assert wait_for(lambda: statuses[-1].offboard and statuses[-1].state == UavStatus.STATE_OFFBOARD, 3.0)
    time.sleep(SETPOINT_TIMEOUT + 0.5)
    times = np.array(fake.setpoint_times())
    # >= 50 Hz at the peer over the whole stream
    span = times[-1] - times[0]
    assert len(times) - 1 >= STREAM_RATE * span, (len(times), span)
    # OFFBOARD requested only after >= 1 s of stream
    set_modes = [c for c in fake.command_list() if c.msg.command == 176 and int(c.msg.param2) == 6]
    assert set_modes and set_modes[0].t - times[0] >= 1.0
    # stale setpoints: the stream stops within setpoint_timeout + one period of the last forwarded setpoint
    forwarded = times[times <= last_publish + 0.005]
    assert times[-1] - forwarded[-1] <= SETPOINT_TIMEOUT + 1.0 / STREAM_RATE
    assert wait_for(lambda: statuses[-1].failsafe and statuses[-1].state == UavStatus.STATE_FAILSAFE, 2.0)
    # wire content: level, facing north -> identity in NED/FRD; thrust normalized with the 12.0 V telemetry
    with fake.lock:
        last = fake.setpoints[-1].msg
    np.testing.assert_allclose(last.q, [1.0, 0.0, 0.0, 0.0], atol=1e-6)
    assert last.thrust == pytest.approx(10.0 / 34.58, abs=1e-5)
    assert statuses[-1].setpoint_rate < STREAM_RATE  # stopped
    # telemetry made it to ROS in ENU/FLU
    assert imus and imus[-1].linear_acceleration.z == pytest.approx(9.81, abs=1e-5)
    assert imus[-1].orientation.z == pytest.approx(math.sin(math.pi / 4), abs=1e-6)


def test_bad_setpoints_never_reach_the_peer_and_garbage_is_counted(graph, corrupt_datagrams):
    node, fake, setpoint_pub, teleop_pub, statuses, imus = graph
    assert wait_for(lambda: statuses and statuses[-1].connected)
    teleop_pub.publish(teleop(TeleopCommand.MODE_ARM))
    assert wait_for(lambda: fake.armed)
    for bad in (setpoint(q=(math.nan, 0.0, 0.0, 1.0)), setpoint(q=(0.5, 0.0, 0.0, 0.5)),
                setpoint(thrust=math.inf), setpoint(uav_id=2)):
        setpoint_pub.publish(bad)
    assert wait_for(lambda: statuses[-1].rejected_setpoints == 4)
    assert fake.setpoint_times() == []
    # streaming continues while 10,000 corrupted datagrams hit the bridge's socket
    stop = threading.Event()

    def controller():
        while not stop.is_set():
            setpoint_pub.publish(setpoint())
            time.sleep(0.02)

    thread = threading.Thread(target=controller, daemon=True)
    thread.start()
    try:
        assert wait_for(lambda: len(fake.setpoint_times()) > 10)
        for i, data in enumerate(corrupt_datagrams(10_000, seed=5)):
            fake.send_raw(data)
            if i % 200 == 0:
                time.sleep(0.002)
        count = len(fake.setpoint_times())
        assert wait_for(lambda: len(fake.setpoint_times()) > count + 20)
        assert wait_for(lambda: statuses[-1].rx_garbage > 7000)
        assert statuses[-1].connected and statuses[-1].state == UavStatus.STATE_WARMUP
    finally:
        stop.set()
        thread.join()
    with fake.lock:
        for received in fake.setpoints:
            assert np.isfinite(received.msg.q).all() and math.isfinite(received.msg.thrust)


def test_kill_and_disconnect(graph):
    node, fake, setpoint_pub, teleop_pub, statuses, imus = graph
    assert wait_for(lambda: statuses and statuses[-1].connected)
    teleop_pub.publish(teleop(TeleopCommand.MODE_ARM))
    assert wait_for(lambda: fake.armed)
    teleop_pub.publish(teleop(TeleopCommand.MODE_KILL))
    assert wait_for(lambda: not fake.armed)
    kills = [c for c in fake.command_list() if c.msg.command == 400 and c.msg.param1 == 0.0]
    assert kills and kills[0].msg.param2 == 21196.0
    assert wait_for(lambda: statuses[-1].state == UavStatus.STATE_KILLED)
    fake.send_heartbeats = False
    assert wait_for(lambda: statuses[-1].state == UavStatus.STATE_DISCONNECTED and not statuses[-1].connected,
                    timeout=4.0)
    assert statuses[-1].link_age >= 1.5
