"""Scripted gamepad: a YAML timeline of Joy axes and buttons (for tests and demos). No rclpy here.

File format (see config/joy_scripts/*.yaml)::

    axes_count: 8          # length of Joy.axes
    buttons_count: 11      # length of Joy.buttons
    loop: false            # restart at the end
    keyframes:             # sorted by t [s] from the start of the script
      - {t: 0.0, buttons: {0: 1}}          # sparse index: value; unspecified entries keep their value
      - {t: 0.2, buttons: {0: 0}}
      - {t: 2.0, axes: {4: 0.5}, ramp: true}   # ramp: axes move linearly from the previous keyframe's values

Buttons never ramp. Values after the last keyframe hold. Axis values are clamped to [−1, 1].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Keyframe:
    t: float
    axes: dict[int, float]
    buttons: dict[int, int]
    ramp: bool = False


@dataclass(frozen=True)
class JoyTimeline:
    axes_count: int
    buttons_count: int
    keyframes: tuple[Keyframe, ...]
    loop: bool = False

    @property
    def duration(self) -> float:
        return self.keyframes[-1].t if self.keyframes else 0.0

    def _states(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Axes/buttons in force at each keyframe (cumulative)."""
        axes = np.zeros(self.axes_count)
        buttons = np.zeros(self.buttons_count, dtype=int)
        states = []
        for frame in self.keyframes:
            for index, value in frame.axes.items():
                axes[index] = value
            for index, value in frame.buttons.items():
                buttons[index] = value
            states.append((axes.copy(), buttons.copy()))
        return states

    def sample(self, t: float) -> tuple[list[float], list[int]]:
        """Axes and buttons at script time t [s]."""
        if not self.keyframes:
            return [0.0] * self.axes_count, [0] * self.buttons_count
        if self.loop and self.duration > 0.0:
            t = t % self.duration
        states = self._states()
        index = int(np.searchsorted([f.t for f in self.keyframes], t, side="right")) - 1
        if index < 0:
            return [0.0] * self.axes_count, [0] * self.buttons_count
        axes, buttons = states[index]
        if index + 1 < len(self.keyframes) and self.keyframes[index + 1].ramp:
            nxt = self.keyframes[index + 1]
            fraction = (t - self.keyframes[index].t) / (nxt.t - self.keyframes[index].t)
            axes = axes + fraction * (states[index + 1][0] - axes)
        return [float(a) for a in axes], [int(b) for b in buttons]


def timeline_from_dict(d: dict) -> JoyTimeline:
    """Validate and build a timeline from the parsed YAML."""
    axes_count = int(d.get("axes_count", 8))
    buttons_count = int(d.get("buttons_count", 11))
    frames = []
    previous_t = -np.inf
    for raw in d.get("keyframes", []):
        t = float(raw["t"])
        if not t >= previous_t:
            raise ValueError(f"keyframes must be sorted by t (got {t} after {previous_t})")
        previous_t = t
        axes = {int(k): float(np.clip(float(v), -1.0, 1.0)) for k, v in (raw.get("axes") or {}).items()}
        buttons = {int(k): int(bool(v)) for k, v in (raw.get("buttons") or {}).items()}
        for index in axes:
            if not 0 <= index < axes_count:
                raise ValueError(f"axis index {index} outside 0..{axes_count - 1}")
        for index in buttons:
            if not 0 <= index < buttons_count:
                raise ValueError(f"button index {index} outside 0..{buttons_count - 1}")
        if any(not np.isfinite(v) for v in axes.values()):
            raise ValueError("axis values must be finite")
        frames.append(Keyframe(t, axes, buttons, bool(raw.get("ramp", False))))
    return JoyTimeline(axes_count, buttons_count, tuple(frames), bool(d.get("loop", False)))
