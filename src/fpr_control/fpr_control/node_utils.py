"""Small helpers shared by the fpr_control nodes (rclpy side only)."""

from __future__ import annotations

from rcl_interfaces.msg import ParameterDescriptor

LOG_THROTTLE_S = 2.0  # [s] per-cycle warnings: at most one per call site and period


def describe(text: str) -> ParameterDescriptor:
    """ParameterDescriptor with a description (every parameter is declared with one)."""
    return ParameterDescriptor(description=text)
