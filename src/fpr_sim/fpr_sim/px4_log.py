"""What the emulated PX4s received and did, as a CSV flight log (ROS-free): the fault-injection evidence.

Every SET_ATTITUDE_TARGET an emulator takes in (addressed to it, before any validation: the raw normalized
thrust and quaternion as they came off MAVLink) is one ``setpoint`` row; every change of an emulator's arming
state or mode is one ``mode`` row. Times are simulation time [s]. A multi-process test cannot reach into the
simulator's emulators, so the simulator node writes this file (parameter ``px4_log_file``) and the test reads it
back with :func:`read_px4_log`. Columns::

    t, uav, event, thrust, qw, qx, qy, qz, mode, armed

``setpoint`` rows leave ``mode``/``armed`` empty; ``mode`` rows leave the thrust and quaternion empty.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Px4Log", "Px4LogData", "read_px4_log"]

_COLUMNS = ("t", "uav", "event", "thrust", "qw", "qx", "qy", "qz", "mode", "armed")


class Px4Log:
    """Attach to the emulators of a :class:`~fpr_sim.simulation.Simulation`; call :meth:`sample` after each
    step (mode rows) and :meth:`close` at the end. Lines are flushed at most every ``flush_every`` rows and at
    close, so a test reading the file after a SIGTERM of the simulator sees all of it."""

    def __init__(self, path: str, emulators: Sequence, flush_every: int = 200) -> None:
        self._stream = open(path, "w", encoding="utf-8", newline="")  # noqa: SIM115 - closed in close()
        self._writer = csv.writer(self._stream)
        self._writer.writerow(_COLUMNS)
        self._emulators = list(emulators)
        self._states: list[tuple[bool, str] | None] = [None] * len(self._emulators)
        self._rows = 0
        self._flush_every = max(1, int(flush_every))
        for emulator in self._emulators:
            emulator.input_log = self._on_attitude_target

    def _row(self, values) -> None:
        self._writer.writerow(values)
        self._rows += 1
        if self._rows % self._flush_every == 0:
            self._stream.flush()

    def _on_attitude_target(self, t: float, uav_id: int, thrust: float, q) -> None:
        self._row((f"{t:.4f}", uav_id, "setpoint", repr(float(thrust)), *(repr(float(v)) for v in q), "", ""))

    def sample(self, t: float) -> None:
        """Write a ``mode`` row for every emulator whose (armed, mode) changed since the last call."""
        for k, emulator in enumerate(self._emulators):
            state = (bool(emulator.armed), str(emulator.mode_name))
            if state != self._states[k]:
                self._states[k] = state
                self._row((f"{t:.4f}", emulator.uav_id, "mode", "", "", "", "", "", state[1], int(state[0])))

    def close(self) -> None:
        if not self._stream.closed:
            self._stream.flush()
            self._stream.close()
        for emulator in self._emulators:
            emulator.input_log = None


@dataclass
class Px4LogData:
    """:func:`read_px4_log`'s result, per UAV id."""

    setpoint_t: dict[int, np.ndarray] = field(default_factory=dict)       #: [s]
    setpoint_thrust: dict[int, np.ndarray] = field(default_factory=dict)  #: raw normalized thrust as received
    mode_t: dict[int, np.ndarray] = field(default_factory=dict)           #: [s] of each change
    modes: dict[int, list[str]] = field(default_factory=dict)             #: PX4 mode names after each change
    armed: dict[int, np.ndarray] = field(default_factory=dict)            #: bool after each change

    def armed_at(self, uav_id: int, t: float) -> bool:
        """Arming state of UAV ``uav_id`` at simulation time ``t`` (False before the first row)."""
        times = self.mode_t.get(uav_id, np.zeros(0))
        k = int(np.searchsorted(times, t, side="right")) - 1
        return bool(self.armed[uav_id][k]) if k >= 0 else False

    def disarm_time(self, uav_id: int, after: float) -> float:
        """First simulation time > ``after`` at which UAV ``uav_id`` is disarmed and stays so; NaN if never."""
        times, armed = self.mode_t.get(uav_id, np.zeros(0)), self.armed.get(uav_id, np.zeros(0, bool))
        candidate = math.nan if self.armed_at(uav_id, after) else float(after)
        for t, a in zip(times, armed, strict=True):
            if t <= after:
                continue
            if a:
                candidate = math.nan
            elif math.isnan(candidate):
                candidate = float(t)
        return candidate


def read_px4_log(path: str) -> Px4LogData:
    """Parse a :class:`Px4Log` file (a truncated last line, from a killed writer, is skipped)."""
    data = Px4LogData()
    setpoints: dict[int, list[tuple[float, float]]] = {}
    modes: dict[int, list[tuple[float, str, bool]]] = {}
    with open(path, encoding="utf-8", newline="") as stream:
        for row in csv.DictReader(stream):
            try:
                t, uav = float(row["t"]), int(row["uav"])
                if row["event"] == "setpoint":
                    setpoints.setdefault(uav, []).append((t, float(row["thrust"])))
                elif row["event"] == "mode":
                    modes.setdefault(uav, []).append((t, row["mode"], bool(int(row["armed"]))))
            except (TypeError, ValueError, KeyError):
                continue
    for uav, rows in setpoints.items():
        data.setpoint_t[uav] = np.array([r[0] for r in rows])
        data.setpoint_thrust[uav] = np.array([r[1] for r in rows])
    for uav, rows in modes.items():
        data.mode_t[uav] = np.array([r[0] for r in rows])
        data.modes[uav] = [r[1] for r in rows]
        data.armed[uav] = np.array([r[2] for r in rows], dtype=bool)
    return data
