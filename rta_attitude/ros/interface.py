"""The rclpy side of the ROS vocabulary (`rta_attitude.topics`): QoS profiles and message classes."""

from __future__ import annotations

from typing import Any

from rta_attitude.topics import QosSpec


def qos_profile(spec: QosSpec, lease_s: float = 0.0) -> Any:
    """The rclpy QoSProfile of a QosSpec (imports rclpy); `lease_s` > 0 sets automatic liveliness with
    that lease on specs that have `liveliness` (a reader's requested lease must be >= the writer's, so
    every node of a run uses the same knob)."""
    from rclpy.duration import Duration
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile, ReliabilityPolicy

    keep_all = spec.history == "keep_all"
    profile = QoSProfile(
        history=HistoryPolicy.KEEP_ALL if keep_all else HistoryPolicy.KEEP_LAST,
        depth=max(spec.depth, 1),
        reliability=ReliabilityPolicy.RELIABLE if spec.reliability == "reliable" else ReliabilityPolicy.BEST_EFFORT,
        durability=(DurabilityPolicy.TRANSIENT_LOCAL if spec.durability == "transient_local"
                    else DurabilityPolicy.VOLATILE),
    )
    if spec.liveliness and lease_s > 0:
        profile.liveliness = LivelinessPolicy.AUTOMATIC
        profile.liveliness_lease_duration = Duration(nanoseconds=round(lease_s * 1e9))
    return profile


def msg_class(type_name: str) -> Any:
    """The rclpy message class of `pkg/msg/Type` (imports the message package)."""
    import importlib

    pkg, _, name = type_name.split("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


__all__ = ["msg_class", "qos_profile"]
