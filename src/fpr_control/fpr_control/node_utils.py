"""Small helpers shared by the fpr_control nodes (rclpy side only)."""

from __future__ import annotations

import math
import time

from rcl_interfaces.msg import ParameterDescriptor


def describe(text: str) -> ParameterDescriptor:
    """ParameterDescriptor with a description (every parameter is declared with one)."""
    return ParameterDescriptor(description=text)


class RateLimitedLog:
    """At most one warning per key and period [s] (wall clock) — for anything per-cycle."""

    def __init__(self, logger, period: float = 2.0) -> None:
        self.logger, self.period, self._last = logger, period, {}

    def warn(self, key: str, text: str) -> None:
        now = time.monotonic()
        if now - self._last.get(key, -math.inf) >= self.period:
            self._last[key] = now
            self.logger.warning(text)
