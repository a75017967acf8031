"""The simulator core (ROS-free): plant + one PX4 emulator per UAV + sensors, with lockstep (DESIGN.md §5).

Time base: the plant's fixed step (1 ms). Each step: the emulators read MAVLink and run their mode logic (and,
in the position-controlled modes, their position controllers, fed with each vehicle's true position and velocity
in its own frame F0i) at the PX4 controller rate (250 Hz) and feed the attitude controllers; after each step
every emulator sends the telemetry messages that are due, each on its own interval (simulation time; PX4's
onboard-link rates, changeable by SET_MESSAGE_INTERVAL, see :mod:`fpr_sim.px4_emulator`).

Lockstep (DESIGN.md §5): at every control-period boundary T_k (``control_rate``, 50 Hz) the simulation does not
advance until every UAV whose setpoint stream is live has a setpoint NEW for that period, or ``lockstep_timeout``
wall seconds passed (then :attr:`Simulation.lockstep_timeouts` is incremented). A setpoint is new for T_k when its
own instant (SET_ATTITUDE_TARGET ``time_boot_ms`` on the emulated PX4's boot clock = simulation time, see
:mod:`fpr_sim.px4_emulator`; fpr_px4_bridge sends the controller's stamp there) is later than the previous
boundary T_{k-1} AND is not the setpoint that served the previous boundary (a repetition carries its stamp;
"different" rather than "later" because the bridge's boot-time mapping can move back by a few ms when its
time-sync estimate improves, which must not make a new setpoint look old). So the bridge's 50 Hz repetitions
of an older setpoint never count (they carry the older stamp), nor does a controller that runs behind (its
setpoint computed on a /clock before T_{k-1}): the controllers' inputs are at most one control period old, and
results do not depend on the machine's speed. The controllers' timers need not be phase-aligned with the
boundaries (a setpoint computed at T_{k-1} + 4 ms serves T_k). Scripted MAVLink clients that send
``time_boot_ms`` = 0 get their setpoints stamped on arrival (each one new), the former behaviour.

A stream is live when a new setpoint arrived during the previous control period, armed or not (so the stream that
must precede arming and OFFBOARD is seen at its true rate in simulation time, however fast the simulation could
run). A live stream is waited for at every boundary until it ends the way a stream ends on PX4: the vehicle
leaves the modes that take offboard setpoints (AUTO.LAND, AUTO.LOITER, a failsafe) or is disarmed (the bridge's
LAND / KILL commands arrive in the same UDP burst as the missing setpoint, and the wait re-reads the emulator's
mode after every poll). A UAV that has never streamed is not waited for (a scenario that starts hovering flies
the held hover setpoint until its controllers take over): the pre-arming phase costs no waits and no timeouts.

Time base per link: only a link whose setpoint stamps are on the simulation's clock can be waited for. Every
new stamped setpoint (``time_boot_ms`` != 0) is checked on arrival: its age (simulation time − stamp) must lie in
[−``clock_tolerance``, ``clock_lag_limit``] (a few ms ahead: millisecond rounding; up to seconds behind: a graph
that starts late). A stamp outside marks the link's time base as *foreign* — a third-party client (MAVSDK,
MAVROS, a GCS) that puts its own uptime in ``time_boot_ms``, as PX4 allows — for the rest of the run: the lockstep
no longer waits for that UAV, which then runs free against the simulator's pacing (``real_time_factor``), and
:attr:`Simulation.on_notice` receives one line saying so. (Without this, every 20 ms period of such a link waited
for the watchdog, and simulated time nearly stopped.) A client whose clock happens to lag the simulation's by
less than ``clock_lag_limit`` is waited for at first; the lockstep then runs on the client's clock, its stamps
soon come out ahead of the simulation time, and it is reclassified within a few periods.

Watchdog: a live stream that neither delivers nor ends within ``lockstep_timeout`` wall seconds is a stalled
graph (a dead or hung node). ``lockstep_on_timeout = "stop"`` (default) raises :class:`LockstepStalled`, one
message naming the UAVs it waited for, instead of flying on without setpoints; ``"continue"`` counts it in
:attr:`Simulation.lockstep_timeouts` and runs on (the stream is then no longer live, so PX4's offboard-loss
failsafe plays out in simulation time: fault-injection runs). ``lockstep = False`` never waits.

MAVLink: one :class:`~fpr_sim.px4_emulator.Px4Emulator` per UAV, as PX4 SITL instance i − 1: bound to
127.0.0.1:(``local_base_port`` + i − 1), sending to 127.0.0.1:(``remote_base_port`` + i − 1) where the bridge
listens (see :mod:`fpr_sim.px4_emulator`).
"""

from __future__ import annotations

import logging
import math
import select
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from fpr_model.rotations import quat_multiply

from fpr_sim.plant import GroundTruth, Plant
from fpr_sim.px4_emulator import LOCAL_BASE_PORT, REMOTE_BASE_PORT, Px4Emulator, boot_time_ms
from fpr_sim.quadrotor import AttitudeCommand
from fpr_sim.scenario import Scenario
from fpr_sim.sensors import UavSensors

__all__ = ["LockstepStalled", "Simulation", "SimulationOptions"]


class LockstepStalled(RuntimeError):
    """The lockstep waited ``lockstep_timeout`` wall seconds for a live setpoint stream (see the module doc)."""


#: [s] a scenario that starts hovering (armed in OFFBOARD) holds its hover setpoint as an offboard stream this long
#: (PX4's offboard-loss failsafe after it, unless the graph's stream took over): a simulation convenience
HOVER_START_WINDOW = 1.5

@dataclass
class SimulationOptions:
    """Timing and networking of the simulator core."""

    physics_rate: float = 1000.0  #: [Hz] fixed step
    control_rate: float = 50.0  #: [Hz] controllers' period used by the lockstep
    lockstep: bool = True
    #: [s] wall: the watchdog of a live setpoint stream that neither delivers nor ends (see the module doc)
    lockstep_timeout: float = 30.0
    lockstep_on_timeout: str = "stop"  #: "stop": raise LockstepStalled; "continue": count it and run on
    local_base_port: int = LOCAL_BASE_PORT  #: UAV i's emulator binds local_base_port + i − 1 (0: ephemeral, tests)
    remote_base_port: int = REMOTE_BASE_PORT  #: ... and sends to remote_base_port + i − 1 (0: only once contacted)
    remote_ports: tuple[int, ...] = ()  #: explicit remote port per UAV (tests); overrides remote_base_port
    #: MAVLink 2 signing key (32 bytes) of every emulated PX4 (None: no signing, PX4's default)
    signing_key: bytes | None = None
    #: [s] a setpoint stamp later than the simulation time by more than this is on a foreign clock (module doc)
    clock_tolerance: float = 0.005
    #: [s] ... and so is one older than this on arrival
    clock_lag_limit: float = 5.0


class Simulation:
    """See the module doc. ``ports`` lists each emulator's bound (local) UDP port, ``remote_ports`` where it sends
    first (0: nowhere until contacted)."""

    def __init__(self, scenario: Scenario, options: SimulationOptions | None = None) -> None:
        self.scenario = scenario
        self.options = options or SimulationOptions()
        if self.options.lockstep_on_timeout not in ("stop", "continue"):
            raise ValueError("lockstep_on_timeout must be 'stop' or 'continue', got "
                             f"{self.options.lockstep_on_timeout!r}")
        if not self.options.lockstep_timeout > 0.0:
            raise ValueError(f"lockstep_timeout must be > 0 s, got {self.options.lockstep_timeout}")
        self.plant = Plant(scenario, dt=1.0 / self.options.physics_rate)
        n = scenario.n
        self.n = n
        truth = self.plant.ground_truth()
        self.sensors = UavSensors(scenario, truth.uav_positions, gravity=self.plant.params.gravity)
        options = self.options
        if options.remote_ports and len(options.remote_ports) != n:
            raise ValueError(f"remote_ports: expected {n} ports, got {list(options.remote_ports)}")
        local_base, remote_base = options.local_base_port, options.remote_base_port
        self.remote_ports = [int(options.remote_ports[i]) if options.remote_ports else
                             ((remote_base + i) if remote_base else 0) for i in range(n)]
        self.emulators = [Px4Emulator(i + 1, scenario.px4, self.sensors.yaw_offsets[i],
                                      local_port=(local_base + i) if local_base else 0,
                                      remote_port=self.remote_ports[i], signing_key=options.signing_key)
                          for i in range(n)]
        self.ports = [e.port for e in self.emulators]
        self._steps_per_control = max(1, int(round(self.options.physics_rate / self.options.control_rate)))
        self._steps_per_px4 = max(1, int(round(self.options.physics_rate / scenario.px4.controller_rate)))
        self._previous_boundary_ms = 0  # T_{k-1} on the PX4 boot clock [ms]
        self._served_ms: list[int | None] = [None] * n  # latest setpoint instant when T_{k-1} was passed [ms]
        self._stream_live = [False] * n  # a new setpoint arrived during the previous control period
        self.lockstep_timeouts = 0
        self.last_timeout = ""  #: the latest timed-out boundary and the UAVs it waited for (one line)
        #: called while the lockstep waits at a boundary, every <= 50 ms, with the wall seconds waited so far (the
        #: simulator node re-publishes /clock: a lost last /clock would otherwise stall every timer on it)
        self.on_lockstep_wait: Callable[[float], None] | None = None
        self.lockstep_waits = 0
        #: per UAV: the link's setpoint stamps are on a foreign clock (module doc): the lockstep does not wait for it
        self.foreign_clock = [False] * n
        self._stamps_checked = [0] * n  # setpoint_latency entries already classified, per UAV
        #: receives one line per notable event (a link on a foreign clock); the simulator node logs it
        self.on_notice: Callable[[str], None] = logging.getLogger("fpr_sim").info
        #: set by a signal handler (the simulator node): the lockstep's wait gives up, the owner's loop ends
        self.stop_requested = False
        self._truth = truth
        self._truth_steps: int | None = None  # plant.steps of ``_truth``; None: recompute (the start changes the plant)
        if scenario.initial_state.mode == "hover" and scenario.initial_state.armed:
            self._start_hovering()
        # PX4 reports its status (battery voltage included) from boot: every stream's first message goes out at
        # t = 0, so a bridge normalizes thrust with the real voltage from the start (no fallback-voltage step).
        self._send_telemetry()

    def _start_hovering(self) -> None:
        """Armed in OFFBOARD with the hover setpoint held (as if the stream had been running)."""
        from fpr_model.dynamics import gravity, thrusts_from_wrench
        from fpr_px4_bridge.px4_protocol import Px4MainMode

        plant = self.plant
        q = plant.state.configuration()
        forces = thrusts_from_wrench(plant.params, q, gravity(plant.params, q))
        quats = plant.default_uav_attitudes(forces)
        f_max = plant.fleet.max_thrust()
        for i, emulator in enumerate(self.emulators):
            emulator.landed = False
            emulator.arm(0.0)  # in the air: taken off (no pre-flight auto-disarm)
            emulator.main_mode, emulator.sub_mode = Px4MainMode.OFFBOARD, 0
            emulator.quat_local = self.sensors.world_to_local_quat(i, quats[i])
            emulator.thrust = float(np.linalg.norm(forces[i]) / f_max[i])
            # the held setpoint counts as a stream for HOVER_START_WINDOW: the graph's own stream (the joy script's
            # ARM + FLY) takes over within it, whatever COM_OF_LOSS_T (0.5 s alone was a start-up race)
            emulator._last_setpoint_time = HOVER_START_WINDOW - emulator.config.offboard_loss_timeout

    # ------------------------------------------------------------------------------------------------
    @property
    def time(self) -> float:
        return self.plant.time

    def close(self) -> None:
        for emulator in self.emulators:
            emulator.close()

    def ground_truth(self) -> GroundTruth:
        """The plant's true state now, evaluated once per physics step: the step's telemetry and the simulator
        node's publishers at the end of a /clock period (ground truth, /tf, motion capture, cameras) share it.
        Only :meth:`step` changes the plant between two calls; the object is read-only to its users."""
        steps = self.plant.steps
        if self._truth_steps != steps:
            self._truth = self.plant.ground_truth()
            self._truth_steps = steps
        return self._truth

    def _landed(self) -> np.ndarray:
        anchors = self.plant.environment.ground.anchors[: self.n, 0]
        return ~np.isnan(anchors)

    def _px4_update(self) -> None:
        t = self.plant.time
        landed = self._landed()
        for emulator in self.emulators:
            emulator.poll(t)
        positions = velocities = None
        if any(e.uses_position_control for e in self.emulators):
            # the position controllers' local position estimate: the true tip states in each F0i (ENU)
            tip_pos, tip_vel = self.plant._tip_kinematics(self.plant._x)
            R, origins = self.sensors.world_to_local_R, self.sensors.origins
            positions = np.einsum("nij,nj->ni", R, tip_pos - origins)
            velocities = np.einsum("nij,nj->ni", R, tip_vel)
        quats, thrusts, armed, feedforward = [], [], [], []
        for i, emulator in enumerate(self.emulators):
            if positions is not None and emulator.uses_position_control:
                setpoint = emulator.update(t, bool(landed[i]), self.plant.fleet.quat[i], positions[i], velocities[i])
            else:
                setpoint = emulator.update(t, bool(landed[i]), self.plant.fleet.quat[i])
            quat = setpoint.quat
            estimate = self.sensors.attitude_estimate_quats(i)
            if estimate is not None and not emulator.flies_body_rates:
                # PX4's attitude law (3.39) acts on its estimate q̂ = q ∘ exp(δ): the true attitude settles at
                # q_d ∘ exp(−δ) (the same equilibrium; the loop's error vector differs by a rotation of δ, second order)
                quat = quat_multiply(quat, estimate[1])
            quats.append(quat)
            thrusts.append(setpoint.thrust)
            armed.append(setpoint.armed)
            feedforward.append(setpoint.rate_feedforward)
        self.plant.set_command(AttitudeCommand(np.array(quats), np.array(thrusts), np.array(armed, dtype=bool),
                                               np.array(feedforward)))

    def _send_telemetry(self) -> None:
        """Every emulator's telemetry due now (each message on its own interval, see :mod:`fpr_sim.px4_emulator`);
        one sensor sample per UAV and instant serves all of its attitude / IMU / position messages."""
        t = self.plant.time
        truth = None
        for i, emulator in enumerate(self.emulators):
            due = emulator.due_messages(t)
            if not due and not emulator.has_requests:
                continue
            if truth is None:
                truth = self.ground_truth()
            sample = None
            if emulator.needs_sample(due):
                sample = self.sensors.sample(i, truth.uav_quats[i], truth.uav_rates[i], truth.uav_specific_forces[i],
                                             truth.uav_positions[i], truth.uav_velocities[i], t=truth.time)
            emulator.send_messages(due, truth.time, sample, float(truth.battery_voltages[i]),
                                   float(truth.battery_remaining[i]), float(self.plant.fleet.battery.current[i]))

    def _expects_setpoint(self, i: int) -> bool:
        """Lockstep waits for UAV i: its stream is live, has not ended, and is on the simulation's clock (module
        doc)."""
        return self._stream_live[i] and not self._on_foreign_clock(i) and self.emulators[i].takes_offboard_setpoints

    def _on_foreign_clock(self, i: int) -> bool:
        """Classify UAV i's new stamped setpoints (module doc, "time base per link"); True once foreign."""
        if self.foreign_clock[i]:
            return True
        latency = self.emulators[i].setpoint_latency
        new = latency.count - self._stamps_checked[i]
        if new <= 0:
            return False
        self._stamps_checked[i] = latency.count
        history = latency.history
        options = self.options
        for k in range(1, min(new, len(history)) + 1):
            arrival, age = history[-k]
            if age < -options.clock_tolerance or age > options.clock_lag_limit:
                self.foreign_clock[i] = True
                stamp = arrival - age
                self.on_notice(
                    f"lockstep: uav{i + 1}'s setpoints carry time_boot_ms {stamp * 1e3:.0f} ms at simulation time "
                    f"{arrival:.3f} s: its client keeps its own clock (MAVSDK, MAVROS, a GCS), not the simulation's; "
                    "the lockstep no longer waits for this link, which runs paced at the simulator's "
                    "real_time_factor")
                return True
        return False

    def _has_new_setpoint(self, i: int) -> bool:
        """UAV i's newest setpoint is new for the current boundary (see the module doc)."""
        stamp = self.emulators[i].setpoint_time_ms
        return stamp is not None and stamp != self._served_ms[i] and stamp > self._previous_boundary_ms

    def _wait_for_setpoints(self) -> None:
        """Lockstep: block until each expected emulator has a setpoint new for this boundary (or timeout)."""
        deadline = time.monotonic() + self.options.lockstep_timeout
        t = self.plant.time
        for i in range(self.n):
            self._on_foreign_clock(i)  # classify what arrived during the period, live streams or not
        expected = [i for i in range(self.n) if self._expects_setpoint(i)]
        while True:
            missing = [self.emulators[i] for i in expected if self.emulators[i].takes_offboard_setpoints
                       and not self._on_foreign_clock(i) and not self._has_new_setpoint(i)]
            if not missing:
                break
            remaining = deadline - time.monotonic()
            if self.stop_requested:
                break
            if remaining <= 0.0:
                self.lockstep_timeouts += 1
                names = ", ".join(f"uav{e.uav_id} ({e.mode_name}, last setpoint at "
                                  f"{'never' if e.setpoint_time_ms is None else f'{e.setpoint_time_ms} ms'})"
                                  for e in missing)
                self.last_timeout = f"t = {t:.3f} s: {names}"
                if self.options.lockstep_on_timeout == "stop":
                    raise LockstepStalled(
                        f"lockstep: no setpoint for t = {t:.3f} s from {names} within {self.options.lockstep_timeout:g}"
                        " s wall: a node of the graph is dead or hung (set lockstep_on_timeout continue to fly on)")
                break
            self.lockstep_waits += 1
            if self.on_lockstep_wait is not None:
                self.on_lockstep_wait(self.options.lockstep_timeout - remaining)
            readable, _, _ = select.select(missing, [], [], min(remaining, 0.05))
            for emulator in readable:
                emulator.poll(t)
        stamps = [e.setpoint_time_ms for e in self.emulators]
        self._stream_live = [stamp is not None and stamp != served
                             for stamp, served in zip(stamps, self._served_ms, strict=True)]
        self._served_ms = stamps
        self._previous_boundary_ms = boot_time_ms(t)

    def setpoint_latency_max(self, start: float = 0.0, end: float = math.inf) -> float:
        """Oldest new setpoint on arrival at its PX4 between ``start`` and ``end`` (simulation time [s]), all
        UAVs [s] (arrival − its stamp; with the lockstep and controllers computing on each boundary's /clock: 0,
        except while a graph that fell behind during a stream-free phase catches up); NaN without any."""
        ages = np.concatenate([e.setpoint_latency.ages_between(start, end) for e in self.emulators])
        return float(ages.max()) if len(ages) else math.nan

    def step(self) -> None:
        """One physics step with the PX4, telemetry and lockstep schedules."""
        k = self.plant.steps
        if self.options.lockstep and k % self._steps_per_control == 0 and k > 0:
            self._wait_for_setpoints()
        if k % self._steps_per_px4 == 0:
            self._px4_update()
        self.plant.step()
        self._send_telemetry()

    def advance(self, duration: float) -> None:
        """Run ``duration`` seconds of simulation time (rounded to whole physics steps)."""
        for _ in range(max(0, int(round(duration * self.options.physics_rate)))):
            self.step()
