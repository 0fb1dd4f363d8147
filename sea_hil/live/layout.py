"""The Foxglove layout shipped as docs/foxglove/sea-hil-layout.json, built from the live channels.

Foxglove's layout file format (File > Import layout, or Layouts > Import from file): `configById` (one entry per
panel, `Type!id`), `layout` (the mosaic tree), `globalVariables`, `userNodes`, `playbackConfig`. Three tabs:
Tracking (hip and knee angles against their references, tracking errors, setpoints), Events (the event/fault log,
trigger reasons, driver state and the verdict over time, the running verdict, the last driver heartbeat and node
statistics) and Link (latency, bandwidth, message rates, CAN bus load). Regenerate with `python -m sea_hil.live.layout docs/foxglove/sea-hil-layout.json`;
tests/test_live_view.py checks that the file is this output and that every path names a live field.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

FOLLOW_S = 10.0   # the plots follow the newest data over this many seconds


def _plot(title: str, series: list[tuple[str, str]], follow_s: float = FOLLOW_S) -> dict[str, Any]:
    return {"foxglovePanelTitle": title, "paths": [
        {"value": path, "enabled": True, "timestampMethod": "receiveTime", "label": label} for path, label in series],
        "showXAxisLabels": True, "showYAxisLabels": True, "showLegend": True, "legendDisplay": "floating",
        "showPlotValuesInLegend": True, "isSynced": True, "xAxisVal": "timestamp", "followingViewWidth": follow_s}


def _raw(title: str, topic: str) -> dict[str, Any]:
    return {"foxglovePanelTitle": title, "topicPath": topic, "diffEnabled": False, "diffMethod": "custom",
            "diffTopicPath": "", "showFullMessageForDiff": False, "expansion": "all"}


def _split(first: Any, second: Any, direction: str = "row", pct: float = 50) -> dict[str, Any]:
    return {"first": first, "second": second, "direction": direction, "splitPercentage": pct}


def build() -> dict[str, Any]:
    cfg: dict[str, dict[str, Any]] = {
        "Plot!hip": _plot("Hip: angle and reference (rad)", [("/live/tracking.theta1_rad", "theta1"),
                                                              ("/live/tracking.theta1_d_rad", "theta1_d")]),
        "Plot!knee": _plot("Knee: angle and reference (rad)", [("/live/tracking.theta2_rad", "theta2"),
                                                                ("/live/tracking.theta2_d_rad", "theta2_d")]),
        "Plot!error": _plot("Tracking error e = theta_d - theta (rad)", [("/live/tracking.e1_rad", "e1 hip"),
                                                                         ("/live/tracking.e2_rad", "e2 knee")]),
        "Plot!setpoint": _plot("Setpoints v_x(t_i) (m), on events", [("/live/setpoint.delta1_ref_m", "hip"),
                                                                     ("/live/setpoint.delta2_ref_m", "knee")]),
        "Log!events": {"foxglovePanelTitle": "Events and faults", "searchTerms": [], "minLogLevel": 1,
                       "topicToRender": "/live/events"},
        "StateTransitions!states": {"foxglovePanelTitle": "Trigger reason and driver state", "isSynced": True,
                                    "paths": [{"value": "/live/setpoint.reason", "timestampMethod": "receiveTime",
                                               "label": "trigger reason"},
                                              {"value": "/live/driver.state_name", "timestampMethod": "receiveTime",
                                               "label": "driver state"},
                                              {"value": "/live/verdict.status", "timestampMethod": "receiveTime",
                                               "label": "verdict"}]},
        "RawMessages!verdict": _raw("Verdict (running; final at the end)", "/live/verdict"),
        "RawMessages!driver": _raw("Driver heartbeat", "/live/driver"),
        "RawMessages!stats": _raw("Node statistics", "/live/node_stats"),
        "Plot!latency": _plot("State -> setpoint round trip at the recorder (us)", [
            ("/live/link.rtt_last_us", "last"), ("/live/link.rtt_p50_us", "p50"), ("/live/link.rtt_p99_us", "p99")]),
        "Plot!bandwidth": _plot("Zenoh bandwidth (bytes/s)", [("/live/link.up_bytes_per_s", "up (state)"),
                                                              ("/live/link.down_bytes_per_s", "down (setpoints)")]),
        "Plot!rates": _plot("Zenoh messages/s", [("/live/link.up_msgs_per_s", "up"),
                                                 ("/live/link.down_msgs_per_s", "down")]),
        "Plot!bus": _plot("CAN bus load (%)", [("/live/bus.load_pct", "window"),
                                               ("/live/bus.load_pct_session", "session")]),
    }
    tabs = [
        ("Tracking", _split(_split("Plot!hip", "Plot!knee", "column"),
                            _split("Plot!error", "Plot!setpoint", "column"))),
        ("Events", _split("Log!events", _split("StateTransitions!states",
                                                _split("RawMessages!verdict", _split("RawMessages!driver", "RawMessages!stats")),
                                                "column", 40))),
        ("Link", _split(_split("Plot!latency", "Plot!bus", "column"), _split("Plot!bandwidth", "Plot!rates",
                                                                             "column"))),
    ]
    cfg["Tab!main"] = {"activeTabIdx": 0, "tabs": [{"title": t, "layout": lay} for t, lay in tabs]}
    return {"configById": cfg, "globalVariables": {}, "userNodes": {}, "playbackConfig": {"speed": 1.0},
            "layout": "Tab!main"}


def text() -> str:
    return json.dumps(build(), indent=2) + "\n"


if __name__ == "__main__":
    Path(sys.argv[1]).write_text(text(), encoding="utf-8")
