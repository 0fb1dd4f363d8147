"""What a topology's summary.json must share with `sea-hil run --lockstep`'s on the same config (issue 32): every
deterministic field (`sea_hil.report.summary.deterministic`: all but the wall-clock `timing` blocks) but each limb's
bus (the topologies run on an ipc bus or SocketCAN, `run` on its virtual bus), and no figure that is -1 (the
"could not compute" of a report that has no data for it)."""
from __future__ import annotations

from typing import Any

from sea_hil.report.summary import deterministic as summary_deterministic

# a recorder without a CAN tap (the compose recorder: its container is not on the host network) records no voltage
# commands and knows no limb's bus: a deployment fact, not a result
NOT_COMPARED = ("max_abs_voltage_v",)
CAN_COMPLETENESS = ("can_command", "can_frames")


def deterministic(summary: dict[str, Any], *, can: bool = True) -> dict[str, Any]:
    """Every deterministic field but each limb's bus; without `can` also what only a recorder on the CAN bus has."""
    out = dict(summary_deterministic(summary))
    out["limbs"] = [{k: v for k, v in limb.items() if k != "bus"} for limb in out.get("limbs", [])]
    if not can:
        out = {k: v for k, v in out.items() if k not in NOT_COMPARED}
        comp = dict(out["completeness"])
        comp["channels"] = {k: v for k, v in comp["channels"].items() if k not in CAN_COMPLETENESS}
        comp.pop("can_frames_lost")
        out["completeness"] = comp
    return out


def minus_one_figures(value: Any, path: str = "") -> list[str]:
    """Paths of every number equal to -1 in a summary (nested dicts and lists)."""
    if isinstance(value, dict):
        return [p for k, v in value.items() for p in minus_one_figures(v, f"{path}.{k}")]
    if isinstance(value, list):
        return [p for i, v in enumerate(value) for p in minus_one_figures(v, f"{path}[{i}]")]
    return [path] if isinstance(value, (int, float)) and not isinstance(value, bool) and value == -1 else []
