"""The single exception root of sea-hil. Every error the project raises on purpose derives from SeaHilError."""
from __future__ import annotations

from typing import Any


class SeaHilError(Exception):
    """Root of all sea-hil errors."""


class ConfigError(SeaHilError):
    """A configuration file or CLI option is invalid."""


class TrajectoryError(SeaHilError):
    """A desired trajectory (e.g. a CSV file) is unusable."""


class MalformedFrame(SeaHilError):
    """A CAN frame that cannot be accepted (unknown id, wrong length, out-of-range or NaN value)."""


class MalformedPayload(SeaHilError):
    """A Zenoh payload that cannot be accepted (bad magic/version/type/length, NaN)."""


class BusError(SeaHilError):
    """The CAN interface failed (down, buffer full beyond retries, cannot open)."""


class RecordingError(SeaHilError):
    """An MCAP recording cannot be written or read."""


class Terminated(SeaHilError):
    """The process was asked to stop by a signal (SIGTERM, SIGHUP); raised so that its close path runs. The CLI
    exits with 128 + `signum`, the shell's convention for a process ended by that signal."""

    def __init__(self, signum: int, message: str) -> None:
        super().__init__(message)
        self.signum = signum


class VerdictError(SeaHilError):
    """A strict session (`Session(strict=True)`, the pytest plugin's `sea_session`) ended with a verdict that is not
    ok (docs/verdict.md); `summary` is its summary.json, the message lists the verdict's reasons."""

    def __init__(self, summary: dict[str, Any], message: str) -> None:
        super().__init__(message)
        self.summary = summary
