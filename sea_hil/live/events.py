"""What the live view logs on `/live/events` (Foxglove's `foxglove.Log`, JSON form): trigger events and the
driver's state changes and faults. Pure."""
from __future__ import annotations

from typing import Any

from sea_hil.live.channels import LOG_LEVELS
from sea_hil.protocol.can_frames import DriverState, ErrorFlags, Heartbeat

NS_PER_S = 1_000_000_000
_STATE_LEVEL = {DriverState.INIT: "INFO", DriverState.RUNNING: "INFO", DriverState.FAULT: "ERROR",
                DriverState.ESTOP: "FATAL"}


def log_message(t_ns: int, level: str, name: str, message: str) -> dict[str, Any]:
    """One foxglove.Log message (JSON form) stamped `t_ns`."""
    return {"timestamp": {"sec": t_ns // NS_PER_S, "nsec": t_ns % NS_PER_S}, "level": LOG_LEVELS[level],
            "message": message, "name": name, "file": "", "line": 0}


def event_log(t_ns: int, setpoint: dict[str, Any]) -> dict[str, Any] | None:
    """The log line of a trigger event (a setpoint sent for a reason other than the periodic TIME), else None."""
    reason = setpoint["reason"]
    if reason in ("", "TIME"):
        return None
    return log_message(t_ns, "INFO", "controller",
                       f"event: setpoint #{setpoint['seq']} ({reason}) for state #{setpoint['state_seq']}, "
                       f"v_x = ({setpoint['delta1_ref_m']:.6g}, {setpoint['delta2_ref_m']:.6g}) m")


class DriverWatch:
    """Per node: the `/live/driver` message of each heartbeat, and log lines when the state or the error flags
    change (a flag newly set is a WARNING, a state is logged at the level its meaning has)."""

    def __init__(self) -> None:
        self._last: dict[int, tuple[DriverState, ErrorFlags]] = {}

    def on_heartbeat(self, t_ns: int, hb: Heartbeat) -> tuple[dict[str, Any], list[dict[str, Any]]]:
        state, flags = DriverState(hb.state), ErrorFlags(hb.flags)
        msg: dict[str, Any] = {"node_id": hb.node_id, "state": int(state), "state_name": state.name,
                               **{f"err_{(f.name or '').lower()}": bool(flags & f) for f in ErrorFlags},
                               "rejected_frames": hb.rejected_frames, "overruns": hb.overruns, "seq": hb.seq}
        name = f"driver {hb.node_id}"
        prev = self._last.get(hb.node_id)
        self._last[hb.node_id] = (state, flags)
        logs = []
        if prev is None or prev[0] != state:
            was = "" if prev is None else f" (was {prev[0].name})"
            logs.append(log_message(t_ns, _STATE_LEVEL[state], name, f"state {state.name}{was}"))
        new = flags & ~(prev[1] if prev is not None else ErrorFlags(0))
        if new:
            logs.append(log_message(t_ns, "WARNING", name, "error flags set: " + ", ".join(
                (f.name or "") for f in ErrorFlags if new & f) + f" (rejected {hb.rejected_frames}, "
                f"overruns {hb.overruns})"))
        cleared = (prev[1] if prev is not None else ErrorFlags(0)) & ~flags
        if cleared:
            logs.append(log_message(t_ns, "INFO", name, "error flags cleared: " + ", ".join(
                (f.name or "") for f in ErrorFlags if cleared & f)))
        return msg, logs
