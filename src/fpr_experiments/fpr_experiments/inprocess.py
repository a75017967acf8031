"""The whole graph in ONE process (rclpy), from the graph description (DESIGN.md §7 "launch-free").

Every node of the description is built from its :class:`~fpr_experiments.graph.NodeSpec` (rcl applies its
``--ros-args``); the recorder spins in an executor thread of its own. The simulation is stepped by
:meth:`InProcessGraph.run_until` in the caller's thread, one ``/clock`` period at a time, so the caller can stop on
a condition. Two ways to run the graph:

- ``deterministic`` (default): ONE thread does everything in a fixed order. Each period: the simulator advances
  and publishes (``/clock``, ground truth, cameras; its PX4 emulators send their telemetry over UDP), the graph's
  executor is drained (every callback that period made ready runs, to quiescence: DDS delivery inside one
  context is synchronous, so what a callback publishes is ready for the next wait), each bridge reads the MAVLink
  waiting on its socket (its receive thread is off, ``receive_thread: false``), and the executor is drained
  again. The setpoints computed on ``/clock`` T are on the emulators' sockets before the simulation passes T, so
  the simulator's own lockstep is off (the drain is the lockstep). Nothing depends on wall time or on thread
  scheduling: the same scenario and seed give the same ground truth bit for bit on an idle or a loaded machine
  (tests/test_determinism.py). The drain is done by :class:`~fpr_experiments.sweep_executor.SweepExecutor`
  (``executor="sweep"``, the default with lean nodes; the recorder is swept too, no thread of its own): it polls
  instead of rebuilding rclpy's wait set at every wait, ×1.5-1.7 real-time factor (docs/benchmarks.md), and
  delivers the graph's messages in process, without DDS (:mod:`fpr_experiments.intra_process`; the simulator's
  publishers too): ``executor="sweep-dds"`` sweeps with every message through DDS, as before (same results).
  ``executor="rclpy"`` drains with rclpy's SingleThreadedExecutor (needed for full nodes: their parameter
  services' clients and QoS event handlers are not served by the sweep).
- threaded: the graph spins in a background executor thread; the simulator's lockstep waits at every 20 ms
  boundary for each streaming UAV's setpoint computed for that period (fpr_sim.simulation), and a backpressure
  (``max_graph_lag``) keeps the simulation from running ahead of the graph while nothing streams. Results then
  depend on the callbacks' order, which varies with load (kept for comparison: benchmarks/bench_graph.py).

Usage::

    specs = describe_graph(GraphOptions(scenario="hover", script="integration_hover"))
    with InProcessGraph(specs) as graph:
        graph.wait_for_discovery()
        graph.run_until(lambda: graph.sim_time >= 10.0, wall_timeout=120.0)
        recording = graph.recorder.snapshot()
"""

from __future__ import annotations

import gc
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import replace

import rclpy
from fpr_model.node_parameters import settle_heap
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

from fpr_experiments.graph import NodeSpec
from fpr_experiments.node_factory import build_node
from fpr_experiments.recording import Recorder, Topic
from fpr_experiments.sweep_executor import SweepExecutor, drain_rclpy_executor

#: [s] simulated: run_until freezes the garbage collector's view of the heap this often (InProcessGraph._freeze_heap)
_FREEZE_PERIOD = 1.0
#: topics every node has and nobody waits for
_IGNORED_TOPICS = ("/rosout", "/parameter_events")


class InProcessGraph:
    """See the module doc. A context manager: ``close()`` destroys every node and shuts the context down."""

    def __init__(self, specs: Sequence[NodeSpec], topics: Sequence[Topic] = (), max_graph_lag: float = 0.1,
                 lean: bool = True, deterministic: bool = True, live_view=None, executor: str | None = None,
                 real_time_factor: float | None = None, verify_delivery: bool = False,
                 measure_periods: bool = False, freeze_heap: bool = True) -> None:
        """``executor``: "sweep" (in-process delivery), "sweep-info-dds" (in-process delivery but for the callbacks
        that take MessageInfo, through DDS: before fpr_experiments.intra_process numbered them itself), "sweep-dds"
        (the sweep with every message through DDS),
        "sweep-copy" (through DDS, and converting each message once per subscription, as rclpy does, instead of once
        per message: fpr_experiments.sweep_executor) or "rclpy" (deterministic mode; None:
        sweep for lean nodes, else rclpy); the
        threaded mode always spins rclpy's executor. ``real_time_factor``: the simulator's pacing (0: as fast as
        the graph runs); None: deterministic runs are not paced (their results do not depend on it) unless a live
        view watches (then the simulator's own parameter, 1 by default), threaded runs keep the parameter.
        ``verify_delivery`` (tests): the in-process delivery checks that no message changes after it was published
        (fpr_experiments.intra_process; it copies every message, slower). ``measure_periods`` (benchmarks,
        deterministic mode): :attr:`period_costs` gets one (simulation time [s], simulator CPU [s], graph CPU [s])
        per /clock period, thread CPU time of the step and of the drains that follow it. ``freeze_heap``: keep the
        graph's objects out of the garbage collector's full collections (:meth:`_freeze_heap`; False: as before,
        the same flight, tests/test_determinism.py)."""
        self.deterministic = deterministic
        if executor is None:
            executor = "sweep" if deterministic and lean else "rclpy"
        if executor not in ("sweep", "sweep-info-dds", "sweep-dds", "sweep-copy", "rclpy"):
            raise ValueError("executor must be 'sweep', 'sweep-info-dds', 'sweep-dds', 'sweep-copy' or 'rclpy', got "
                             f"{executor!r}")
        if executor != "rclpy" and not deterministic:
            raise ValueError(f"executor {executor!r} needs deterministic=True (the threaded runner waits in rclpy)")
        self.executor_kind = executor
        self.verify_delivery = verify_delivery
        self.measure_periods = measure_periods
        self.freeze_heap = freeze_heap
        self._frozen = False
        #: with ``measure_periods``: (simulation time [s], simulator CPU [s], graph CPU [s]) per /clock period
        self.period_costs: list[tuple[float, float, float]] = []
        self.live_view = live_view  #: fpr_experiments.live_view.LiveView the recorder forwards to, or None
        if real_time_factor is None and deterministic and live_view is None:
            real_time_factor = 0.0
        pace = {} if real_time_factor is None else {"real_time_factor": float(real_time_factor)}
        if deterministic:  # bridges read MAVLink when told; the drain replaces the simulator's lockstep
            specs = [replace(s, parameters={**s.parameters, "receive_thread": False}) if s.executable == "px4_bridge"
                     else replace(s, parameters={**s.parameters, "lockstep": False, **pace})
                     if s.executable == "simulator" else s for s in specs]
        elif pace:
            specs = [replace(s, parameters={**s.parameters, **pace}) if s.executable == "simulator" else s
                     for s in specs]
        self.specs = list(specs)
        self.max_graph_lag = max_graph_lag
        self.lean = lean  #: nodes without parameter services / default QoS event handlers (node_factory.build_node)
        self.context = rclpy.Context()
        rclpy.init(context=self.context, args=[])
        self.nodes: list[Node] = []
        self.by_name: dict[str, Node] = {}
        self.errors: list[str] = []  #: exceptions raised in callbacks (the graph keeps running)
        self.simulator = None
        self.recorder: Recorder | None = None
        self._running = True
        self._executor: SingleThreadedExecutor | None = None
        self._sweep: SweepExecutor | None = None
        self._fallbacks_logged = 0
        self._spinner: threading.Thread | None = None
        try:
            self._build(topics)
        except BaseException:
            self.close()
            raise

    def _build(self, topics: Sequence[Topic]) -> None:
        for spec in self.specs:
            node = self._build_node(spec)
            self.nodes.append(node)
            self.by_name[spec.fully_qualified_name] = node
            if spec.executable == "simulator":
                self.simulator = node
        use_sim_time = self.simulator is not None
        sweep = self.executor_kind in ("sweep", "sweep-info-dds", "sweep-dds", "sweep-copy")
        self.recorder = Recorder(self.context, topics, use_sim_time=use_sim_time, live_view=self.live_view,
                                 spin=not sweep)
        if sweep:
            self._sweep = SweepExecutor(share_messages=self.executor_kind != "sweep-copy",
                                        intra_process=self.executor_kind in ("sweep", "sweep-info-dds"),
                                        verify=self.verify_delivery,
                                        route_message_info=self.executor_kind != "sweep-info-dds")
            for node in [*self.nodes, self.recorder]:
                if node is not self.simulator:
                    self._sweep.add_node(node)
            if self.simulator is not None:
                self._sweep.add_publisher_node(self.simulator)
        else:
            self._executor = SingleThreadedExecutor(context=self.context)
            for node in self.nodes:
                if node is not self.simulator:
                    self._executor.add_node(node)
        # the graph's clock: a node spun by the main executor (its /clock lags as the executor does)
        self._graph_clock_node = next(n for n in reversed(self.nodes) if n is not self.simulator)
        self._bridges = [node for spec, node in zip(self.specs, self.nodes, strict=True)
                         if spec.executable == "px4_bridge"]
        if self.freeze_heap:
            settle_heap()  # the construction's garbage collected once, then frozen (see _freeze_heap)
            self._frozen = True
        if not self.deterministic:
            self._spinner = threading.Thread(target=self._spin, name="graph_executor", daemon=True)
            self._spinner.start()

    def _build_node(self, spec: NodeSpec) -> Node:
        """One node of the graph (fpr_experiments.overlapped builds the simulator's stand-in instead)."""
        return build_node(spec, self.context, lean=self.lean)

    def _spin(self) -> None:
        executor = self._executor
        while self._running and self.context.ok():
            try:
                executor.spin_once(timeout_sec=0.05)
            except Exception as error:  # noqa: BLE001 - report, keep the graph alive; metrics decide
                if not self._running or not self.context.ok():
                    return
                self.errors.append(repr(error))

    def drain(self) -> int:
        """Deterministic mode: run every ready callback of the graph, and what they make ready, to quiescence;
        callback exceptions are kept in :attr:`errors`. Returns the callbacks run."""
        if self._sweep is not None:
            done = self._sweep.drain(self.errors)
            router = self._sweep.router
            if router is not None and len(router.fallbacks) > self._fallbacks_logged:
                for line in router.fallbacks[self._fallbacks_logged:]:
                    self._graph_clock_node.get_logger().info(f"in-process delivery: {line}")
                self._fallbacks_logged = len(router.fallbacks)
            return done
        return drain_rclpy_executor(self._executor, self.errors)

    def _deterministic_step(self) -> None:
        if self.measure_periods:
            start = time.thread_time()
        self.simulator.step()
        if self.measure_periods:
            stepped = time.thread_time()
        self.drain()
        for bridge in self._bridges:
            bridge.receive_pending()
        self.drain()
        if self.measure_periods:
            self.period_costs.append((self.sim_time, stepped - start, time.thread_time() - stepped))

    def node(self, fully_qualified_name: str) -> Node:
        return self.by_name[fully_qualified_name]

    # ---- discovery ----------------------------------------------------------------------------------
    def discovery_pending(self) -> list[str]:
        """In-graph connections not matched yet, seen from both ends: a publisher with fewer matched subscriptions
        than the graph has on its topic, or a subscription with fewer matched publishers (discovery is
        asymmetric: a writer can match before its reader does, and the reader would miss the first messages)."""
        publishers: dict[str, list] = {}
        subscriptions: dict[str, list] = {}
        for node in [*self.nodes, self.recorder]:
            for publisher in node.publishers:
                if not publisher.topic_name.startswith(_IGNORED_TOPICS):
                    publishers.setdefault(publisher.topic_name, []).append(publisher)
            for subscription in node.subscriptions:
                if not subscription.topic_name.startswith(_IGNORED_TOPICS):
                    subscriptions.setdefault(subscription.topic_name, []).append(subscription)
        pending = []
        for name, pubs in publishers.items():
            subs = subscriptions.get(name, [])
            for publisher in pubs:
                if publisher.get_subscription_count() < len(subs):
                    pending.append(f"{name} publisher ({publisher.get_subscription_count()}/{len(subs)})")
            for subscription in subs:
                if subscription.get_publisher_count() < len(pubs):
                    pending.append(f"{name} subscription ({subscription.get_publisher_count()}/{len(pubs)})")
        return pending

    def wait_for_discovery(self, timeout: float = 30.0) -> float:
        """Until every in-graph connection is matched; returns the wall time it took, else ``TimeoutError``."""
        start = time.monotonic()
        while pending := self.discovery_pending():
            if time.monotonic() - start > timeout:
                raise TimeoutError(f"discovery incomplete after {timeout} s: {pending[:10]}")
            time.sleep(0.05)
        return time.monotonic() - start

    # ---- running ------------------------------------------------------------------------------------
    @property
    def sim_time(self) -> float:
        return self.simulator.sim.time

    @property
    def lockstep_timeouts(self) -> int:
        return self.simulator.sim.lockstep_timeouts

    def _graph_time(self) -> float:
        return self._graph_clock_node.get_clock().now().nanoseconds * 1e-9

    def _hold_for_graph(self, wall_deadline: float) -> None:
        limit = self.max_graph_lag
        while self.sim_time - self._graph_time() > limit and time.monotonic() < wall_deadline:
            time.sleep(0.0005)

    def run_until(self, condition: Callable[[], bool], wall_timeout: float, sim_timeout: float = math.inf,
                  progress: Callable[[], None] | None = None, progress_period: float = 2.0) -> bool:
        """Step the simulation until ``condition()`` (checked every /clock period); False on a timeout (wall [s]
        or simulated [s]). ``progress`` is called every ``progress_period`` simulated seconds."""
        if self.simulator is None:
            raise RuntimeError("run_until needs the simulator (backend sim)")
        wall_deadline = time.monotonic() + wall_timeout
        sim_deadline = self.sim_time + sim_timeout
        next_progress = self.sim_time + progress_period
        next_freeze = self.sim_time + _FREEZE_PERIOD
        while not condition():
            if time.monotonic() > wall_deadline or self.sim_time >= sim_deadline:
                return False
            if self.deterministic:
                self._deterministic_step()
            else:
                self.simulator.step()
                self._hold_for_graph(wall_deadline)
            if self.freeze_heap and self.sim_time >= next_freeze:  # the last second's recording (_freeze_heap)
                next_freeze += _FREEZE_PERIOD
                self._freeze_heap()
            if progress is not None and self.sim_time >= next_progress - 1e-9:
                next_progress += progress_period
                progress()
        return True

    def wait_for_recorder(self, wall_timeout: float = 30.0) -> bool:
        """Until the recorder holds the last published ground truth (the graph may lag behind after landing)."""
        last = self.simulator.last_truth_time
        return last is None or self.recorder.wait_for("/fpr/ground_truth", last, timeout=wall_timeout)

    # ---- teardown -----------------------------------------------------------------------------------
    def _freeze_heap(self) -> None:
        """Move every object the cyclic garbage collector tracks now out of its sight (``gc.freeze``, O(1)).

        The graph's objects (imports, nodes, ~370,000 for n = 6) and the recording, which grows all flight
        (message objects kept by the in-process delivery), live until :meth:`close`; the collector's full
        collections walked them all, more as the recording grew (~0.1-0.16 s each, a pause in one 50 Hz
        controller callback, 3-4 % of the CPU). Frozen objects are still freed by their reference counts as usual;
        only a reference cycle made before a freeze waits for :meth:`close` (``gc.unfreeze``). The results do not
        depend on it: the collector frees nothing the simulation reads."""
        gc.freeze()
        self._frozen = True

    def close(self) -> None:
        self._running = False
        if self._frozen:
            gc.unfreeze()  # collectable again: a process may build several graphs one after the other
            self._frozen = False
        if self._spinner is not None:
            self._spinner.join(timeout=5.0)
        if self._executor is not None:
            self._executor.shutdown(timeout_sec=1.0)
        if self._sweep is not None:
            self._sweep.close()
        if self.recorder is not None:
            try:
                self.recorder.stop()
            except Exception:  # noqa: BLE001 - best effort at teardown
                pass
        for node in reversed(self.nodes):
            try:
                node.destroy_node()
            except Exception:  # noqa: BLE001
                pass
        self.nodes.clear()
        self.context.try_shutdown()

    def __enter__(self) -> InProcessGraph:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
