"""In-process delivery (fpr_experiments.intra_process through the SweepExecutor, real rclpy): a graph node's
publish reaches the graph's subscriptions as the same object without DDS, in order, within the subscription's
KEEP_LAST depth and only where the QoS would match; MessageInfo callbacks get DDS's publication sequence
numbers; what must stay with DDS does (TRANSIENT_LOCAL; float32 scalars get a CDR copy); a subscriber outside the
graph still receives everything through DDS; a publisher outside the graph sends its topic back to DDS, announced,
without losing or duplicating; the verifying mode catches a publisher that changes a message after publishing it.
The whole graph flown both ways is compared bit for bit in tests/test_determinism.py."""

from __future__ import annotations

import math
import time

import pytest

rclpy = pytest.importorskip("rclpy")
from fpr_experiments.node_factory import lean_class  # noqa: E402
from fpr_experiments.sweep_executor import SweepExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import BatteryState  # noqa: E402
from std_msgs.msg import Int32  # noqa: E402

LeanNode = lean_class(Node)


@pytest.fixture
def context(request):
    """A context of its own per test; every test also uses topics of its own (``_topic``): endpoints of an earlier
    test's context may linger in discovery for a while and would count as outside the graph."""
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    yield ctx
    for node in _NODES.pop(id(ctx), []):
        node.destroy_node()
    ctx.try_shutdown()


_NODES: dict[int, list[Node]] = {}


def _node(name: str, context) -> Node:
    node = LeanNode(name, context=context, start_parameter_services=False)
    _NODES.setdefault(id(context), []).append(node)
    return node


def _topic(request, name: str = "numbers") -> str:
    return f"/{request.node.name.split('[')[0]}/{name}"


def _wait(condition, what: str, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, what
        time.sleep(0.01)


def _graph(context, topic: str, depth: int = 10, **executor_options):
    """A publisher node and a subscriber node, both swept; returns (executor, publisher, received, subscription)."""
    talker, listener = _node("talker", context), _node("listener", context)
    received: list = []
    publisher = talker.create_publisher(Int32, topic, 10)
    subscription = listener.create_subscription(Int32, topic, received.append, depth)
    executor = SweepExecutor(outside_check_every=1, **executor_options)
    executor.add_node(talker)
    executor.add_node(listener)
    _wait(lambda: publisher.get_subscription_count() >= 1, "no match")
    return executor, publisher, received, subscription


def test_graph_messages_arrive_as_the_same_object_in_order_without_dds(context, request):
    topic = _topic(request)
    executor, publisher, received, subscription = _graph(context, topic)
    messages = [Int32(data=k) for k in range(5)]
    for message in messages:
        publisher.publish(message)
    errors: list[str] = []
    assert executor.drain(errors) == 5 and errors == []
    assert [m.data for m in received] == [0, 1, 2, 3, 4]
    assert all(a is b for a, b in zip(received, messages, strict=True))  # handed over, not copied
    assert subscription.handle.take_message(Int32, True) is None  # nothing went through DDS
    assert topic in executor.router.topics and executor.router.fallbacks == []


def test_keep_last_depth_drops_the_oldest_as_a_reader_history_does(context, request):
    topic = _topic(request)
    executor, publisher, received, _ = _graph(context, topic, depth=2)
    for k in range(5):
        publisher.publish(Int32(data=k))
    executor.drain([])
    assert [m.data for m in received] == [3, 4]


def test_wrong_type_is_refused_as_by_rclpy(context, request):
    topic = _topic(request)
    _, publisher, _, _ = _graph(context, topic)
    with pytest.raises(TypeError, match="Expected"):
        publisher.publish("not a message")


def test_incompatible_qos_is_not_delivered(context, request):
    topic = _topic(request)
    talker, listener = _node("talker", context), _node("listener", context)
    received: list = []
    publisher = talker.create_publisher(Int32, topic, QoSProfile(depth=10,
                                                                       reliability=ReliabilityPolicy.BEST_EFFORT))
    listener.create_subscription(Int32, topic, received.append,
                                 QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
    executor = SweepExecutor()
    executor.add_node(talker)
    executor.add_node(listener)
    publisher.publish(Int32(data=1))
    executor.drain([])
    assert received == []  # a reliable reader does not match a best-effort writer in DDS either


def _info_flight(context, topic: str, intra_process: bool):
    """Two publishers on one topic, a MessageInfo subscriber and a plain one; five interleaved publishes."""
    first, second, listener = _node("first", context), _node("second", context), _node("listener", context)
    with_info: list = []
    plain: list = []
    publishers = [first.create_publisher(Int32, topic, 10), second.create_publisher(Int32, topic, 10)]
    subscription = listener.create_subscription(Int32, topic, lambda m, info: with_info.append((m.data, info)), 10)
    listener.create_subscription(Int32, topic, plain.append, 10)
    executor = SweepExecutor(intra_process=intra_process)
    for node in (first, second, listener):
        executor.add_node(node)
    _wait(lambda: all(p.get_subscription_count() == 2 for p in publishers), "no match")
    executor.drain([])  # the router is built before anything is published (as in the graph)
    for k, publisher in enumerate([0, 1, 0, 1, 0]):
        publishers[publisher].publish(Int32(data=10 * publisher + k))
    if not intra_process:
        _wait(lambda: subscription.handle.get_publisher_count() == 2, "no match")
        time.sleep(0.2)
    executor.drain([])
    return executor, subscription, with_info, [m.data for m in plain]


def test_message_info_callbacks_are_routed_with_the_sequence_numbers_dds_gives(context, request):
    """The controllers' /fpr/info callback takes MessageInfo and tells publishers apart by the publication
    sequence number: routed, it gets the number DDS's writer would give (per publisher, from 1), the same keys."""
    routed_topic, dds_topic = _topic(request, "routed"), _topic(request, "dds")
    executor, subscription, routed, plain = _info_flight(context, routed_topic, intra_process=True)
    assert routed_topic in executor.router.topics and executor.router.fallbacks == []
    assert subscription.handle.take_message(Int32, True) is None  # nothing went through DDS
    _, _, through_dds, dds_plain = _info_flight(context, dds_topic, intra_process=False)
    assert [d for d, _ in routed] == [d for d, _ in through_dds] == plain == dds_plain == [0, 11, 2, 13, 4]
    numbers = [info["publication_sequence_number"] for _, info in routed]
    assert numbers == [info["publication_sequence_number"] for _, info in through_dds] == [1, 1, 2, 2, 3]
    assert all(info.keys() == through_dds[0][1].keys() for _, info in routed)
    assert all(info["reception_sequence_number"] is None for _, info in routed + through_dds)


def test_transient_local_topics_stay_with_dds(context, request):
    latched_topic = _topic(request, "latched")
    talker, listener = _node("talker", context), _node("listener", context)
    latched: list = []
    latched_qos = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    latched_pub = talker.create_publisher(Int32, latched_topic, latched_qos)
    executor = SweepExecutor()
    executor.add_node(talker)
    executor.add_node(listener)
    assert executor.router.topics == {}
    latched_pub.publish(Int32(data=7))
    listener.create_subscription(Int32, latched_topic, latched.append, latched_qos)  # joins late
    _wait(lambda: latched_pub.get_subscription_count() == 1, "no match")
    time.sleep(0.2)  # the late joiner's replay
    executor.drain([])
    assert [m.data for m in latched] == [7]
    assert latched_topic not in executor.router.topics


def test_float32_scalars_are_rounded_as_on_the_wire(context, request):
    topic = _topic(request)
    talker, listener = _node("talker", context), _node("listener", context)
    received: list = []
    publisher = talker.create_publisher(BatteryState, topic, 10)
    listener.create_subscription(BatteryState, topic, received.append, 10)
    executor = SweepExecutor()
    executor.add_node(talker)
    executor.add_node(listener)
    message = BatteryState(voltage=12.3456789)
    publisher.publish(message)
    executor.drain([])
    assert received[0] is not message
    assert received[0].voltage != 12.3456789 and math.isclose(received[0].voltage, 12.3456789, rel_tol=1e-7)


def test_a_subscriber_outside_the_graph_still_gets_every_message(context, request):
    topic = _topic(request)
    executor, publisher, received, _ = _graph(context, topic)
    viewer = _node("viewer", context)  # not swept: outside the graph, as another process
    seen = viewer.create_subscription(Int32, topic, lambda m: None, 10)
    _wait(lambda: publisher.get_subscription_count() == 2, "viewer not matched")
    executor.drain([])  # the router notices the outside subscriber at the start of a drain
    for k in range(3):
        publisher.publish(Int32(data=k))
    executor.drain([])
    assert [m.data for m in received] == [0, 1, 2]
    outside = [seen.handle.take_message(Int32, False) for _ in range(4)]
    assert [m[0].data for m in outside[:3]] == [0, 1, 2] and outside[3] is None
    assert executor.router.fallbacks == []


def test_a_publisher_outside_the_graph_sends_the_topic_back_to_dds_without_loss_or_duplicates(context, request):
    topic = _topic(request)
    executor, publisher, received, _ = _graph(context, topic)
    viewer = _node("viewer", context)
    viewer.create_subscription(Int32, topic, lambda m: None, 10)  # makes the graph publish DDS copies
    _wait(lambda: publisher.get_subscription_count() == 2, "viewer not matched")
    executor.drain([])
    publisher.publish(Int32(data=1))
    executor.drain([])
    injector = _node("injector", context)
    outside = injector.create_publisher(Int32, topic, 10)
    _wait(lambda: outside.get_subscription_count() == 2, "injector not matched")
    publisher.publish(Int32(data=2))  # queued in process, before the router notices the injector
    executor.drain([])  # notices it: back to DDS; the copy of 1 in the reader is discarded, 2 comes from the queue
    outside.publish(Int32(data=100))
    publisher.publish(Int32(data=3))  # through DDS now
    executor.drain([])
    assert [m.data for m in received] == [1, 2, 100, 3]
    assert len(executor.router.fallbacks) == 1 and f"{topic}: back to DDS delivery" in executor.router.fallbacks[0]


def test_verify_catches_a_message_changed_after_publishing(context, request):
    topic = _topic(request)
    executor, publisher, received, _ = _graph(context, topic, verify=True)
    message = Int32(data=1)
    publisher.publish(message)
    executor.drain([])
    assert received[0].data == 1  # unchanged: delivered
    publisher.publish(message)
    message.data = 2  # reused and changed before the subscriber ran
    with pytest.raises(RuntimeError, match="numbers: the Int32 changed after it was published"):
        executor.drain([])


def test_outside_endpoints_are_looked_for_every_check_every_drains(context, request):
    topic = _topic(request)
    executor, publisher, received, _ = _graph(context, topic)
    executor.router.check_every = 3
    executor.drain([])  # looks (the first drain of the new period)
    injector = _node("injector", context)
    outside = injector.create_publisher(Int32, topic, 10)
    _wait(lambda: outside.get_subscription_count() == 1, "injector not matched")
    outside.publish(Int32(data=100))
    executor.drain([])
    executor.drain([])
    assert received == [] and executor.router.fallbacks == []  # not looked yet: waits in the reader's history
    executor.drain([])  # looks: back to DDS, the message is taken
    assert [m.data for m in received] == [100] and len(executor.router.fallbacks) == 1


def test_check_every_must_be_positive():
    with pytest.raises(ValueError, match="check_every"):
        SweepExecutor(outside_check_every=0)


def test_close_gives_the_publishers_their_own_publish_back(context, request):
    topic = _topic(request)
    executor, publisher, received, subscription = _graph(context, topic)
    executor.close()
    assert "publish" not in vars(publisher)
    publisher.publish(Int32(data=9))
    _wait(lambda: subscription.handle.take_message(Int32, False) is not None, "not through DDS after close")
