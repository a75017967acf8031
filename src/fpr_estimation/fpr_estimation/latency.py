"""Detection-latency compensation of the relative-pose filter. ROS-free.

A marker detection describes the relative pose ``p_T_bi`` at its capture instant ``t_c`` (the image's exposure),
but reaches the filter after the camera's readout, the transport and the detection: 40-100 ms on the thesis's
Raspberry Pi cameras (fpr_sim README, "Camera latency"). Applied as if it were current, a detection taken while the
UAV rotates at ω is off by ω·latency: 7° at 2 rad/s and 60 ms, enough for the innovation gate to reject good
detections in a swing and for the estimate to go stale (the decentralized impedance flights of issue 11).

The filter's own process model (thesis (4.10)-(4.13), hypothesis ṗ = 0, the platform still in F0i) says how the
relative pose moves between ``t_c`` and the filter's time ``t``: the position does not, the relative attitude turns
with the UAV only, ``p_R_bi(t) = p_R_bi(t_c) · 0i_R_bi(t_c)ᵀ · 0i_R_bi(t)``. :class:`AttitudeHistory` keeps the
UAV's attitude ``0i_q_bi`` (the IMU messages, PX4's estimate in the local frame F0i) over a short horizon and gives
that rotation ``Δ = 0i_R_bi(t_c)ᵀ · 0i_R_bi(t)``, interpolating the attitude at ``t_c`` (slerp between the two
samples around it). The measurement is carried forward to the filter's time with the model the filter itself
predicts with ("measurement extrapolation": no state history or re-filtering; exact for this model, whose state
transition depends on the IMU only). What the model leaves out (the platform's rotation, the leg motion) is left
to the filter's process noise, as for the prediction.
"""

from __future__ import annotations

from collections import deque

import numpy as np
from fpr_model.rotations import quat_conjugate, quat_from_rotvec, quat_multiply, quat_to_rotmat, quat_to_rotvec

__all__ = ["AttitudeHistory"]


class AttitudeHistory:
    """The UAV attitudes ``0i_q_bi`` [w, x, y, z] of the last ``horizon`` seconds, by stamp [s] (increasing)."""

    def __init__(self, horizon: float) -> None:
        if not (np.isfinite(horizon) and horizon > 0.0):
            raise ValueError(f"latency horizon must be positive and finite, got {horizon}")
        self.horizon = float(horizon)
        self._samples: deque[tuple[float, np.ndarray]] = deque()

    def __len__(self) -> int:
        return len(self._samples)

    @property
    def latest_stamp(self) -> float | None:
        return self._samples[-1][0] if self._samples else None

    @property
    def oldest_stamp(self) -> float | None:
        return self._samples[0][0] if self._samples else None

    def clear(self) -> None:
        self._samples.clear()

    def add(self, stamp: float, quaternion: np.ndarray) -> None:
        """A unit attitude quaternion at ``stamp``; a stamp not after the latest replaces nothing (ignored)."""
        stamp = float(stamp)
        if self._samples and stamp <= self._samples[-1][0]:
            return
        self._samples.append((stamp, np.asarray(quaternion, dtype=float).copy()))
        while len(self._samples) > 2 and self._samples[1][0] <= stamp - self.horizon:
            self._samples.popleft()

    def attitude_at(self, stamp: float) -> np.ndarray | None:
        """``0i_q_bi`` at ``stamp`` (slerp between the samples around it; the latest at or after it); None when
        ``stamp`` is before the oldest sample kept or the history is empty."""
        samples = self._samples
        if not samples or stamp < samples[0][0]:
            return None
        if stamp >= samples[-1][0]:
            return samples[-1][1]
        # newest first: a detection is at most a few IMU periods old
        for index in range(len(samples) - 1, 0, -1):
            before_stamp, before = samples[index - 1]
            if before_stamp <= stamp:
                after_stamp, after = samples[index]
                fraction = (stamp - before_stamp) / (after_stamp - before_stamp)
                if after @ before < 0.0:
                    after = -after
                step = quat_to_rotvec(quat_multiply(quat_conjugate(before), after))
                return quat_multiply(before, quat_from_rotvec(fraction * step))
        return samples[0][1]

    def rotation_since(self, stamp: float) -> np.ndarray | None:
        """``Δ = 0i_R_bi(stamp)ᵀ · 0i_R_bi(latest)`` (3×3): how the UAV body turned from ``stamp`` to the latest
        sample, in body axes at ``stamp``. Identity for a stamp at or after the latest; None when ``stamp`` is older
        than the history (the caller applies the measurement uncompensated and says so)."""
        then = self.attitude_at(stamp)
        if then is None:
            return None
        now = self._samples[-1][1]
        return quat_to_rotmat(quat_multiply(quat_conjugate(then), now))
