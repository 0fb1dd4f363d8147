"""summary.json: the numbers users compare between runs, one schema for `simulate`, `run`, `report` and `sweep`.

Common keys: `controller`, `duration_s`, `transmissions` (an object everywhere: `downlink_msgs`, `downlink_bytes`,
`uplink_msgs`, `uplink_bytes`, and `total_msgs`, `total_bytes` = uplink + downlink, `transmissions_block`), `events_by_reason`, `tracking`, `inter_event_s`, `max_abs_voltage_v`, and `timing`:
every field derived from wall-clock or CPU time (offline `cpu_s`; sessions `wall_s`, `latency_us`,
`latency_samples` and the edge's timing counters). Everything outside `timing` is deterministic (offline always, a
session in lockstep), so two runs compare with `deterministic(a) == deterministic(b)`. docs/session.md lists the keys.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

TIMING_KEY = "timing"

PAPER = {"tt": {"transmissions": 997, "max_abs_error_rad": 0.07},
         "et": {"transmissions": 305, "max_abs_error_rad": 0.075}}


def transmissions_block(downlink_msgs: int, downlink_bytes: int, uplink_msgs: int, uplink_bytes: int
                        ) -> dict[str, int]:
    """summary.json's `transmissions` (and `lead_in`'s counts): each direction and the link total (states up +
    setpoints or voltages down; payload bytes)."""
    return {"downlink_msgs": downlink_msgs, "downlink_bytes": downlink_bytes, "uplink_msgs": uplink_msgs,
            "uplink_bytes": uplink_bytes, "total_msgs": uplink_msgs + downlink_msgs,
            "total_bytes": uplink_bytes + downlink_bytes}


def tracking_block(theta_rad: np.ndarray, desired_rad: np.ndarray) -> dict[str, list[float]]:
    err = theta_rad - desired_rad
    return {"max_abs_error_rad": [float(v) for v in np.abs(err).max(axis=0)],
            "rms_error_rad": [float(v) for v in np.sqrt(np.mean(err ** 2, axis=0))]}


def inter_event_block(event_t_s: np.ndarray) -> dict[str, float]:
    gaps = np.diff(event_t_s)
    if len(gaps) == 0:
        return {"min": 0.0, "median": 0.0, "max": 0.0}
    return {"min": float(gaps.min()), "median": float(np.median(gaps)), "max": float(gaps.max())}


def deterministic(summary: dict[str, Any]) -> dict[str, Any]:
    """The summary without its `timing` blocks (the top-level one and each limb's): what must be identical between
    two lockstep (or offline) runs."""
    out = {k: v for k, v in summary.items() if k != TIMING_KEY}
    if "limbs" in out:
        out["limbs"] = [{k: v for k, v in e.items() if k != TIMING_KEY} for e in out["limbs"]]
    return out


def write_summary(path: Path, summary: dict[str, Any]) -> None:
    path.write_text(json.dumps(summary, indent=2, sort_keys=True) + "\n", encoding="utf-8")


def compare_table(tt: dict[str, Any], et: dict[str, Any]) -> str:
    """Markdown table TT vs ET next to the paper's numbers."""
    def tx(s: dict[str, Any]) -> int:
        return int(s["transmissions"]["downlink_msgs"])

    def mx(s: dict[str, Any]) -> float:
        return max(s["tracking"]["max_abs_error_rad"])

    rows = [
        "| | TT (this run) | ET (this run) | TT (paper) | ET (paper) |",
        "|---|---|---|---|---|",
        f"| transmissions per run | {tx(tt)} | {tx(et)} | {PAPER['tt']['transmissions']} | {PAPER['et']['transmissions']} |",
        f"| ET/TT transmissions | | {tx(et) / max(tx(tt), 1):.3f} | | {305 / 997:.3f} |",
        f"| max abs tracking error [rad] (both joints) | {mx(tt):.4f} | {mx(et):.4f} | ~0.07 | ~0.075 |",
        f"| ET/TT max error | | {mx(et) / mx(tt):.3f} | | {0.075 / 0.07:.3f} |",
    ]
    for j, name in enumerate(("hip", "knee")):
        rows.append(f"| max abs error {name} [rad] | {tt['tracking']['max_abs_error_rad'][j]:.4f} | "
                    f"{et['tracking']['max_abs_error_rad'][j]:.4f} | | |")
        rows.append(f"| rms error {name} [rad] | {tt['tracking']['rms_error_rad'][j]:.4f} | "
                    f"{et['tracking']['rms_error_rad'][j]:.4f} | | |")
    ie_tt, ie_et = tt["inter_event_s"], et["inter_event_s"]
    rows.append(f"| inter-event min/median/max [s] | {ie_tt['min']:.3f}/{ie_tt['median']:.3f}/{ie_tt['max']:.3f} | "
                f"{ie_et['min']:.3f}/{ie_et['median']:.3f}/{ie_et['max']:.3f} | 0.01 | ~0.05 typical, 0.25 max |")
    return "\n".join(rows) + "\n"
