"""The overlapped two-process layout (issue 15): the simulator in a process of its own, stepping the next /clock
period while the graph (every other node, in :class:`~fpr_experiments.inprocess.InProcessGraph`'s deterministic
runner) works on the previous one. Deterministic: the same scenario and seed give the same ground truth bit for
bit on an idle or a loaded machine (tests/test_determinism.py), whatever the two processes' timing; its failures
stop the run with one error each (src/fpr_experiments/test/test_overlapped.py).

The schedule, per /clock period k (T_k = k x the /clock period):

- the **simulator process** steps period k (physics T_(k-1) -> T_k, its PX4 emulators send their telemetry over
  UDP as always) and sends the graph one *period message*: every message the simulator published in the step
  (the message objects, pickled: /clock, ground truth, camera frames or marker poses, /tf, ...), T_k, and how
  many datagrams each emulator has sent so far. Before step k it waits for the graph's *acknowledgement* of
  period k-2 and admits into each emulator exactly the datagrams the graph's bridges had sent by then
  (``Px4Emulator.admit``): what arrives early waits in the socket;
- the **graph process** takes period message k, publishes its messages from a stand-in ``simulator`` node (in
  process, :mod:`fpr_experiments.intra_process`), drains the graph (the controllers compute on T_k, the bridges
  send their setpoints) and acknowledges period k with each bridge's count of datagrams sent; then, while the
  simulator already steps on, it lets each bridge read exactly the telemetry datagrams of period k
  (``MavlinkLink.receive_limit``) and drains again. A datagram a bridge sends while it handles telemetry (a
  command after a COMMAND_ACK) counts in the next acknowledgement. A thread of the graph process reads the
  period messages as they come, so the simulator never waits in its send (a camera period's ~1 MB is larger
  than the socket's buffer).

So the simulator steps period k+1 while the graph drains period k, and the setpoints the controllers compute on
/clock T_k reach the emulators before step k+2: they act from T_(k+1), one /clock period (10 ms at the default
100 Hz) later than in one process, where they act from T_k. That period of added control latency is the price
of the overlap, and the reason this layout is an option beside the default one-process runner, not a
replacement: its flights differ from the one-process flights by that latency (docs/results_overlapped.md compares
the whole suite). The real robot has more than 10 ms of latency between a camera frame and the motors anyway.

What runs where: the simulator process builds the simulator node from its :class:`~fpr_experiments.graph.NodeSpec`
(the same parameters as in one process) in a ROS domain of its own (the graph's + 1, modulo 101): nothing in it
is seen by DDS in the graph's domain; every publish of its node is captured (``rclpy.publisher.Publisher.publish``
replaced in that process only) instead of sent, and a captured topic counts as subscribed there (the simulator
builds its lazy /tf whatever the graph listens to). The graph process's stand-in node has a publisher of the same
topic, type and QoS for each of the simulator's, and publishes what the period message carries; its latched
/tf_static and /robot_description are sent with the start-up message and published once, as the simulator does.
The processes talk over a socket pair (``multiprocessing.connection``), which stays on this machine.

Limits: the simulator's lockstep is off (the period messages are the lockstep); PX4 clients other than the
graph's bridges (MAVSDK, a GCS) are not supported (they would upset the datagram counts), fault injection needs
the one-process or multi-process runner, and ``run --processes --overlapped`` is refused. Measured speed: about
×1.05 with emulated cameras, nothing with images (docs/benchmarks.md).
"""

from __future__ import annotations

import importlib
import os
import pickle
import queue
import select
import socket
import subprocess
import sys
import threading
import time
import traceback
from collections.abc import Sequence
from multiprocessing.connection import Connection

from rclpy.node import Node

from fpr_experiments.graph import NodeSpec
from fpr_experiments.inprocess import InProcessGraph
from fpr_experiments.recording import Topic

#: [s] wall: the graph's watchdog of the simulator process (a period message), and the simulator's of the graph
#: (an acknowledgement); beyond it the run stops with one error naming the silent side
WATCHDOG_S = 30.0
#: [s] wall: how long a bridge's or an emulator's datagrams of one period may take to arrive
DATAGRAM_TIMEOUT_S = 10.0
#: topics of every node that stay in their process
_LOCAL_TOPICS = ("/rosout", "/parameter_events")
#: the environment variable that tells ``python -m fpr_experiments.overlapped`` which descriptor is its socket
_SOCKET_VARIABLE = "FPR_OVERLAPPED_SOCKET"


def simulator_domain(graph_domain: int) -> int:
    """The simulator process's ROS domain: never the graph's (valid ids 0-232; 1-101 here)."""
    return graph_domain % 101 + 1


# ---- the graph's side ------------------------------------------------------------------------------------------
class SimulatorStandIn(Node):
    """The graph process's ``simulator`` node, standing in for the simulator process: a publisher of the same
    topic, type and QoS for each of the simulator's, the attributes the runners read (``sim.time``,
    ``sim.lockstep_timeouts``, ``last_truth_time``) and :meth:`step`, which publishes the next period's messages.
    Built by :class:`OverlappedGraph`; destroying it stops the simulator process."""

    class _SimulationView:
        time = 0.0
        lockstep_timeouts = 0

    def __init__(self, spec: NodeSpec, context, watchdog: float = WATCHDOG_S) -> None:
        super().__init__("simulator", context=context, enable_rosout=False, start_parameter_services=False)
        self.watchdog = watchdog
        self.sim = self._SimulationView()
        self.last_truth_time: float | None = None
        self.sent: list[int] = []  #: per UAV, datagrams its emulator had sent by the latest period
        self.simulator_cpu = 0.0  #: [s] the simulator process's CPU time from the start to the latest period
        self.period = 0  #: the latest period message's number
        self._started = False
        self._proxies: dict[str, object] = {}  #: topic -> its publisher
        ours, theirs = socket.socketpair()
        environment = dict(os.environ, **{_SOCKET_VARIABLE: str(theirs.fileno())})
        graph_domain = int(os.environ.get("ROS_DOMAIN_ID", "0") or 0)
        environment["ROS_DOMAIN_ID"] = str(simulator_domain(graph_domain))
        self.process = subprocess.Popen([sys.executable, "-m", "fpr_experiments.overlapped"], env=environment,
                                        pass_fds=(theirs.fileno(),))
        theirs.close()
        self._socket = ours  # shut down at the end, which wakes the reader thread
        self.connection = Connection(os.dup(ours.fileno()))
        #: what the simulator process sent, read as soon as it arrives by a thread of its own: a period message
        #: with camera frames (~1 MB) is larger than the socket's buffer, and the simulator must not wait in its
        #: send until the graph is ready for that period (None: the connection ended)
        self._inbox: queue.Queue[bytes | None] = queue.Queue()
        self._reader = threading.Thread(target=self._read, name="overlapped-reader", daemon=True)
        self._reader.start()
        try:
            self._send(("spec", spec))
            _, publishers, latched = self._receive(what="its start-up message (the simulator node is built)")
            for topic, (module, name), qos in publishers:
                msg_type = getattr(importlib.import_module(module), name)
                self._proxies[topic] = self.create_publisher(msg_type, topic, _qos(qos))
            self._publish(latched)
        except BaseException:
            self.destroy_node()
            raise

    def _send(self, message) -> None:
        try:
            self.connection.send_bytes(pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL))
        except OSError as error:
            raise RuntimeError(f"overlapped layout: the simulator process is gone ({self._exit_text()}): "
                               f"{error}") from None

    def _read(self) -> None:
        try:
            while True:
                self._inbox.put(self.connection.recv_bytes())
        except (EOFError, OSError):
            self._inbox.put(None)

    def _receive(self, what: str):
        try:
            data = self._inbox.get(timeout=self.watchdog)
        except queue.Empty:
            raise RuntimeError(f"overlapped layout: the simulator process (pid {self.process.pid}) sent no "
                               f"{what} within {self.watchdog:g} s wall ({self._exit_text()})") from None
        if data is None:
            self._inbox.put(None)  # for whoever asks next
            try:
                self.process.wait(timeout=1.0)
            except subprocess.TimeoutExpired:
                pass
            raise RuntimeError(f"overlapped layout: the simulator process ended ({self._exit_text()}) before "
                               f"{what}")
        message = pickle.loads(data)
        if message[0] == "error":
            raise RuntimeError(f"overlapped layout: the simulator process failed: {message[1]}")
        return message

    def _exit_text(self) -> str:
        code = self.process.poll()
        return "still running" if code is None else f"exit code {code}"

    def _publish(self, messages: Sequence[tuple[str, object]]) -> None:
        for topic, message in messages:
            self._proxies[topic].publish(message)

    def step(self) -> None:
        """Publish the next period's messages (waiting for them: the simulator process runs at most one period
        ahead of the graph)."""
        if not self._started:
            self._send(("start",))
            self._started = True
        _, period, sim_time, messages, sent, timeouts, truth_time, cpu = \
            self._receive(what=f"period {self.period + 1}")
        self.period, self.sim.time, self.sent = period, sim_time, sent
        self.sim.lockstep_timeouts, self.simulator_cpu = timeouts, cpu
        if truth_time is not None:
            self.last_truth_time = truth_time
        self._publish(messages)

    def acknowledge(self, sent: Sequence[int]) -> None:
        """The graph drained the latest period: its bridges had sent ``sent`` datagrams (per UAV) by then."""
        self._send(("ack", self.period, list(sent)))

    def destroy_node(self) -> None:
        """Stop the simulator process (it ends within 10 s, else it is killed), then destroy the node."""
        if self.process.poll() is None:
            try:
                self.connection.send_bytes(pickle.dumps(("stop",)))
            except OSError:
                pass
            try:
                self.process.wait(timeout=10.0)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        try:
            self._socket.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self._reader.join(timeout=5.0)
        self.connection.close()
        self._socket.close()
        super().destroy_node()


def _qos(fields: tuple[int, int, int, int]):
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    history, depth, reliability, durability = fields
    return QoSProfile(history=HistoryPolicy(history), depth=depth, reliability=ReliabilityPolicy(reliability),
                      durability=DurabilityPolicy(durability))


class OverlappedGraph(InProcessGraph):
    """:class:`InProcessGraph` (deterministic, in-process delivery) with the simulator in a process of its own,
    working on the next /clock period while the graph drains the previous one (module doc). ``watchdog`` [s wall]:
    the longest either process waits for the other."""

    def __init__(self, specs: Sequence[NodeSpec], topics: Sequence[Topic] = (), live_view=None,
                 verify_delivery: bool = False, watchdog: float = WATCHDOG_S) -> None:
        if sum(spec.executable == "simulator" for spec in specs) != 1:
            raise ValueError("the overlapped layout needs exactly one simulator node in the graph")
        self.watchdog = watchdog
        self._bridge_of_uav: dict[int, object] = {}
        super().__init__(specs, topics, live_view=live_view, verify_delivery=verify_delivery, executor="sweep")

    def _build_node(self, spec: NodeSpec):
        if spec.executable == "simulator":
            return SimulatorStandIn(spec, self.context, self.watchdog)
        node = super()._build_node(spec)
        if spec.executable == "px4_bridge":
            if spec.uav_id is None:
                raise ValueError(f"{spec.fully_qualified_name}: the overlapped layout needs the bridge's uav_id")
            self._bridge_of_uav[spec.uav_id] = node
        return node

    def _deterministic_step(self) -> None:
        stand_in = self.simulator
        stand_in.step()
        bridges = [self._bridge_of_uav.get(uav) for uav in range(1, len(stand_in.sent) + 1)]
        for bridge, sent in zip(bridges, stand_in.sent, strict=True):
            if bridge is not None:
                bridge.link.receive_limit = sent
        self.drain()  # the controllers compute on this /clock, the bridges send the setpoints
        stand_in.acknowledge([bridge.link.counters.tx_frames if bridge is not None else 0 for bridge in bridges])
        for bridge, sent in zip(bridges, stand_in.sent, strict=True):
            if bridge is not None:
                _read_datagrams(bridge, sent)
        self.drain()

    @property
    def simulator_cpu(self) -> float:
        """[s] the simulator process's CPU time from the first period to the latest (benchmarks)."""
        return self.simulator.simulator_cpu


def _read_datagrams(bridge, total: int) -> None:
    """``bridge`` (a px4_bridge node without its receive thread) handles its telemetry datagrams until it has read
    ``total`` since the start, waiting for those still in flight."""
    link = bridge.link
    bridge.receive_pending()
    deadline = None
    while link.counters.rx_datagrams < total:
        now = time.monotonic()
        deadline = now + DATAGRAM_TIMEOUT_S if deadline is None else deadline
        if now >= deadline:
            raise RuntimeError(f"overlapped layout: {bridge.get_fully_qualified_name()} read "
                               f"{link.counters.rx_datagrams} of the {total} datagrams its PX4 emulator sent within "
                               f"{DATAGRAM_TIMEOUT_S:g} s")
        select.select([link.fileno()], [], [], deadline - now)
        bridge.receive_pending()


# ---- the simulator's side --------------------------------------------------------------------------------------
def _simulator_process(connection: Connection) -> None:
    import rclpy
    from rclpy.publisher import Publisher

    from fpr_experiments.node_factory import build_node

    def receive(what: str):
        if not connection.poll(WATCHDOG_S):
            raise RuntimeError(f"the graph process sent no {what} within {WATCHDOG_S:g} s wall")
        return pickle.loads(connection.recv_bytes())

    _, spec = receive("graph description")
    outbox: list[tuple[str, object]] = []
    original_publish = Publisher.publish

    def capture(publisher, msg) -> None:  # this process only: every publish goes to the graph process instead
        if publisher.topic_name in _LOCAL_TOPICS:
            original_publish(publisher, msg)
        else:
            outbox.append((publisher.topic_name, msg))

    original_count = Publisher.get_subscription_count

    def count(publisher) -> int:  # a captured topic's listeners are in the graph process: build what is due
        return original_count(publisher) if publisher.topic_name in _LOCAL_TOPICS else 1

    Publisher.publish = capture
    Publisher.get_subscription_count = count
    context = rclpy.Context()
    rclpy.init(context=context, args=[])
    node = build_node(spec, context, lean=True)
    try:
        publishers = []
        for publisher in node.publishers:
            if publisher.topic_name in _LOCAL_TOPICS:
                continue
            qos = publisher.qos_profile
            msg_type = publisher.msg_type
            publishers.append((publisher.topic_name, (msg_type.__module__.rsplit(".", 1)[0], msg_type.__name__),
                               (int(qos.history), int(qos.depth), int(qos.reliability), int(qos.durability))))
        connection.send_bytes(pickle.dumps(("hello", publishers, list(outbox)), protocol=pickle.HIGHEST_PROTOCOL))
        outbox.clear()
        if receive("start")[0] != "start":
            return
        cpu_at_start = time.process_time()
        emulators = node.sim.emulators
        # what the emulators sent while the simulator was built went to ports the graph's bridges had not bound
        # yet (the graph builds them after this message, as the one-process runner builds them after the simulator)
        unsent = [emulator.sent_datagrams for emulator in emulators]
        period = 0
        while True:
            period += 1
            if period >= 3:  # step k needs the graph's acknowledgement of period k-2 (module doc)
                message = receive(f"acknowledgement of period {period - 2}")
                if message[0] != "ack":
                    return  # stop
                if message[1] != period - 2:
                    raise RuntimeError(f"the graph acknowledged period {message[1]} where {period - 2} was due")
                for emulator, sent in zip(emulators, message[2], strict=True):
                    emulator.admit(sent, DATAGRAM_TIMEOUT_S)
            node.step()
            sent = [emulator.sent_datagrams - before for emulator, before in zip(emulators, unsent, strict=True)]
            connection.send_bytes(pickle.dumps(
                ("period", period, node.sim.time, list(outbox), sent, node.sim.lockstep_timeouts,
                 node.last_truth_time, time.process_time() - cpu_at_start), protocol=pickle.HIGHEST_PROTOCOL))
            outbox.clear()
    finally:
        node.destroy_node()
        context.try_shutdown()


def main() -> int:
    """``python -m fpr_experiments.overlapped``: the simulator process (started by :class:`SimulatorStandIn`)."""
    variable = os.environ.get(_SOCKET_VARIABLE)
    if variable is None:
        print("fpr_experiments.overlapped is started by OverlappedGraph (the simulator process of the overlapped "
              "layout), not by hand", file=sys.stderr)
        return 2
    connection = Connection(int(variable))
    try:
        _simulator_process(connection)
    except (EOFError, BrokenPipeError, ConnectionResetError):
        return 0  # the graph process is gone: nothing to tell it
    except BaseException as error:  # noqa: BLE001 - tell the graph process, then fail
        text = "".join(traceback.format_exception_only(type(error), error)).strip()
        try:
            connection.send_bytes(pickle.dumps(("error", text)))
        except OSError:
            pass
        traceback.print_exc()
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
