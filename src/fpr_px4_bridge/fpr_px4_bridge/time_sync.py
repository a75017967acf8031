"""Map the autopilot's time since boot (``time_boot_ms``) onto the local ROS clock (ROS-free).

``t_local = t_boot + offset``, with the offset estimated as the minimum of ``t_received − t_boot`` over a
sliding window of samples: transport and scheduling delays only add to a sample, so the least-delayed one is
the best estimate, and the window lets the estimate follow clock drift. Works with wall time and with
simulation time (``use_sim_time``), since both clocks are just the ``t_received`` the caller passes in.

The inverse, :meth:`BootTimeMapper.to_boot`, puts a local instant on the autopilot's boot clock: the bridge
stamps each SET_ATTITUDE_TARGET with its setpoint's own instant that way (see :mod:`fpr_px4_bridge.bridge`).

The estimate restarts when the autopilot reboots (``t_boot`` jumps back) or the local clock jumps back (a
simulation reset), so stamps never come out of an old epoch.

:class:`SimulationBootClock` is the exact mapping for a simulated autopilot whose boot clock IS the simulation
time (PX4 SITL in lockstep, fpr_sim's emulator: boot at t = 0): offset 0, no estimate. The minimum-delay estimator
is biased there whenever the receiving node's /clock lags the simulation (a sample then looks "early"), which
shifted setpoint stamps by up to a period and could make two new setpoints look like one to the lockstep.
"""

from __future__ import annotations

from collections import deque

__all__ = ["BootTimeMapper", "SimulationBootClock"]


class BootTimeMapper:
    """Sliding-window minimum offset between an autopilot's boot clock and the local clock, both in seconds."""

    def __init__(self, window: int = 200, reset_threshold: float = 1.0) -> None:
        if window < 1:
            raise ValueError("window must be >= 1")
        self.window = int(window)
        self.reset_threshold = float(reset_threshold)
        self._samples: deque[tuple[int, float]] = deque()  # (index, offset), increasing offsets (monotonic)
        self._index = 0
        self._last_boot: float | None = None
        self.resets = 0

    def reset(self) -> None:
        self._samples.clear()
        self._last_boot = None

    @property
    def offset(self) -> float | None:
        """Current estimate of ``t_local − t_boot`` [s], None before the first sample."""
        return self._samples[0][1] if self._samples else None

    def update(self, boot_time: float, received_time: float) -> None:
        """Add a sample: the message stamped ``boot_time`` (autopilot boot clock) arrived at ``received_time``."""
        if self._last_boot is not None and boot_time < self._last_boot - self.reset_threshold:
            self.reset()
            self.resets += 1
        sample = received_time - boot_time
        current = self.offset
        if current is not None and sample < current - self.reset_threshold:
            self.reset()  # the local clock jumped back (e.g. the simulation restarted)
            self.resets += 1
        self._last_boot = boot_time
        self._index += 1
        samples = self._samples
        while samples and samples[-1][1] >= sample:
            samples.pop()
        samples.append((self._index, sample))
        while samples[0][0] <= self._index - self.window:
            samples.popleft()

    def to_local(self, boot_time: float, fallback: float) -> float:
        """Local time of the autopilot instant ``boot_time``; ``fallback`` (e.g. the receive time) before any sample."""
        offset = self.offset
        return fallback if offset is None else boot_time + offset

    def to_boot(self, local_time: float) -> float | None:
        """The autopilot boot-clock instant [s] of the local instant ``local_time``; None before any sample."""
        offset = self.offset
        return None if offset is None else local_time - offset


class SimulationBootClock(BootTimeMapper):
    """The autopilot's boot clock is the local (simulated) clock: ``t_local = t_boot`` (see the module doc)."""

    @property
    def offset(self) -> float:
        return 0.0

    def update(self, boot_time: float, received_time: float) -> None:
        """Nothing to estimate."""
