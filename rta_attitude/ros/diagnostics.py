"""Status on /diagnostics, the topic rqt_robot_monitor and the diagnostic aggregator read.

Each node keeps one DiagnosticStatus named `<node's full name>: <what>` (e.g. `/rta/asif_filter:
filter`, `/rta/plant: run`) with a level that means something: OK, WARN (the filter intervenes with
slack on a soft constraint; the plant has an active fault episode, e.g. deadline misses), ERROR (the
filter fell back; the run failed). It is published when its level or message changes and otherwise
at most once per `period_s` of wall time (1 Hz by default, as diagnostic_updater does), so the
per-step topics (filter_status, run_status) stay the full record and /diagnostics stays cheap.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from rta_attitude import topics
from rta_attitude.ros import interface

OK, WARN, ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR
DEFAULT_PERIOD_S = 1.0


class DiagnosticsPublisher:
    """One node's status on /diagnostics (see the module docstring)."""

    def __init__(self, node: Any, what: str, period_s: float = DEFAULT_PERIOD_S) -> None:
        self.name = f"{node.get_fully_qualified_name()}: {what}"
        self.period_s = period_s
        self.pub = node.create_publisher(DiagnosticArray, topics.DIAGNOSTICS,
                                         interface.qos_profile(topics.DIAGNOSTICS_QOS))
        self.node = node
        self.last: tuple[bytes, str] | None = None
        self.last_wall_s = -float("inf")
        self.published = 0

    def update(self, level: bytes, message: str, values: Mapping[str, Any], stamp_ns: int) -> bool:
        """Publish if the level or message changed or `period_s` has passed; returns whether it did."""
        now = time.monotonic()
        if (level, message) == self.last and now - self.last_wall_s < self.period_s:
            return False
        status = DiagnosticStatus(level=level, name=self.name, message=message,
                                  hardware_id=topics.STATUS_HARDWARE_ID,
                                  values=[KeyValue(key=k, value=str(v)) for k, v in values.items()])
        msg = DiagnosticArray(status=[status])
        sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
        msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
        self.pub.publish(msg)
        self.last, self.last_wall_s = (level, message), now
        self.published += 1
        return True


def filter_level(status: str, fallback: str, slack_active: bool) -> tuple[bytes, str]:
    """The filter's /diagnostics level and message from one call's outcome."""
    if status == "fallback":
        return ERROR, f"fallback: {fallback}"
    if slack_active:
        return WARN, "intervening with slack on a soft constraint"
    return OK, "intervening" if status == "solved" else "passing u_des through"


def run_level(run_state: str, faults: int) -> tuple[bytes, str]:
    """The plant's /diagnostics level and message from its run state and active fault episodes."""
    if run_state.startswith(topics.RUN_FAILED):
        return ERROR, run_state
    if faults:
        return WARN, f"{run_state}; {faults} fault episode(s) active"
    return OK, run_state


__all__ = ["DEFAULT_PERIOD_S", "ERROR", "OK", "WARN", "DiagnosticsPublisher", "filter_level", "run_level"]
