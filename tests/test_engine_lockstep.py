"""The offline session engine against lockstep, the reference (issue 28): every deterministic summary block bit for
bit, over a matrix of ideal and delayed / lossy / bursty links, the trigger at the edge and at the controller, TT and
ET, disturbances, model mismatch, start poses off the trajectory, a disturbance that latches a drive limit fault
mid-session, the local fallback on a silent downlink. Each lockstep session is a real one (plant, edge, recorder
here, the controller in a child process, Zenoh on loopback) on a 3 s gait. A cheap subset runs by default; all
cases with `SEA_HIL_FULL_MATRIX=1`."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import pytest
from paper_scheme import paper

from sea_hil.config.loader import load_config
from sea_hil.offline.session_engine import result_summary, run_engine
from sea_hil.protocol.link import parse_link_spec
from sea_hil.session.run import RunOptions, run_session

# every deterministic block of a session summary (the rest is wall-clock timing or the edge's own counters)
COMPARED = ("transmissions", "tracking", "lead_in", "events_by_reason", "inter_event_s", "duration_s",
            "uplink_outside_msgs", "max_abs_voltage_v", "rejections")
# edge counters the engine does not replay: the loop times lockstep measures (the engine's loop_count is 0); a drive
# latch's times (the engine's edge sees the latch at the sample after the fault, lockstep's at the drive's next 10 Hz
# heartbeat: compared below within one heartbeat period)
EDGE_NOT_REPLAYED = ("loop_count",)
LATCH_TIMES = ("drive_latch_origin_t_ns", "drive_latch_1_t_ns", "drive_latch_1_until_t_ns")
SHORT = {"trajectory": {"period_s": 3.0, "lead_in_s": 0.3}}
LOSSY = "delay=5ms,jitter=2ms,dist=normal,loss=2%"
BURSTY = "delay=10ms,jitter=3ms,ge=0.02/0.3/0.8"
OFF_START = {"plant": {"initial_theta_rad": [0.45, 1.0]}}          # the pose: inside limits, off the gait
FAR_START = {"plant": {"initial_theta_rad": [-0.3, 0.2]}}
# a slow knee torque that drives the limb past a drive limit half a second into the measured cycle
FAULT = {"disturbance": {"knee": {"kind": "sine", "amplitude_nm": 6.0, "frequency_hz": 0.25}}}
FALLBACK = {"trigger": {"placement": "edge", "edge_fallback": "local"}, "controller": {"compensation": "predict"}}

# name -> (mode, link spec or None, overrides, paper scheme?)
CASES: dict[str, tuple[str, str | None, dict[str, Any], bool]] = {
    "off-start-default-et": ("et", None, OFF_START, False),
    "off-start-paper-tt-lossy": ("tt", LOSSY, OFF_START, True),
    "fault-mid-session-et": ("et", None, FAULT, False),
    "fallback-bursty-et": ("et", BURSTY, FALLBACK, False),
    # SEA_HIL_FULL_MATRIX=1 adds:
    "off-start-default-tt": ("tt", None, OFF_START, False),
    "off-start-paper-et": ("et", None, OFF_START, True),
    "far-start-default-et-lossy": ("et", LOSSY, FAR_START, False),
    "far-start-paper-tt": ("tt", "delay=3ms", FAR_START, True),
    "hold-et-bursty": ("et", BURSTY, {"trigger": {"edge_fallback": "hold"}}, False),
    "paper-et-bursty": ("et", BURSTY, {}, True),
    "mismatch-disturbance-et": ("et", LOSSY, {"controller": {"model": {"m1_kg": 1.28, "k2_n_per_m": 16000.0}},
                                              "disturbance": {"kind": "sine", "amplitude_nm": [0.2, 0.05],
                                                              "frequency_hz": 2.0}}, False),
    "noise-paper-tt": ("tt", "delay=2ms,jitter=1ms", {"disturbance": {"kind": "noise", "amplitude_nm": [0.3, 0.05],
                                                                        "seed": 3}}, True),
    "fault-mid-session-paper-tt": ("tt", LOSSY, FAULT, True),
    "fallback-silent-downlink-tt": ("tt", "delay=5ms", {**FALLBACK, "link": {"downlink": parse_link_spec(
        "delay=5ms,ge=0.02/0.05/1.0")}}, False),
    "edge-check-sample-et": ("et", "delay=4ms", {"trigger": {"placement": "edge", "edge_check": "sample"}}, False),
    # jitter that reorders: states released after a newer one are recorded and counted, not answered
    "reorder-et": ("et", "delay=10ms,jitter=8ms,reorder=on", {}, False),
}
CHEAP = ("off-start-default-et", "off-start-paper-tt-lossy", "fault-mid-session-et", "fallback-bursty-et", "reorder-et")
SELECTED = sorted(CASES) if os.environ.get("SEA_HIL_FULL_MATRIX") else CHEAP


def case_config(name: str) -> Any:
    mode, spec, extra, is_paper = CASES[name]
    ov: dict[str, Any] = {**SHORT, **extra}
    link = {"seed": 3, **ov.get("link", {})}
    if spec:
        link.setdefault("uplink", parse_link_spec(spec))
        link.setdefault("downlink", parse_link_spec(spec))
    ov["link"] = link
    ov["disturbance"] = {"seed": 3, **ov.get("disturbance", {})}
    return load_config(None, paper(ov) if is_paper else ov)


@pytest.mark.parametrize("name", SELECTED)
def test_offline_engine_equals_lockstep(name: str, tmp_path: Path) -> None:
    mode = CASES[name][0]
    cfg = case_config(name)
    live = run_session(cfg, RunOptions(controller=mode, out=tmp_path / "run", lockstep=True, progress=False,
                                       figures=False), log=lambda *a, **k: None)
    offline = run_engine(cfg, mode)
    got = result_summary(offline, mode, cfg)
    assert {k: got[k] for k in COMPARED} == {k: live[k] for k in COMPARED}
    # the edge's counters from its final /stats record, built by one rule for both (issue 29)
    assert _replayed(got["edge"]) == _replayed(live["edge"])
    assert _judged(got["verdict"]) == _judged(live["verdict"])
    assert bool(got["drive_faults"]) == offline.drive_faulted
    hb_period_s = 1.0 / cfg.can.heartbeat_rate_hz
    for mine, theirs in zip(got["drive_faults"], live["drive_faults"], strict=True):   # edge count vs CAN heartbeats
        assert (mine["source"], theirs["source"]) == ("edge", "can")
        assert 0.0 <= theirs["t_s"] - mine["t_s"] < hb_period_s, (mine, theirs)
    if name.startswith("fault-mid-session"):     # the limit fault latched inside the session, not at its start
        assert offline.drive_faulted and max(live["tracking"]["max_abs_error_rad"]) > 0.1
        assert max(live["lead_in"]["tracking"]["max_abs_error_rad"]) < 0.05
        assert got["verdict"]["status"] == "invalid"


def _replayed(edge: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in edge.items() if k not in EDGE_NOT_REPLAYED and k not in LATCH_TIMES}


def _judged(verdict: dict[str, Any]) -> dict[str, Any]:
    """The verdict without a drive latch's times (its `t_s`, time in fault and the message that says them: lockstep
    reads them from the drive's 10 Hz HEARTBEAT frames, the engine's edge sees the latch at the next sample)."""
    def reason(r: dict[str, Any]) -> dict[str, Any]:
        if r["severity"] != "invalid":
            return r
        return {k: r[k] for k in ("code", "severity", "node_id", "state", "flags", "cleared")}
    return {"status": verdict["status"], "reasons": [reason(r) for r in verdict["reasons"]]}
