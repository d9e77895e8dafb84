"""Exceptions of rta_attitude: one base class, a few children, one-line messages."""

from __future__ import annotations


class RtaError(Exception):
    """Base of every error rta_attitude raises on purpose."""


class ConfigError(RtaError):
    """A configuration file, key, type or value is wrong (the message names which)."""


class SolverError(RtaError):
    """The filter's QP could not be solved and the fallback policy is `raise`."""


class MessageError(RtaError):
    """A ROS message or bag record is malformed (NaN, wrong length or names, bad stamp)."""


class BagError(RtaError):
    """An MCAP bag cannot be written or read (missing, empty, truncated, foreign)."""


class OutputError(RtaError):
    """An output file or directory cannot be created or written (the message names the path and why)."""


__all__ = ["BagError", "ConfigError", "MessageError", "OutputError", "RtaError", "SolverError"]
