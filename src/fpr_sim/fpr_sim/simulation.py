"""The simulator core (ROS-free): plant + one PX4 emulator per UAV + sensors, with lockstep (DESIGN.md §5).

Time base: the plant's fixed step (1 ms). Each step: the emulators read MAVLink and run their mode logic at the
PX4 controller rate (250 Hz) and feed the attitude controllers; telemetry goes out at ``telemetry_rate`` and
status at ``status_rate`` (simulation time).

Lockstep: at every control-period boundary (``control_rate``, 50 Hz) the simulation does not advance until every
ARMED UAV's emulator has received a new setpoint since the previous boundary, or ``lockstep_timeout`` wall
seconds passed (then :attr:`Simulation.lockstep_timeouts` is incremented). Results then do not depend on the
machine's speed. ``lockstep = False`` never waits.
"""

from __future__ import annotations

import select
import time
from dataclasses import dataclass

import numpy as np

from fpr_sim.plant import GroundTruth, Plant
from fpr_sim.px4_emulator import Px4Emulator
from fpr_sim.quadrotor import AttitudeCommand
from fpr_sim.scenario import Scenario
from fpr_sim.sensors import UavSensors

__all__ = ["Simulation", "SimulationOptions"]


@dataclass
class SimulationOptions:
    """Timing and networking of the simulator core."""

    physics_rate: float = 1000.0  #: [Hz] fixed step
    control_rate: float = 50.0  #: [Hz] controllers' period used by the lockstep
    lockstep: bool = True
    lockstep_timeout: float = 0.5  #: [s] wall-clock wait per control period before giving up
    base_port: int = 14540  #: UAV i listens on base_port + i − 1 (0: ephemeral ports, tests)


class Simulation:
    """See the module doc. ``ports`` (after construction) lists each emulator's UDP port."""

    def __init__(self, scenario: Scenario, options: SimulationOptions | None = None) -> None:
        self.scenario = scenario
        self.options = options or SimulationOptions()
        self.plant = Plant(scenario, dt=1.0 / self.options.physics_rate)
        n = scenario.n
        self.n = n
        truth = self.plant.ground_truth()
        self.sensors = UavSensors(scenario, truth.uav_positions)
        base = self.options.base_port
        self.emulators = [Px4Emulator(i + 1, scenario.px4, self.sensors.yaw_offsets[i],
                                      port=(base + i) if base else 0) for i in range(n)]
        self.ports = [e.port for e in self.emulators]
        self._steps_per_control = max(1, int(round(self.options.physics_rate / self.options.control_rate)))
        self._steps_per_px4 = max(1, int(round(self.options.physics_rate / scenario.px4.controller_rate)))
        self._steps_per_telemetry = max(1, int(round(self.options.physics_rate / scenario.px4.telemetry_rate)))
        self._steps_per_status = max(1, int(round(self.options.physics_rate / scenario.px4.status_rate)))
        self._boundary_counts = [0] * n
        self.lockstep_timeouts = 0
        self.lockstep_waits = 0
        self._truth = truth
        if scenario.initial_state.mode == "hover" and scenario.initial_state.armed:
            self._start_hovering()

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
            emulator.armed = True
            emulator.main_mode, emulator.sub_mode = Px4MainMode.OFFBOARD, 0
            emulator.quat_local = self.sensors.world_to_local_quat(i, quats[i])
            emulator.thrust = float(np.linalg.norm(forces[i]) / f_max[i])
            emulator._last_setpoint_time = 0.0
            emulator._stream_start = -emulator.config.offboard_warmup
            emulator.landed = False

    # ------------------------------------------------------------------------------------------------
    @property
    def time(self) -> float:
        return self.plant.time

    def close(self) -> None:
        for emulator in self.emulators:
            emulator.close()

    def ground_truth(self) -> GroundTruth:
        return self.plant.ground_truth()

    def _landed(self) -> np.ndarray:
        anchors = self.plant.environment.ground.anchors[: self.n, 0]
        return ~np.isnan(anchors)

    def _px4_update(self) -> None:
        t = self.plant.time
        landed = self._landed()
        quats, thrusts, armed, feedforward = [], [], [], []
        for i, emulator in enumerate(self.emulators):
            emulator.poll(t)
            setpoint = emulator.update(t, bool(landed[i]), self.plant.fleet.quat[i])
            quats.append(setpoint.quat)
            thrusts.append(setpoint.thrust)
            armed.append(setpoint.armed)
            feedforward.append(setpoint.rate_feedforward)
        self.plant.set_command(AttitudeCommand(np.array(quats), np.array(thrusts), np.array(armed, dtype=bool),
                                               np.array(feedforward)))

    def _send_telemetry(self, status: bool) -> None:
        truth = self.plant.ground_truth()
        self._truth = truth
        battery = self.plant.fleet.battery
        for i, emulator in enumerate(self.emulators):
            sample = self.sensors.sample(i, truth.uav_quats[i], truth.uav_rates[i], truth.uav_specific_forces[i],
                                         truth.uav_positions[i], truth.uav_velocities[i])
            emulator.send_telemetry(sample)
            if status:
                emulator.send_status(float(truth.battery_voltages[i]), float(truth.battery_remaining[i]),
                                     float(battery.current[i]))

    def _wait_for_setpoints(self) -> None:
        """Lockstep: block until each armed emulator got a setpoint since the last boundary (or timeout)."""
        deadline = time.monotonic() + self.options.lockstep_timeout
        t = self.plant.time
        while True:
            missing = [e for i, e in enumerate(self.emulators)
                       if e.armed and e.counters.setpoints <= self._boundary_counts[i]]
            if not missing:
                break
            remaining = deadline - time.monotonic()
            if remaining <= 0.0:
                self.lockstep_timeouts += 1
                break
            self.lockstep_waits += 1
            readable, _, _ = select.select(missing, [], [], min(remaining, 0.05))
            for emulator in readable:
                emulator.poll(t)
        self._boundary_counts = [e.counters.setpoints for e in self.emulators]

    def step(self) -> None:
        """One physics step with the PX4, telemetry and lockstep schedules."""
        k = self.plant.steps
        if self.options.lockstep and k % self._steps_per_control == 0 and k > 0:
            self._wait_for_setpoints()
        if k % self._steps_per_px4 == 0:
            self._px4_update()
        self.plant.step()
        k += 1
        if k % self._steps_per_telemetry == 0:
            self._send_telemetry(status=k % self._steps_per_status == 0)

    def advance(self, duration: float) -> None:
        """Run ``duration`` seconds of simulation time (rounded to whole physics steps)."""
        for _ in range(max(0, int(round(duration * self.options.physics_rate)))):
            self.step()
