"""Fault bookkeeping of the nodes: counters, and one log line per fault *episode*, not per message.

A node reports every bad or missing input with `FaultLog.fault(kind, detail)`: the counter of that
kind goes up by one each time, but only the first occurrence of an episode is logged (a warning
naming the kind and the first offending value); `clear(kind)` ends the episode when the input is
good again, with one info line saying how many occurred in it. A stream of 1000 NaN states is one
warning and one info line, and 1000 in the counter that `filter_status` (or `run_status`) publishes.

`StampOrder` classifies the stamps of one stream: new, duplicate (equal to the newest taken) or out
of order (older than it).

Pure Python (no rclpy): the logger is anything with `warning(str)` and `info(str)`.
"""

from __future__ import annotations

from collections.abc import Callable, MutableMapping
from typing import Protocol


class Logger(Protocol):
    """What FaultLog needs of a logger (rclpy's node logger has it)."""

    def warning(self, message: str) -> object: ...

    def info(self, message: str) -> object: ...


class FaultLog:
    """Counters by kind, logged once per episode.

    Args:
        logger: where the episode lines go.
        counts: the counter mapping to increment (kind -> count); a new dict if omitted. Kinds that
            are missing start at 0.
        on_change: called with (kind, active) when an episode starts (True) or ends (False).
    """

    def __init__(self, logger: Logger, counts: MutableMapping[str, int] | None = None,
                 on_change: Callable[[str, bool], None] | None = None) -> None:
        self.logger = logger
        self.counts: MutableMapping[str, int] = counts if counts is not None else {}
        self.on_change = on_change
        self.active: dict[str, int] = {}
        """Kinds in an episode now -> occurrences in it."""
        self.episodes: dict[str, int] = {}
        """Kind -> episodes so far (= warning lines logged for it)."""

    def fault(self, kind: str, detail: str) -> None:
        """Count one occurrence of `kind`; log it if it starts an episode."""
        self.counts[kind] = self.counts.get(kind, 0) + 1
        if kind in self.active:
            self.active[kind] += 1
            return
        self.active[kind] = 1
        self.episodes[kind] = self.episodes.get(kind, 0) + 1
        self.logger.warning(f"{kind}: {detail} (counted; logged again only after it clears)")
        if self.on_change is not None:
            self.on_change(kind, True)

    def clear(self, *kinds: str) -> None:
        """End the episodes of `kinds` that are active (one info line each)."""
        for kind in kinds:
            n = self.active.pop(kind, None)
            if n is None:
                continue
            self.logger.info(f"{kind}: cleared after {n} in a row ({self.counts.get(kind, 0)} in total)")
            if self.on_change is not None:
                self.on_change(kind, False)

    def summary(self) -> str:
        """'kind n, kind n' of the non-zero counters (sorted), or 'none'."""
        return ", ".join(f"{k} {n}" for k, n in sorted(self.counts.items()) if n) or "none"


class StampOrder:
    """The stamp order of one stream: each stamp must be newer than the newest taken."""

    def __init__(self) -> None:
        self.newest_ns: int | None = None

    def check(self, t_ns: int) -> str:
        """'' if t_ns is newer than every stamp taken, else 'duplicate' (equal) or 'out_of_order' (older)."""
        if self.newest_ns is None or t_ns > self.newest_ns:
            return ""
        return "duplicate" if t_ns == self.newest_ns else "out_of_order"

    def take(self, t_ns: int) -> None:
        """Record t_ns as taken (the newest from now on if it is newer)."""
        if self.newest_ns is None or t_ns > self.newest_ns:
            self.newest_ns = t_ns

    def reset(self) -> None:
        """Forget every stamp taken (the clock started over: any stamp is new again)."""
        self.newest_ns = None


__all__ = ["FaultLog", "Logger", "StampOrder"]
