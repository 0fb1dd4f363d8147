"""The `/diagnostics` statuses of the bag export (diagnostic_msgs/DiagnosticStatus as dicts): a driver's HEARTBEAT
(level ERROR in FAULT or ESTOP, WARN with error flags set, else OK) and a set of counters (a node's `/stats`
record, the recorder's final counters: WARN when a loss counter is above zero, its names in the message)."""
from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from sea_hil.protocol.can_frames import DriverState, ErrorFlags, Heartbeat

DIAG_OK, DIAG_WARN, DIAG_ERROR = 0, 1, 2
# a counter whose name holds one of these and is > 0 makes its status WARN
LOSS_MARKS = ("dropped", "lost", "rejected", "overruns", "missed", "errors", "failures")


def hardware_id(node_id: Any) -> str:
    return f"sea-hil drive node {node_id}" if isinstance(node_id, int) else ""


def heartbeat_status(hb: Heartbeat, name: str) -> dict[str, Any]:
    """One driver's HEARTBEAT as a status: state, error flags, its rejected-frame and overrun counts."""
    level = (DIAG_ERROR if hb.state in (DriverState.FAULT, DriverState.ESTOP)
             else DIAG_WARN if hb.flags else DIAG_OK)
    flags = "|".join(f.name or "" for f in ErrorFlags if f & hb.flags) or "none"
    values = {"state": hb.state.name, "error_flags": flags, "rejected_frames": hb.rejected_frames,
              "overruns": hb.overruns, "seq": hb.seq}
    return {"level": level, "name": name, "message": f"{hb.state.name}, error flags {flags}",
            "hardware_id": hardware_id(hb.node_id),
            "values": [{"key": k, "value": str(v)} for k, v in values.items()]}


def counter_status(name: str, values: Mapping[str, Any], hardware: str) -> dict[str, Any]:
    """A set of counters as a status, every one a KeyValue (null -> empty string)."""
    losses = [k for k, v in values.items() if any(mark in k for mark in LOSS_MARKS) and _positive(v)]
    return {"level": DIAG_WARN if losses else DIAG_OK, "name": name,
            "message": f"nonzero: {', '.join(losses)}" if losses else "ok", "hardware_id": hardware,
            "values": [{"key": str(k), "value": "" if v is None else str(v)} for k, v in values.items()]}


def _positive(v: Any) -> bool:
    if isinstance(v, str):
        try:
            v = float(v)
        except ValueError:
            return False
    return isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0
