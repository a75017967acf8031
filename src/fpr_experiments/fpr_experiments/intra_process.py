"""In-process delivery for the deterministic in-process graph (issue 15): a message published by one node of the
graph reaches the graph's other nodes without Fast DDS, as rclcpp's intra-process communication does (rclpy has
none).

Why: with every node in one process, Fast DDS still serializes each message, copies it into the history of every
matched reader under its locks and notifies each reader's listener; the sweep then polls every subscription with a
``take_message`` (mostly empty). Measured on the n = 3 flight (docs/benchmarks.md): 60-300 µs per publish in the
graph (~6,000 messages per simulated second), plus ~50,000 empty takes per simulated second; and rclpy converts
each message to C and CDR at the publisher (30-120 µs in the graph) and back to Python once per drain (20-60 µs).

What it does (:class:`IntraProcessRouter`, driven by :class:`fpr_experiments.sweep_executor.SweepExecutor`):

- a topic is *routed* when every endpoint of it inside the graph allows it: it has at least one publisher in the
  graph and one subscription of a node the sweep serves; and every such endpoint is VOLATILE (a TRANSIENT_LOCAL
  publisher's late-joiner replay stays with DDS: /tf_static, /robot_description);
- a subscription whose callback takes ``MessageInfo`` (the controllers' /fpr/info: they tell publishers apart by
  the publication sequence number, fpr_control.information) gets with each routed message the dict rclpy's take
  gives: ``publication_sequence_number`` counted per publisher from 1, one per publish, as Fast DDS's writer counts
  (checked against DDS: src/fpr_experiments/test/test_intra_process.py; routed and DDS flights are bit-identical:
  tests/test_determinism.py),
  ``source_timestamp`` = ``received_timestamp`` = the wall clock at the publish [ns], ``reception_sequence_number``
  None (Fast DDS gives none). The count starts when the router first routes the publisher: a publisher that had
  published through DDS before (none in the graph: /fpr/info is published from the controllers' timers, which run
  only once the sweep does) would number from 1 again, which the controllers read as a restarted publisher;
- a routed publisher's ``publish`` appends the message object itself to the queue of every served subscription
  whose QoS is compatible with it (``rclpy.qos.qos_check_compatible``, as DDS matching) — no serialization, no
  copy, like rclcpp's intra-process publish of a ``unique_ptr``: the publisher hands the message over and must not
  change it afterwards, and subscribers must not change what they receive (both already hold for the sweep's
  shared messages; the project's publishers build a new message per publish). ``IntraProcessRouter(verify=True)``
  checks both: it keeps a copy of every published message and compares it, field by field (NaN equal to NaN),
  with what is delivered, at every delivery (a test flies the whole graph so). Comparing CDR bytes would not do:
  rclpy's serialization leaves the alignment padding uninitialized, so equal messages can serialize differently.
  One exception to handing the object over: a type with float32 scalar fields (sensor_msgs/BatteryState) holds
  them as Python floats, which rclpy rounds to float32 only when it serializes, so its subscribers get a copy
  made through CDR (what DDS delivers; float32 arrays and sequences are rounded when assigned already).
  Each queue keeps the subscription's KEEP_LAST depth (the oldest message is dropped, as a
  reader's history does) or everything (KEEP_ALL). A raw subscription gets the CDR bytes
  (``serialize_message``), unless its callback says it takes message objects too (``accepts_messages``: the
  experiment recorder, which serializes at the end);
- the sweep takes from these queues instead of polling DDS, so it only visits subscriptions a publish has reached;
- everything outside the router keeps working through DDS: a routed publisher also publishes through DDS while
  something outside the graph (another process, a node of this process the sweep does not serve) is matched to
  it (``get_subscription_count`` above the routed subscriptions), so a viewer or ``ros2 topic echo`` sees every
  message; and a topic with a publisher outside the graph (another process, a test's injector node) goes back to
  DDS delivery for good, announced in :attr:`IntraProcessRouter.fallbacks` — its served subscriptions then take
  what is queued, then poll DDS again. The DDS copies a routed publisher sent for outside subscribers before that
  moment sit in the in-graph readers' histories too; they are discarded once (they were delivered from the queue
  already), and with them whatever the new outside publisher sent before the check noticed it. Both checks run
  at the start of every tenth drain (``check_every``; a C call per routed endpoint, ~0.3 µs each, ~3 % of the run
  when done at every drain): an outside subscriber misses at most that long, as if discovery had taken that much
  longer; an outside publisher's messages wait in the readers' histories meanwhile (within their depth), except
  after DDS copies were sent (those are discarded with them);
- messages published through DDS before routing started (while the graph was built) are taken first.

The order of delivery is DDS's: per subscription first in, first out, one message per sweep, delivered
synchronously to the queues during the publishing callback; the same scenario and seed give the same ground truth
bit for bit with and without routing (tests/test_determinism.py). Not routed, hence unchanged: services, and
publishers created after the router was built until the sweep's next refresh (it rebuilds when a node's entity
counts change).
"""

from __future__ import annotations

import array
import importlib
import math
import time
from collections import deque
from collections.abc import Callable, Iterable

import numpy as np
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSCompatibility, qos_check_compatible
from rclpy.serialization import deserialize_message, serialize_message
from rclpy.subscription import Subscription
from rosidl_parser.definition import AbstractNestedType, BasicType, NamespacedType

__all__ = ["IntraProcessRouter", "Route", "RoutedTopic"]


class RoutedTopic:
    """One topic delivered in process. ``routed`` turns False for good when a publisher outside the graph appears."""

    __slots__ = ("name", "routed", "dds_copies", "routes", "publishers")

    def __init__(self, name: str) -> None:
        self.name = name
        self.routed = True
        #: a routed publisher published through DDS for an outside subscriber (copies sit in in-graph readers)
        self.dds_copies = False
        self.routes: list[Route] = []
        self.publishers: list[_PublisherRoute] = []


class Route:
    """One served subscription of a routed topic: its queue of messages and how many graph publishers DDS should
    match it with (more means one from outside)."""

    __slots__ = ("subscription", "topic", "queue", "graph_publishers", "poll_dds", "dds", "with_info")

    def __init__(self, subscription: Subscription, topic: RoutedTopic) -> None:
        self.subscription = subscription
        self.topic = topic
        #: the callback takes (message, MessageInfo): :meth:`take` returns such pairs
        self.with_info = subscription._callback_type is not Subscription.CallbackType.MessageOnly
        qos = subscription.qos_profile
        #: message objects, or CDR bytes (published as bytes); (object, its copy) pairs when the router verifies
        self.queue: deque = deque(maxlen=None if qos.history == HistoryPolicy.KEEP_ALL else max(1, qos.depth))
        self.graph_publishers = 0
        #: take from DDS first: what was published through DDS before routing started, until the reader is empty
        self.poll_dds = True
        #: DDS may hold something for it (leftovers, or the topic went back to DDS): the sweep skips a route with
        #: neither this nor a queued message without calling :meth:`take`
        self.dds = True

    def take(self):
        """The next message for this subscription (a message object, or CDR bytes when it came through DDS or was
        published as bytes), or None (see the module doc for the order); with :attr:`with_info` a (message,
        MessageInfo) pair."""
        handle = self.subscription.handle
        if self.topic.routed:
            if self.poll_dds:
                taken = handle.take_message(self.subscription.msg_type, True)
                if taken is not None:
                    return taken if self.with_info else taken[0]
                self.poll_dds = self.dds = False
            return self.queue.popleft() if self.queue else None
        if self.queue:
            return self.queue.popleft()
        taken = handle.take_message(self.subscription.msg_type, True)
        return None if taken is None else taken if self.with_info else taken[0]


class _PublisherRoute:
    __slots__ = ("publisher", "topic", "targets", "outside_subscribers", "original", "sequence")

    def __init__(self, publisher: Publisher, topic: RoutedTopic) -> None:
        self.publisher = publisher
        self.topic = topic
        self.targets: list[Route] = []
        self.outside_subscribers = False
        #: this publisher's messages so far: the publication sequence number DDS's writer gives (1, 2, ...)
        self.sequence = 0
        # the class's publish bound to this publisher (the instance attribute installed below shadows it)
        self.original: Callable = Publisher.publish.__get__(publisher)


def _volatile(qos) -> bool:
    return qos.durability != DurabilityPolicy.TRANSIENT_LOCAL


def _compatible(publisher: Publisher, subscription: Subscription) -> bool:
    compatibility, _ = qos_check_compatible(publisher.qos_profile, subscription.qos_profile)
    return compatibility != QoSCompatibility.ERROR


class IntraProcessRouter:
    """See the module doc. :meth:`build` (again whenever the graph's entities change), :meth:`route_of` for the
    sweep, :meth:`check_outside` at the start of every drain, :meth:`close` to give the publishers back."""

    def __init__(self, verify: bool = False, check_every: int = 10, route_message_info: bool = True) -> None:
        """``verify``: keep a copy of each published message and check at every delivery that neither the
        publisher nor an earlier subscriber changed it (:meth:`delivered`; for tests: it copies everything).
        ``check_every``: look for endpoints outside the graph at every so many drains (:meth:`check_outside`).
        ``route_message_info`` False: a topic with a MessageInfo callback stays with DDS (as before the router
        numbered them; benchmarks/bench_graph.py's lever)."""
        if check_every < 1:
            raise ValueError(f"check_every must be >= 1, got {check_every}")
        self.verify = verify
        self.route_message_info = route_message_info
        self.check_every = check_every
        self._checks = 0
        self.topics: dict[str, RoutedTopic] = {}
        self._routes: dict[int, Route] = {}  # id(subscription) -> route
        self._publishers: dict[int, _PublisherRoute] = {}  # id(publisher) -> its route
        #: one line per topic that went back to DDS delivery (the runner logs them)
        self.fallbacks: list[str] = []

    def build(self, served: Iterable[Node], publishing: Iterable[Node]) -> None:
        """Route what can be routed among the subscriptions of ``served`` nodes (swept by the caller) and the
        publishers of ``served`` and ``publishing`` nodes. Queues and fallbacks of an earlier build are kept."""
        served = list(served)
        subscriptions: dict[str, list[Subscription]] = {}
        for node in served:
            for subscription in node.subscriptions:
                subscriptions.setdefault(subscription.topic_name, []).append(subscription)
        publishers: dict[str, list[Publisher]] = {}
        for node in [*served, *publishing]:
            for publisher in node.publishers:
                publishers.setdefault(publisher.topic_name, []).append(publisher)
        old_routes, old_publishers = self._routes, self._publishers
        self._routes, self._publishers = {}, {}
        for name, subs in subscriptions.items():
            pubs = publishers.get(name, [])
            routable = (bool(pubs)
                        and (self.route_message_info
                             or all(s._callback_type is Subscription.CallbackType.MessageOnly for s in subs))
                        and all(_volatile(s.qos_profile) for s in subs)
                        and all(_volatile(p.qos_profile) for p in pubs))
            topic = self.topics.get(name)
            if topic is None:
                if not routable:
                    continue
                topic = self.topics[name] = RoutedTopic(name)
            elif topic.routed and not routable:  # keep its queues: they are delivered first, then DDS
                self._fall_back(topic, "its endpoints in the graph changed (a TRANSIENT_LOCAL or publisher-less "
                                       "endpoint)")
            topic.routes, topic.publishers = [], []
            for subscription in subs:
                if not self.route_message_info and \
                        subscription._callback_type is not Subscription.CallbackType.MessageOnly:
                    continue  # a fallen-back topic: served by the sweep's plain DDS path, with its MessageInfo
                route = old_routes.get(id(subscription))
                if route is None or route.subscription is not subscription:
                    route = Route(subscription, topic)
                route.graph_publishers = sum(_compatible(p, subscription) for p in pubs)
                topic.routes.append(route)
                self._routes[id(subscription)] = route
            for publisher in pubs:
                entry = old_publishers.get(id(publisher))
                if entry is None or entry.publisher is not publisher or entry.topic is not topic:
                    entry = _PublisherRoute(publisher, topic)  # its publish closes over this topic
                    publisher.publish = self._publish_function(entry)
                entry.targets = [r for r in topic.routes if _compatible(publisher, r.subscription)]
                topic.publishers.append(entry)
                self._publishers[id(publisher)] = entry
        for key, entry in old_publishers.items():  # no longer routed (destroyed, or its topic lost subscribers)
            if key not in self._publishers:
                _restore(entry.publisher)
        for name in [name for name, topic in self.topics.items() if not topic.routes]:
            del self.topics[name]

    def _publish_function(self, entry: _PublisherRoute) -> Callable:
        msg_type = entry.publisher.msg_type
        verify = self.verify
        wire_copy = _has_float32_scalars(msg_type)
        topic = entry.topic

        def publish(msg) -> None:
            if not topic.routed:
                entry.original(msg)
                entry.sequence += 1
                return
            if not isinstance(msg, (msg_type, bytes)):  # what rclpy's Publisher.publish raises
                raise TypeError(f"Expected {msg_type}, got {type(msg)}")
            entry.sequence += 1
            if wire_copy and not isinstance(msg, bytes):
                msg = _copy(msg)  # float32 scalars rounded as on the wire
            item = (msg, _copy(msg)) if verify and not isinstance(msg, bytes) else msg
            info = None
            for route in entry.targets:
                if route.with_info:
                    if info is None:  # what DDS's reader gives (rclpy's MessageInfo keys; wall-clock stamps)
                        now = time.time_ns()
                        info = {"source_timestamp": now, "received_timestamp": now,
                                "publication_sequence_number": entry.sequence, "reception_sequence_number": None}
                    route.queue.append((item, info))
                else:
                    route.queue.append(item)
            if entry.outside_subscribers:
                entry.original(msg)
                topic.dds_copies = True

        publish.__doc__ = f"In-process delivery of {entry.publisher.topic_name} (fpr_experiments.intra_process)"
        return publish

    def delivered(self, route: Route, item):
        """The message of a queue ``item`` (see ``verify``): raises ``RuntimeError`` naming the topic if the
        message changed since it was published."""
        if not self.verify or not isinstance(item, tuple):
            return item
        message, published = item
        if not _same(message, published):
            raise RuntimeError(f"in-process delivery on {route.topic.name}: the {type(message).__name__} changed "
                               "after it was published (a publisher reused it, or a subscriber modified it)")
        return message

    def route_of(self, subscription: Subscription) -> Route | None:
        return self._routes.get(id(subscription))

    def check_outside(self) -> None:
        """Outside subscribers (publish through DDS too) and outside publishers (back to DDS for good); called at
        every drain, it looks at every ``check_every``-th call (the first included)."""
        self._checks += 1
        if (self._checks - 1) % self.check_every:
            return
        for topic in self.topics.values():
            if not topic.routed:
                continue
            for entry in topic.publishers:
                entry.outside_subscribers = entry.publisher.handle.get_subscription_count() > len(entry.targets)
            outside = [r for r in topic.routes if r.subscription.handle.get_publisher_count() > r.graph_publishers]
            if outside:
                matched = outside[0].subscription.handle.get_publisher_count()
                self._fall_back(topic, f"a publisher outside the in-process graph ({matched} matched, "
                                       f"{outside[0].graph_publishers} in the graph)")

    def _fall_back(self, topic: RoutedTopic, reason: str) -> None:
        topic.routed = False
        for route in topic.routes:
            route.dds = True
        discarded = 0
        if topic.dds_copies:
            for route in topic.routes:
                while route.subscription.handle.take_message(route.subscription.msg_type, True) is not None:
                    discarded += 1
        self.fallbacks.append(f"{topic.name}: back to DDS delivery: {reason}"
                              + (f"; {discarded} DDS copies of routed messages discarded" if discarded else ""))

    def close(self) -> None:
        """Give every publisher its own ``publish`` back (the graph is closing or the executor is replaced)."""
        for entry in self._publishers.values():
            _restore(entry.publisher)
        self._publishers, self._routes, self.topics = {}, {}, {}


def _restore(publisher: Publisher) -> None:
    publisher.__dict__.pop("publish", None)


_FLOAT32_SCALARS: dict[type, bool] = {}


def _has_float32_scalars(msg_type: type) -> bool:
    """A message type holding float32 values as Python floats anywhere (scalar fields, nested messages)."""
    if msg_type not in _FLOAT32_SCALARS:
        _FLOAT32_SCALARS[msg_type] = False  # a recursive type is decided by its other fields
        _FLOAT32_SCALARS[msg_type] = any(_slot_has_float32_scalars(slot) for slot in msg_type.SLOT_TYPES)
    return _FLOAT32_SCALARS[msg_type]


def _slot_has_float32_scalars(slot) -> bool:
    if isinstance(slot, BasicType):
        return slot.typename == "float"
    if isinstance(slot, NamespacedType):
        return _has_float32_scalars(getattr(importlib.import_module(".".join(slot.namespaces)), slot.name))
    if isinstance(slot, AbstractNestedType):  # arrays / sequences: of messages only (numbers are stored typed)
        return isinstance(slot.value_type, NamespacedType) and _slot_has_float32_scalars(slot.value_type)
    return False


def _copy(message):
    return deserialize_message(serialize_message(message), type(message))


def _same(a, b) -> bool:
    """Field-by-field equality of two ROS messages (or field values); NaN equals NaN."""
    if hasattr(a, "get_fields_and_field_types"):
        return type(a) is type(b) and all(_same(getattr(a, name), getattr(b, name))
                                          for name in a.get_fields_and_field_types())
    if isinstance(a, (np.ndarray, array.array)):
        a, b = np.asarray(a), np.asarray(b)
        return a.shape == b.shape and np.array_equal(a, b, equal_nan=a.dtype.kind == "f")
    if isinstance(a, (list, tuple)):
        return isinstance(b, (list, tuple)) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b
