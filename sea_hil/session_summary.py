"""summary.json of a networked session, computed from its MCAP recording only, so `sea-hil report` on the same
file reproduces `sea-hil run`'s numbers exactly."""
from __future__ import annotations

from typing import Any

import numpy as np

from protocol.recording import SessionData
from sea_hil.summary import inter_event_block, tracking_block


def _unique(msgs: list, key: str = "seq") -> list[dict[str, Any]]:
    seen: set[Any] = set()
    out = []
    for m in msgs:
        k = (m.payload.get("key"), m.payload.get(key))
        if k not in seen:
            seen.add(k)
            out.append(m.payload)
    return out


def tracking_arrays(data: SessionData) -> dict[str, np.ndarray]:
    rows = _unique(data.messages.get("/tracking", []), "state_seq")
    rows.sort(key=lambda r: r["t_s"])
    t = np.array([r["t_s"] for r in rows])
    theta = np.array([[r["theta1_rad"], r["theta2_rad"]] for r in rows]).reshape(-1, 2)
    desired = np.array([[r["theta1_d_rad"], r["theta2_d_rad"]] for r in rows]).reshape(-1, 2)
    ev_t = np.array([r["t_s"] for r in rows if r.get("event")])
    reasons = [r.get("reason", "") for r in rows if r.get("event")]
    return {"t_s": t, "theta_rad": theta, "desired_rad": desired, "event_t_s": ev_t, "reasons": np.array(reasons)}


def final_edge_stats(data: SessionData) -> dict[str, Any]:
    finals = [m.payload for m in data.messages.get("/stats", []) if m.payload.get("final")]
    return finals[-1] if finals else {}


def session_summary(data: SessionData, controller: str) -> dict[str, Any]:
    tr = tracking_arrays(data)
    down = _unique(data.messages.get("/zenoh/setpoint", [])) + _unique(data.messages.get("/zenoh/voltage", []))
    up = _unique(data.messages.get("/zenoh/state", []))
    volts = [(m.payload.get("u1_v", 0.0), m.payload.get("u2_v", 0.0)) for m in data.messages.get("/can/command", [])]
    v = np.abs(np.array(volts, dtype=float)).max(axis=0) if volts else np.zeros(2)
    edge = final_edge_stats(data)
    reasons: dict[str, int] = {}
    for r in tr["reasons"]:
        reasons[str(r)] = reasons.get(str(r), 0) + 1
    summary: dict[str, Any] = {
        "controller": controller,
        "duration_s": float(tr["t_s"][-1]) if len(tr["t_s"]) else 0.0,
        "transmissions": {"downlink_msgs": len(down), "downlink_bytes": int(sum(d["payload_bytes"] for d in down)),
                          "uplink_msgs": len(up), "uplink_bytes": int(sum(u["payload_bytes"] for u in up))},
        "events_by_reason": dict(sorted(reasons.items())),
        "tracking": tracking_block(tr["theta_rad"], tr["desired_rad"]) if len(tr["t_s"]) else
        {"max_abs_error_rad": [0.0, 0.0], "rms_error_rad": [0.0, 0.0]},
        "inter_event_s": inter_event_block(tr["event_t_s"]),
        "max_abs_voltage_v": [float(v[0]), float(v[1])],
        "latency_us": {k: float(edge.get(f"latency_{k}_us", -1.0)) for k in ("min", "p50", "p90", "p99", "max")},
        "latency_samples": int(edge.get("latency_count", 0)),
        "edge": {k: edge[k] for k in sorted(edge) if not k.startswith("latency") and k not in ("key", "final")},
    }
    return summary


TIMING_FIELDS = ("latency_us", "latency_samples", "wall_s", "edge")  # vary with wall-clock timing
