"""Node health as REP-107 diagnostics: a ROS-free status report and its diagnostic_msgs/DiagnosticArray form.

Every fpr node that flies the robot (controller, px4_bridge, pose_estimator) publishes, once a second, one
``diagnostic_msgs/DiagnosticArray`` on ``/diagnostics`` holding one ``DiagnosticStatus`` for itself: ``name`` the
node's fully qualified name (e.g. ``/fpr/uav2/controller``), ``hardware_id`` ``uav<i>``, ``level`` OK / WARN /
ERROR / STALE (REP-107's levels), a one-line ``message`` and key/value pairs. That is what rqt_runtime_monitor,
diagnostic_aggregator and Foxglove's diagnostics panel read; the typed per-UAV status topics (``controller_status``,
``status``) stay for the nodes and the experiment metrics.

The message conversion (:func:`to_diagnostic_array`) imports diagnostic_msgs when called, so this module stays
importable without ROS.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

__all__ = ["ERROR", "OK", "STALE", "WARN", "StatusReport", "format_value", "to_diagnostic_array"]

#: REP-107 levels (diagnostic_msgs/DiagnosticStatus)
OK, WARN, ERROR, STALE = 0, 1, 2, 3
LEVEL_NAMES = {OK: "OK", WARN: "WARN", ERROR: "ERROR", STALE: "STALE"}


@dataclass(frozen=True)
class StatusReport:
    """One component's health: ``level`` (OK..STALE), a one-line ``message`` and its key/value pairs."""

    name: str
    level: int
    message: str
    hardware_id: str = ""
    values: Mapping[str, object] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.level not in LEVEL_NAMES:
            raise ValueError(f"level: expected one of {sorted(LEVEL_NAMES)} (REP-107), got {self.level!r}")


def format_value(value: object) -> str:
    """A key/value pair's value as text: floats with 4 significant digits, sequences comma-separated."""
    if isinstance(value, float):
        return "nan" if math.isnan(value) else f"{value:.4g}"
    if isinstance(value, (list, tuple)):
        return ", ".join(format_value(v) for v in value)
    return str(value)


def to_diagnostic_array(reports: Iterable[StatusReport], stamp):
    """diagnostic_msgs/DiagnosticArray of ``reports``, header stamped ``stamp`` (builtin_interfaces/Time)."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    array = DiagnosticArray()
    array.header.stamp = stamp
    for report in reports:
        status = DiagnosticStatus()
        status.level = bytes([report.level])
        status.name, status.message, status.hardware_id = report.name, report.message, report.hardware_id
        status.values = [KeyValue(key=str(k), value=format_value(v)) for k, v in report.values.items()]
        array.status.append(status)
    return array
