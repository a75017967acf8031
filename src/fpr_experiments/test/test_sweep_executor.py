"""SweepExecutor (real rclpy, scripts/run_tests.sh): timers under a /clock-driven ROS time tick exactly once per
period (no duplicated, no skipped tick) at the same instants as with rclpy's own executor; subscriptions get
their messages in order, with MessageInfo when they ask for it; services are served; a failing callback is
reported and the others run; a graph that never settles is said; entities created later are served; what the
sweep does not serve is refused with a message. Driven like the deterministic runner: publish /clock, drain."""

from __future__ import annotations

import threading
import time

import pytest

rclpy = pytest.importorskip("rclpy")
from fpr_experiments.node_factory import lean_class  # noqa: E402
from fpr_experiments.sweep_executor import SweepExecutor, UnsupportedEntity, drain_rclpy_executor  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from std_msgs.msg import Int32  # noqa: E402

LeanNode = lean_class(Node)


@pytest.fixture
def context():
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    yield ctx
    ctx.try_shutdown()


def _node(name: str, context, sim_time: bool = False) -> Node:
    return LeanNode(name, context=context, start_parameter_services=False,
                    parameter_overrides=[Parameter("use_sim_time", value=sim_time)])


def _wait_matched(publisher, count: int = 1, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while publisher.get_subscription_count() < count:
        assert time.monotonic() < deadline, f"{publisher.topic_name}: no subscription matched"
        time.sleep(0.01)


def _timer_ticks(context, executor_kind: str) -> dict[str, list[int]]:
    """Ticks [ns of ROS time] of a 50 Hz and a 20 Hz timer over 2 s of /clock at 100 Hz."""
    node = _node(f"ticker_{executor_kind}", context, sim_time=True)
    driver = _node(f"clock_driver_{executor_kind}", context)
    clock_pub = driver.create_publisher(Clock, "/clock", 10)
    ticks: dict[str, list[int]] = {"50 Hz": [], "20 Hz": []}
    node.create_timer(0.02, lambda: ticks["50 Hz"].append(node.get_clock().now().nanoseconds))
    node.create_timer(0.05, lambda: ticks["20 Hz"].append(node.get_clock().now().nanoseconds))
    errors: list[str] = []
    if executor_kind == "sweep":
        executor = SweepExecutor()
        executor.add_node(node)

        def drain():
            executor.drain(errors)
    else:
        rclpy_executor = SingleThreadedExecutor(context=context)
        rclpy_executor.add_node(node)

        def drain():
            drain_rclpy_executor(rclpy_executor, errors)
    _wait_matched(clock_pub)
    for k in range(1, 201):  # 10 ms steps to 2 s
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(k * 10_000_000, 1_000_000_000)
        clock_pub.publish(msg)
        drain()
    assert errors == []
    node.destroy_node()
    driver.destroy_node()
    return ticks


def test_timers_tick_once_per_period_under_clock_as_with_rclpys_executor(context):
    sweep = _timer_ticks(context, "sweep")
    reference = _timer_ticks(context, "rclpy")
    for name, period_ns in (("50 Hz", 20_000_000), ("20 Hz", 50_000_000)):
        ticks = sweep[name]
        steps = [b - a for a, b in zip(ticks, ticks[1:], strict=False)]
        assert steps and set(steps) == {period_ns}, f"{name}: duplicated or skipped ticks: {sorted(set(steps))}"
        assert len(ticks) >= 2_000_000_000 // period_ns - 1, f"{name}: {len(ticks)} ticks in 2 s"
        assert ticks == reference[name], f"{name}: the sweep ticks at other instants than rclpy's executor"


def test_subscriptions_in_order_with_message_info_when_asked(context):
    node = _node("listener", context)
    talker = _node("talker", context)
    plain, with_info = [], []
    node.create_subscription(Int32, "/numbers", lambda msg: plain.append(msg.data), 10)
    node.create_subscription(Int32, "/numbers", lambda msg, info: with_info.append(
        (msg.data, info["publication_sequence_number"])), 10)
    executor = SweepExecutor()
    executor.add_node(node)
    publisher = talker.create_publisher(Int32, "/numbers", 10)
    _wait_matched(publisher, 2)
    for value in (7, 8, 9):  # queued before one drain
        publisher.publish(Int32(data=value))
    errors: list[str] = []
    assert executor.drain(errors) == 6
    assert plain == [7, 8, 9]
    assert [v for v, _ in with_info] == [7, 8, 9]
    assert [s for _, s in with_info] == sorted(s for _, s in with_info)
    assert executor.drain(errors) == 0 and errors == []


@pytest.mark.parametrize("share", [True, False])
def test_one_message_is_converted_once_for_all_its_subscribers_unless_told_not_to(context, share):
    """Every subscription of the process gets the message, equal in content; with sharing (the default) they get
    ONE Python object per message (one deserialization), distinct messages stay distinct objects; without, each
    subscription its own object, as with rclpy's executor. A raw subscription still gets the serialized bytes."""
    node = _node(f"readers_{share}", context)
    talker = _node(f"talker_share_{share}", context)
    received: dict[str, list] = {"a": [], "b": [], "c": []}
    for name in received:
        node.create_subscription(Int32, "/shared", lambda msg, name=name: received[name].append(msg), 10)
    raw = []
    node.create_subscription(Int32, "/shared", raw.append, 10, raw=True)
    executor = SweepExecutor(share_messages=share)
    executor.add_node(node)
    publisher = talker.create_publisher(Int32, "/shared", 10)
    _wait_matched(publisher, 4)
    for value in (5, 6):
        publisher.publish(Int32(data=value))
    errors: list[str] = []
    assert executor.drain(errors) == 8 and errors == []
    for name in received:
        assert [m.data for m in received[name]] == [5, 6]
    first, second = received["a"]
    assert first is not second
    assert all(isinstance(b, bytes) for b in raw) and len(raw) == 2
    if share:
        assert all(received[name][k] is received["a"][k] for name in "bc" for k in (0, 1))
    else:
        assert received["b"][0] is not first and received["c"][0] is not first


def test_a_failing_callback_is_reported_and_the_others_run(context):
    node = _node("faulty", context)
    talker = _node("talker2", context)
    received = []

    def fail(msg):
        raise ValueError(f"bad {msg.data}")

    node.create_subscription(Int32, "/n", fail, 10)
    node.create_subscription(Int32, "/n", lambda msg: received.append(msg.data), 10)
    executor = SweepExecutor()
    executor.add_node(node)
    publisher = talker.create_publisher(Int32, "/n", 10)
    _wait_matched(publisher, 2)
    publisher.publish(Int32(data=3))
    errors: list[str] = []
    executor.drain(errors)
    assert received == [3]
    assert errors == ["ValueError('bad 3')"]


def test_a_graph_that_never_settles_is_said(context):
    node = _node("echo", context)
    publisher = node.create_publisher(Int32, "/loop", 10)
    node.create_subscription(Int32, "/loop", lambda msg: publisher.publish(Int32(data=msg.data + 1)), 10)
    executor = SweepExecutor()
    executor.MAX_SWEEPS = 50
    executor.add_node(node)
    _wait_matched(publisher)
    publisher.publish(Int32(data=0))
    with pytest.raises(RuntimeError, match="did not settle after 50 sweeps"):
        executor.drain([])


def test_entities_created_after_add_node_are_served(context):
    node = _node("late", context)
    talker = _node("talker3", context)
    executor = SweepExecutor()
    executor.add_node(node)
    received = []
    node.create_subscription(Int32, "/late", lambda msg: received.append(msg.data), 10)
    publisher = talker.create_publisher(Int32, "/late", 10)
    _wait_matched(publisher)
    publisher.publish(Int32(data=5))
    executor.drain([])
    assert received == [5]


def test_services_are_served(context):
    from rcl_interfaces.srv import GetParameterTypes

    server = _node("server", context)
    server.create_service(GetParameterTypes, "/types", lambda request, response: (
        setattr(response, "types", [len(name) for name in request.names]) or response))
    executor = SweepExecutor()
    executor.add_node(server)
    client_context = rclpy.Context()
    rclpy.init(context=client_context)
    try:
        caller = Node("caller", context=client_context)
        client = caller.create_client(GetParameterTypes, "/types")
        assert client.wait_for_service(timeout_sec=10.0)
        caller_executor = SingleThreadedExecutor(context=client_context)
        caller_executor.add_node(caller)
        future = client.call_async(GetParameterTypes.Request(names=["ab", "cde"]))
        spinner = threading.Thread(target=caller_executor.spin_until_future_complete, args=(future, 10.0))
        spinner.start()
        deadline = time.monotonic() + 10.0
        while not future.done() and time.monotonic() < deadline:
            executor.drain([])
            time.sleep(0.005)
        spinner.join(timeout=5.0)
        assert future.done() and list(future.result().types) == [2, 3]
    finally:
        client_context.try_shutdown()


def test_what_the_sweep_does_not_serve_is_refused(context):
    full = Node("full", context=context, start_parameter_services=False)  # default QoS event handlers
    full.create_subscription(Int32, "/x", lambda msg: None, 10)
    with pytest.raises(UnsupportedEntity, match="waitables"):
        SweepExecutor().add_node(full)
    with_client = _node("with_client", context)
    from rcl_interfaces.srv import GetParameterTypes

    with_client.create_client(GetParameterTypes, "/types")
    with pytest.raises(UnsupportedEntity, match="clients"):
        SweepExecutor().add_node(with_client)
    asynchronous = _node("asynchronous", context)

    async def callback(msg):
        return None

    asynchronous.create_subscription(Int32, "/y", callback, 10)
    with pytest.raises(UnsupportedEntity, match="async callback"):
        SweepExecutor().add_node(asynchronous)
