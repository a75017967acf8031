"""A scripted human operator (ROS-free), so that the thesis's teleoperated experiments need no human.

The thesis flew §4.4.1 Scenario II (tennis-ball positioning, Table 4.3) and §4.4.2 Scenario I (load pick-up,
Tables 4.6-4.8) by pure teleoperation, "eye-to-platform", and in §4.4.2 Scenario II the operator gave the vertical
speed and the contact force while law (4.39) gave the rest. :class:`Pilot` stands in for that operator: it looks
at the platform (the motion capture stands in for the operator's eyes) with a reaction delay and a position
estimate error, decides a stick position ``update_period`` times a second with a proportional law on the
position error (expressed in the platform's flat frame F_Fp, the frame of the velocity commands (4.25)) plus a
slow trim near the target, adds a tremor, and outputs gamepad axes through the same mapping as a person
(config/teleop.yaml: its dead zones apply to the pilot as to a human — the thesis notes the large dead zone hampers
fine control, l.6780).

The trim is the integral of the position error while P is within ``trim_zone`` of the target (a person who sees
the platform hang 10 cm low holds the stick further up until it climbs; far away they just fly at their own
speed), bounded to ``trim_limit`` and frozen while the asked speed is at ``max_speed`` (no wind-up). It is off by
default (a pure P law: holding a point within 15-20 cm, Tables 4.2 and 4.6) and on in the precise-positioning
script of Table 4.3 (ch4_tennis), whose operator's whole job is to null the last centimetres: the decentralized
controllers of Table 4.1 have no position integral (Kp and Ki '*' for p_p), so with the hardware profile's thrust
deficit a P-only operator left the platform where the asked climb speed equalled the sag, 8-10 cm below every
tennis ball, and no task could succeed (0/7 for both controllers).

A pilot script is a joy script (``keyframes``: buttons and scripted axes, fpr_control.joy_timeline) plus::

    pilot: {reaction_delay: 0.25, horizontal_gain: 0.8, ...}     # PilotConfig fields
    tasks:
      start: 10.0                   # [s] script time the first task begins
      end: 150.0                    # [s] the pilot lets go (the keyframes alone drive the sticks after)
      list:
        - {kind: goto, target: [0.5, 0.3, 2.0], criterion: 0.10, window: 10.0, success_radius: 0.05}
        - {kind: push, force: 5.0, approach_speed: 0.1, duration: 20.0}

Tasks run one after the other inside [start, end]; each ends with a ``task_end`` event (success or not):

- ``goto``: fly the platform centre P to ``target`` [m, world]; once the 3-D error is below ``criterion`` the
  ``window`` [s] opens; success = the error stays below ``success_radius`` for ``settle`` s within it (Table 4.3:
  10 cm / 10 s / 5 cm, l.6700-6712). Failure: the window closes, or ``timeout`` [s] passes before the criterion.
  ``axes`` (default x, y, z) says which velocity channels the pilot drives.
- ``push``: hold the height until P is within ``align_radius`` (horizontally) of ``target`` (the board's target
  point; law (4.39) or the centralized reference aligns it), then climb along a height reference rising at
  ``approach_speed`` (never above ``target``'s height) until the platform is seen touching the board (true
  contact force above ``contact_threshold``), then press the force trigger to ``force`` over ``ramp`` s and hold
  it ``duration`` s with the vertical stick centred, then release it (success = contact was made). A contact seen
  lost while pressing — no contact force and the platform ``contact_loss_distance`` from where it touched (it slid
  off the board), or no contact force for ``contact_loss_time`` — releases the trigger and starts the approach
  again from the board's height (event ``contact_lost``); the force is then held ``duration`` s from the new
  contact.
- ``hold``: keep P at ``target`` for ``duration`` s (success = inside ``success_radius`` at the end).

After the last task and until ``end`` the pilot holds the last target. Everything is seeded.
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

TASK_KINDS = ("goto", "push", "hold")
_CHANNELS = {"x": "velocity_x", "y": "velocity_y", "z": "velocity_z", "yaw": "yaw_rate", "force": "contact_force"}


@dataclass(frozen=True)
class PilotConfig:
    reaction_delay: float = 0.25    #: [s] visuo-motor delay (typical human 0.2-0.3 s)
    update_period: float = 0.1      #: [s] a new stick decision every 100 ms
    horizontal_gain: float = 0.8    #: [1/s] asked platform speed per metre of horizontal error
    vertical_gain: float = 1.0      #: [1/s] ... of vertical error
    max_speed: float = 0.3          #: [m/s] the operator's own speed limit
    perception_noise: float = 0.01  #: [m] 1σ per axis of the operator's position estimate, per decision
    stick_noise: float = 0.03       #: 1σ tremor, fraction of the full stick travel, per decision
    trim_gain: float = 0.0          #: [1/s²] trim speed added per metre·second of position error (0: a pure P law)
    trim_limit: float = 0.15        #: [m/s] bound of the trim, per axis
    trim_zone: float = 0.3          #: [m] the trim integrates only while the 3-D error is below this
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("reaction_delay", "update_period", "horizontal_gain", "vertical_gain", "max_speed",
                     "perception_noise", "stick_noise", "trim_gain", "trim_limit", "trim_zone"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"pilot {name} must be finite and >= 0, got {value}")
        if self.update_period <= 0.0:
            raise ValueError(f"pilot update_period must be > 0, got {self.update_period}")


def _world_to_flat(vector: np.ndarray, yaw: float) -> np.ndarray:
    """A world-frame vector in the platform's flat frame F_Fp (rotated by -yaw about z; (4.25)'s frame)."""
    cos_yaw, sin_yaw = math.cos(yaw), math.sin(yaw)
    return np.array([cos_yaw * vector[0] + sin_yaw * vector[1], -sin_yaw * vector[0] + cos_yaw * vector[1],
                     vector[2]])


@dataclass(frozen=True)
class Channel:
    """One gamepad channel of the teleop mapping (fpr_control config/teleop.yaml)."""

    axis: int
    scale: float          #: command units per unit of axis deflection from ``center``
    center: float = 0.0
    minimum: float = -math.inf
    maximum: float = math.inf

    def axis_value(self, command: float) -> float:
        """The axis position that asks for ``command`` (clamped to the channel's range and to [-1, 1])."""
        command = min(max(command, self.minimum), self.maximum)
        return float(np.clip(self.center + command / self.scale, -1.0, 1.0))


def channels_from_mapping(mapping: dict) -> dict[str, Channel]:
    """The absolute-mode axis channels of a teleop mapping (velocity_x/y/z, yaw_rate, contact_force)."""
    out = {}
    for name in _CHANNELS.values():
        c = (mapping.get("channels") or {}).get(name)
        if not c or "axis" not in c or c.get("mode", "absolute") != "absolute":
            continue
        out[name] = Channel(int(c["axis"]), float(c.get("scale", 1.0)), float(c.get("center", 0.0)),
                            float(c.get("minimum", -math.inf)), float(c.get("maximum", math.inf)))
    return out


@dataclass
class Task:
    kind: str
    target: list[float] = field(default_factory=lambda: [0.0, 0.0, 2.0])  #: [m] world (goto, hold)
    criterion: float = 0.10        #: [m] goto: the window opens below this error
    window: float = 10.0           #: [s] goto: time given once inside the criterion
    success_radius: float = 0.05   #: [m]
    settle: float = 1.0            #: [s] goto: stay inside success_radius this long
    timeout: float = 40.0          #: [s] goto: to reach the criterion
    axes: list[str] = field(default_factory=lambda: ["x", "y", "z"])
    force: float = 5.0             #: [N] push
    ramp: float = 3.0              #: [s] push: trigger ramp
    approach_speed: float = 0.1    #: [m/s] push
    contact_threshold: float = 0.3  #: [N] push: the operator sees the contact
    align_radius: float = math.inf  #: [m] push: climb only while P is this close (horizontally) to ``target``
    duration: float = 10.0         #: [s] push (holding the force), hold
    #: push: while pressing, the contact is seen lost when the platform is ``contact_loss_distance`` [m] from where
    #: it touched without a contact force (it slid off the board), or after ``contact_loss_time`` [s] without one;
    #: the operator then releases the trigger and approaches again (a decentralized impedance pressing on nothing
    #: climbs at force / damping, 0.5 m/s at 5 N). A bounce on the board is neither.
    contact_loss_distance: float = 0.10
    contact_loss_time: float = 1.5
    label: str = ""

    def __post_init__(self) -> None:
        if self.kind not in TASK_KINDS:
            raise ValueError(f"task kind '{self.kind}' is not one of {', '.join(TASK_KINDS)}")
        unknown = sorted(set(self.axes) - set(_CHANNELS))
        if unknown:
            raise ValueError(f"task axes {unknown}: valid are {', '.join(_CHANNELS)}")
        if len(self.target) != 3 or not all(math.isfinite(v) for v in self.target):
            raise ValueError(f"task target must be 3 finite numbers, got {self.target}")
        for name in ("contact_loss_time", "contact_loss_distance"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"task {name} must be positive, got {value}")


@dataclass
class TaskPlan:
    start: float
    end: float
    tasks: list[Task]


def _from_dict(cls, data: Any, path: str):
    from fpr_experiments.catalog import check_keys

    return cls(**check_keys(cls, data, path))


def pilot_from_script(document: dict) -> tuple[PilotConfig, TaskPlan]:
    """The ``pilot`` and ``tasks`` sections of a pilot script (the keyframes are the joy timeline's)."""
    config = _from_dict(PilotConfig, document.get("pilot") or {}, "pilot")
    tasks = document.get("tasks") or {}
    if not isinstance(tasks, dict) or set(tasks) - {"start", "end", "list"}:
        raise ValueError("tasks: expected {start, end, list}")
    plan = TaskPlan(float(tasks.get("start", 0.0)), float(tasks.get("end", math.inf)),
                    [_from_dict(Task, t, f"tasks.list[{k}]") for k, t in enumerate(tasks.get("list") or [])])
    if not plan.end > plan.start:
        raise ValueError(f"tasks: end {plan.end} must be after start {plan.start}")
    return config, plan


@dataclass
class Observation:
    """What the operator sees at an instant: platform centre P [m, world], its yaw [rad], the contact force [N]."""

    t: float
    position: np.ndarray
    yaw: float
    contact_force: float = 0.0


class Pilot:
    """See the module doc. Call :meth:`observe` with every ground-truth sample and :meth:`axes` at the Joy
    rate; :meth:`take_events` returns the task events since the last call."""

    def __init__(self, config: PilotConfig, plan: TaskPlan, channels: dict[str, Channel]) -> None:
        missing = sorted({_CHANNELS[a] for t in plan.tasks for a in t.axes} - set(channels))
        if missing:
            raise ValueError(f"the teleop mapping has no absolute axis channel for {missing}")
        self.config, self.plan, self.channels = config, plan, channels
        self.rng = np.random.default_rng(config.seed)
        self._seen: collections.deque[Observation] = collections.deque(maxlen=2000)
        self._index = -1                  # current task (-1: not started)
        self._task_start = 0.0
        self._window_open: float | None = None
        self._inside_since: float | None = None
        self._contact_at: float | None = None
        self._contact_lost_since: float | None = None
        self._contact_point: np.ndarray | None = None
        self._next_decision = -math.inf
        self._sticks: dict[int, float] = {}
        self._events: list[dict] = []
        self._hold_target: np.ndarray | None = None
        self._z_reference: float | None = None
        self._trim = np.zeros(3)          # [m/s] world frame: the operator's learned stick offset

    # ---- inputs / outputs ---------------------------------------------------------------------------
    def observe(self, observation: Observation) -> None:
        self._seen.append(observation)

    def take_events(self) -> list[dict]:
        events, self._events = self._events, []
        return events

    def _view(self, t: float) -> Observation | None:
        """What the operator has seen by now: the newest sample at least ``reaction_delay`` old."""
        limit = t - self.config.reaction_delay
        chosen = None
        for observation in self._seen:
            if observation.t <= limit + 1e-9:
                chosen = observation
            else:
                break
        return chosen

    def _event(self, t: float, event: str, **values) -> None:
        task = self.plan.tasks[self._index] if 0 <= self._index < len(self.plan.tasks) else None
        self._events.append({"t": round(t, 4), "event": event, "task": self._index + 1,
                             "kind": task.kind if task else None, **values})

    # ---- task logic ---------------------------------------------------------------------------------
    def _start_task(self, t: float, index: int) -> None:
        self._index, self._task_start = index, t
        self._window_open = self._inside_since = self._contact_at = self._contact_lost_since = None
        self._contact_point = self._z_reference = None
        if index < len(self.plan.tasks):
            task = self.plan.tasks[index]
            extra = {"target": list(task.target)} if task.kind in ("goto", "hold") else {}
            if task.kind == "goto":
                extra.update(criterion=task.criterion, success_radius=task.success_radius)
            self._event(t, "task_start", label=task.label, **extra)
            if task.kind in ("goto", "hold"):
                self._hold_target = np.asarray(task.target, dtype=float)

    def _end_task(self, t: float, success: bool, reason: str) -> None:
        self._event(t, "task_end", success=bool(success), reason=reason)
        self._start_task(t, self._index + 1)

    def _progress(self, t: float, seen: Observation) -> None:
        task = self.plan.tasks[self._index]
        elapsed = t - self._task_start
        if task.kind == "goto":
            error = float(np.linalg.norm(seen.position - np.asarray(task.target)))
            if self._window_open is None:
                if error < task.criterion:
                    self._window_open = t
                    self._event(t, "criterion_reached", error=round(error, 4))
                elif elapsed > task.timeout:
                    self._end_task(t, False, f"criterion {task.criterion} m not reached in {task.timeout} s")
                return
            if error < task.success_radius:
                self._inside_since = t if self._inside_since is None else self._inside_since
                if t - self._inside_since >= task.settle:
                    self._end_task(t, True, f"within {task.success_radius} m for {task.settle} s")
                    return
            else:
                self._inside_since = None
            if t - self._window_open > task.window:
                self._end_task(t, False, f"not settled within {task.success_radius} m in the {task.window} s window")
        elif task.kind == "push":
            if self._contact_at is None:
                if seen.contact_force > task.contact_threshold:
                    self._contact_at = t
                    self._contact_point = np.array(seen.position, dtype=float)
                    self._event(t, "contact", force=round(seen.contact_force, 3))
                elif elapsed > task.timeout:
                    self._end_task(t, False, "no contact")
            elif seen.contact_force <= task.contact_threshold:
                self._contact_lost_since = self._contact_lost_since if self._contact_lost_since is not None else t
                moved = float(np.linalg.norm(seen.position - self._contact_point))
                if moved >= task.contact_loss_distance or t - self._contact_lost_since >= task.contact_loss_time:
                    self._event(t, "contact_lost", pressed=round(t - self._contact_at, 3), moved=round(moved, 3))
                    self._contact_at = self._contact_lost_since = None
                    # back down to the board's height (the platform rose off it) and approach again
                    self._z_reference = min(float(seen.position[2]), float(task.target[2]))
            elif t - self._contact_at > task.ramp + task.duration:
                self._end_task(t, True, "force held")
            else:
                self._contact_lost_since = None
        elif task.kind == "hold" and elapsed > task.duration:
            target = np.asarray(task.target)
            self._end_task(t, bool(np.linalg.norm(seen.position - target) < task.success_radius), "held")

    # ---- sticks -------------------------------------------------------------------------------------
    def _decide(self, t: float, seen: Observation) -> dict[int, float]:
        c, rng = self.config, self.rng
        sticks: dict[int, float] = {}
        task = self.plan.tasks[self._index] if self._index < len(self.plan.tasks) else None
        axes = task.axes if task is not None else ["x", "y", "z"]
        if task is not None and task.kind == "push":
            return self._push_sticks(t, seen, task)
        if self._hold_target is None:
            return sticks
        estimate = seen.position + rng.normal(0.0, c.perception_noise, 3)
        error_world = self._hold_target - estimate
        error_flat = _world_to_flat(error_world, seen.yaw)
        velocity = np.array([c.horizontal_gain * error_flat[0], c.horizontal_gain * error_flat[1],
                             c.vertical_gain * error_flat[2]]) + _world_to_flat(self._trim, seen.yaw)
        speed = float(np.linalg.norm(velocity))
        if speed > c.max_speed:
            velocity *= c.max_speed / speed
        elif float(np.linalg.norm(error_world)) < c.trim_zone:
            self._trim = np.clip(self._trim + c.trim_gain * error_world * c.update_period, -c.trim_limit,
                                 c.trim_limit)
        for k, name in enumerate(("x", "y", "z")):
            if name in axes:
                channel = self.channels[_CHANNELS[name]]
                sticks[channel.axis] = float(np.clip(channel.axis_value(velocity[k]) + rng.normal(0.0, c.stick_noise),
                                                     -1.0, 1.0))
        return sticks

    def _push_sticks(self, t: float, seen: Observation, task: Task) -> dict[int, float]:
        """push: hold the height while (4.39) aligns P under the target, then climb along a height reference
        rising at ``approach_speed`` (a person watches the platform rise, not the stick: with the decentralized
        impedance's compliance the same stick climbs slower under an unmodelled load), then the force trigger."""
        c = self.config
        sticks: dict[int, float] = {}
        target = np.asarray(task.target, dtype=float)
        aligned = float(np.linalg.norm(seen.position[:2] - target[:2])) < task.align_radius
        if self._z_reference is None:
            self._z_reference = float(seen.position[2])
        if self._contact_at is None and aligned and self._z_reference < target[2]:
            self._z_reference += task.approach_speed * c.update_period
        if "z" in task.axes:
            if self._contact_at is None:
                speed = c.vertical_gain * (self._z_reference - float(seen.position[2]))
                speed += task.approach_speed if aligned else 0.0
                speed = float(np.clip(speed, -c.max_speed, c.max_speed))
            else:
                speed = 0.0  # in contact: the force command pushes, the stick is centred
            channel = self.channels["velocity_z"]
            sticks[channel.axis] = channel.axis_value(speed)
        if "force" in task.axes:
            since = 0.0 if self._contact_at is None else t - self._contact_at
            force = task.force * min(1.0, since / task.ramp) if task.ramp > 0 else task.force
            sticks[self.channels["contact_force"].axis] = self.channels["contact_force"].axis_value(
                force if self._contact_at is not None else 0.0)
        return sticks

    def axes(self, t: float) -> dict[int, float]:
        """The axes the pilot holds at script time ``t`` (empty outside [start, end]): {axis index: value}."""
        plan = self.plan
        if t < plan.start or t >= plan.end:
            if t >= plan.end and 0 <= self._index < len(plan.tasks):
                self._end_task(t, False, "task time over")
                self._index = len(plan.tasks)
            self._sticks = {}
            return {}
        if self._index < 0:
            self._start_task(t, 0)
        seen = self._view(t)
        if seen is None:
            return dict(self._sticks)
        if self._index < len(plan.tasks):
            self._progress(t, seen)
        if t >= self._next_decision:
            self._next_decision = t + self.config.update_period
            self._sticks = self._decide(t, seen)
        return dict(self._sticks)
