"""A polling executor for the deterministic in-process graph (issue 15, "the executor").

The deterministic runner (:mod:`fpr_experiments.inprocess`) runs every callback the simulator's last step made
ready, to quiescence, in ONE thread. rclpy's :class:`~rclpy.executors.SingleThreadedExecutor` does that through
``wait_for_ready_callbacks``: every wait rebuilds a wait set of every entity of every node (Python loops over
~80-150 entities, context managers, callback-group checks), calls ``rcl_wait``, and wraps each ready callback in a
coroutine task; measured on the n = 3 flight, that machinery cost more than the callbacks themselves (drain 13.4 s
of which the callbacks 5.7 s, 8 s simulated; docs/benchmarks.md). Here nothing waits: the runner already knows
when something may be ready (right after it stepped the simulator or read MAVLink), so :meth:`SweepExecutor.drain`

- sweeps the nodes in the order they were added; per node, every timer whose ``is_timer_ready()`` (rcl, on the
  node's clock: /clock time in simulation) is called, then ONE message is taken from each subscription (an empty
  take costs ~1 µs) and its callback run, exactly as rclpy's executor does it (``call_timer`` then the callback;
  ``take_message`` then the callback with the message, or message and ``MessageInfo`` for subscriptions that ask
  for it);
- repeats the sweep until one finds nothing: what a callback published is delivered synchronously inside one
  context, so it is taken in the next sweep; a subscription's queued messages go one per sweep (the order rclpy
  gives them too: one take per ready subscription per wait);
- serves each node's services (Jazzy's type-description service of every node) once per drain, first;
- delivers the graph's messages in process (:mod:`fpr_experiments.intra_process`, ``intra_process=True``, the
  default): a publish of a node of the graph hands the message object to the queue of each subscription of the
  graph, without DDS, and the sweep only takes from subscriptions with something queued (DDS serves what
  comes from outside the graph and what is TRANSIENT_LOCAL; a callback that takes ``MessageInfo``, as the
  controllers' /fpr/info, gets one numbered as DDS's writer numbers it);
- converts each message into Python once for all of its subscribers in the process: it takes the serialized
  message (a raw take, ~2 µs) and deserializes it once per drain (rclpy's ``deserialize_message``), so the n
  controllers, n bridges and the recorder that read one /fpr/info ζ, and the ~13 TimeSources that read one
  /clock message, share one Python object. rclpy's own take converts once per subscription (measured in one
  process, 8 subscriptions: 304 µs for an InformationVector, 170 µs for a Clock, against 40 and 70 µs here;
  even for one subscriber the raw take + deserialization is the cheaper path, 2 + 22 µs against 38 µs). Callbacks
  must therefore treat a received message as read-only — the project's nodes do (they copy what they keep into
  their own types); ``share_messages=False`` gives every subscription its own object, as rclpy does.

The order is fixed (nodes as added, timers before subscriptions, entities in creation order), so the same
scenario and seed give the same callbacks in the same order on any machine. Only plain (not ``async``)
callbacks, timers, subscriptions and services are served: a node with clients, guard conditions or waitables
(QoS event handlers: the lean nodes have none) is refused at :meth:`add_node` with a message saying to use rclpy's
executor (the threaded runner), rather than silently never serving them. Entities created or destroyed later are
picked up at the next drain (the lists are re-read when their lengths change).

Written here rather than taken from rclpy because rclpy's executors wait by design; its ``EventsExecutor``
(rclpy.experimental) avoids the rebuild but with a ``/clock``-driven ROS time its timers fired twice then skipped
(250 Hz /clock) or stalled (50 Hz) in the measurements of issue 15, and it is still experimental in Jazzy.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable

from rclpy.executors import Executor, ExternalShutdownException, TimeoutException
from rclpy.node import Node
from rclpy.serialization import deserialize_message, serialize_message
from rclpy.subscription import Subscription

from fpr_experiments.intra_process import IntraProcessRouter, Route

__all__ = ["SweepExecutor", "UnsupportedEntity", "drain_rclpy_executor"]


class UnsupportedEntity(TypeError):
    """A node has an entity the sweep does not serve (client, guard condition, waitable, async callback)."""


class SweepExecutor:
    """See the module doc. ``drain(errors)`` runs everything ready to quiescence and returns the callbacks run;
    an exception in a callback is appended to ``errors`` (``repr``) and the sweep goes on, as the runner keeps
    the graph alive and lets the flight metrics decide."""

    #: sweeps of one drain before it says the graph does not settle (a callback chain re-triggering itself)
    MAX_SWEEPS = 10_000

    def __init__(self, share_messages: bool = True, intra_process: bool = True, verify: bool = False,
                 outside_check_every: int = 10, route_message_info: bool = True) -> None:
        """``share_messages``: one Python message per received message for all subscribers (else one each, as
        rclpy). ``intra_process``: deliver among the graph's nodes without DDS (:mod:`fpr_experiments.intra_process`;
        nodes added with :meth:`add_publisher_node` publish in process too; ``verify``: check that no message
        changes after it was published; ``outside_check_every``: drains between two looks for endpoints outside the
        graph; ``route_message_info``: route the topics whose callbacks take MessageInfo too; IntraProcessRouter)."""
        self.share_messages = share_messages
        self.router = IntraProcessRouter(verify=verify, check_every=outside_check_every,
                                         route_message_info=route_message_info) if intra_process else None
        #: nodes whose publishers are routed but whose callbacks somebody else runs (the simulator)
        self._publisher_nodes: list[Node] = []
        #: this drain's deserialized messages, by (type, serialized bytes): one conversion per message
        self._decoded: dict[tuple[type, bytes], object] = {}
        self._nodes: list[Node] = []
        self._signature: tuple[int, ...] = ()
        #: per node: (timers, subscriptions with how each callback is called, services), in creation order
        self._entities: list[tuple[list, list[tuple[Subscription, bool, Route | None]], list]] = []

    def add_node(self, node: Node) -> None:
        self._check(node)
        self._nodes.append(node)
        self._refresh()

    def add_publisher_node(self, node: Node) -> None:
        """A node whose callbacks this executor does not run but whose publishers deliver in process (the
        simulator, which the deterministic runner steps itself)."""
        self._publisher_nodes.append(node)
        self._refresh()

    def close(self) -> None:
        """Give the publishers their own ``publish`` back (before the nodes are destroyed)."""
        if self.router is not None:
            self.router.close()

    @property
    def nodes(self) -> list[Node]:
        return list(self._nodes)

    @staticmethod
    def _check(node: Node) -> None:
        unsupported = [f"{len(list(getattr(node, kind)))} {kind}" for kind in ("clients", "guards", "waitables")
                       if list(getattr(node, kind))]
        if unsupported:
            raise UnsupportedEntity(f"node '{node.get_name()}' has {', '.join(unsupported)}: SweepExecutor serves "
                                    "timers, subscriptions and services only; run it with rclpy's executor "
                                    "(InProcessGraph(deterministic=False)) or build it lean")
        for entity in [*node.timers, *node.subscriptions, *node.services]:
            if inspect.iscoroutinefunction(entity.callback):
                raise UnsupportedEntity(f"node '{node.get_name()}': async callback {entity.callback!r} on "
                                        f"{getattr(entity, 'topic_name', entity)}; SweepExecutor runs plain "
                                        "callbacks only")

    def _current_signature(self) -> tuple[int, ...]:
        # rclpy's Node keeps its entities in these lists (its executors read them through the properties); the
        # lengths tell cheaply whether a node created or destroyed something since the last drain
        # (waitables are name-mangled private: `_Node__waitables`)
        return (*(len(lst) for node in self._nodes for lst in (node._timers, node._subscriptions, node._publishers,
                                                               node._services, node._clients, node._guards,
                                                               node._Node__waitables)),
                *(len(node._publishers) for node in self._publisher_nodes))

    def _refresh(self) -> None:
        for node in self._nodes:
            self._check(node)
        if self.router is not None:
            self.router.build(self._nodes, self._publisher_nodes)
        route_of = self.router.route_of if self.router is not None else (lambda _: None)
        self._entities = [(list(node.timers),
                           [(sub, sub._callback_type is Subscription.CallbackType.MessageOnly, route_of(sub))
                            for sub in node.subscriptions],
                           list(node.services)) for node in self._nodes]
        self._signature = self._current_signature()

    def drain(self, errors: list[str]) -> int:
        if self._current_signature() != self._signature:
            self._refresh()
        if self.router is not None:
            self.router.check_outside()
        done = self._serve_services(errors)
        try:
            for _ in range(self.MAX_SWEEPS):
                ran = self._sweep(errors)
                if ran == 0:
                    return done
                done += ran
        finally:
            self._decoded.clear()
        raise RuntimeError(f"SweepExecutor: the graph did not settle after {self.MAX_SWEEPS} sweeps ({done} "
                           "callbacks): a callback keeps making itself ready")

    def _sweep(self, errors: list[str]) -> int:
        ran = 0
        for timers, subscriptions, _ in self._entities:
            for timer in timers:
                handle = timer.handle
                if handle.is_timer_ready():
                    handle.call_timer()
                    ran += 1
                    _run(timer.callback, (), errors)
            for subscription, message_only, route in subscriptions:
                if route is not None:  # in process (message-only callbacks)
                    if not route.queue and not route.dds:
                        continue
                    item = route.take()
                    if item is None:
                        continue
                    ran += 1
                    if route.with_info:  # (message, MessageInfo), as rclpy calls such a callback
                        _run(subscription.callback, (self._routed(subscription, route, item[0]), item[1]), errors)
                    else:
                        _run(subscription.callback, (self._routed(subscription, route, item),), errors)
                    continue
                shared = self.share_messages and not subscription.raw
                taken = subscription.handle.take_message(subscription.msg_type, shared or subscription.raw)
                if taken is None:
                    continue
                ran += 1
                if shared:
                    taken = (self._message(subscription.msg_type, taken[0]), taken[1])
                _run(subscription.callback, (taken[0],) if message_only else taken, errors)
        return ran

    def _routed(self, subscription: Subscription, route: Route, item):
        """What a subscription's callback gets for an in-process queue item (fpr_experiments.intra_process)."""
        if isinstance(item, bytes):  # from DDS, or published serialized
            if subscription.raw:
                return item
            return (self._message(subscription.msg_type, item) if self.share_messages
                    else deserialize_message(item, subscription.msg_type))
        message = self.router.delivered(route, item)
        if subscription.raw:
            return message if getattr(subscription.callback, "accepts_messages", False) \
                else serialize_message(message)
        return message if self.share_messages else deserialize_message(serialize_message(message),
                                                                       subscription.msg_type)

    def _message(self, msg_type: type, serialized: bytes) -> object:
        """The Python message of ``serialized``, deserialized once per drain for every subscriber."""
        key = (msg_type, serialized)
        message = self._decoded.get(key)
        if message is None:
            message = self._decoded[key] = deserialize_message(serialized, msg_type)
        return message

    def _serve_services(self, errors: list[str]) -> int:
        served = 0
        for _, _, services in self._entities:
            for service in services:
                while True:
                    request, header = service.handle.service_take_request(service.srv_type.Request)
                    if header is None:
                        break
                    served += 1
                    try:
                        service.send_response(service.callback(request, service.srv_type.Response()), header)
                    except Exception as error:  # noqa: BLE001 - report, keep serving
                        errors.append(repr(error))
        return served


def _run(callback: Callable, args: tuple, errors: list[str]) -> None:
    try:
        callback(*args)
    except Exception as error:  # noqa: BLE001 - report, keep the graph alive; the metrics decide
        errors.append(repr(error))


def drain_rclpy_executor(executor: Executor, errors: list[str]) -> int:
    """The same drain with rclpy's own executor (full nodes, and the reference the sweep is tested against): run
    ready callbacks until two waits in a row find nothing (it answers one wait per generator: the first empty
    answer can be the end of the previous batch); exceptions go to ``errors``. Returns the callbacks run."""
    done, empty = 0, 0
    while empty < 2:
        try:
            handler, _, _ = executor.wait_for_ready_callbacks(timeout_sec=0.0)
        except TimeoutException:
            empty += 1
            continue
        except ExternalShutdownException:
            return done
        empty = 0
        handler()
        done += 1
        if handler.exception() is not None:  # report, keep the graph alive; the metrics decide
            errors.append(repr(handler.exception()))
    return done
