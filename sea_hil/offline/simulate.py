"""`sea-hil simulate`: offline closed loop, summary.json and the paper's figures."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from sea_hil.config.root import SeaHilConfig
from sea_hil.offline.closed_loop import SimResult, simulate
from sea_hil.protocol.payloads import PAYLOAD_SIZE, MsgType, TriggerReason
from sea_hil.report.figures import inter_event_figure, tracking_figure
from sea_hil.report.summary import (
    TIMING_KEY,
    compare_table,
    inter_event_block,
    tracking_block,
    transmissions_block,
    write_summary,
)
from sea_hil.verdict.rules import verdict


def offline_transmissions(res: SimResult) -> dict[str, int]:
    """What the networked session would send for this loop, counted the session's way: one SetpointPayload per
    event (downlink) and one StatePayload per outer sample (uplink), bytes = payload sizes of protocol/payloads.py
    (Zenoh, TCP and IP overhead not included; no lead-in, no lockstep ACKs)."""
    down, up = len(res.event_t_s), len(res.t_s)
    return transmissions_block(down, down * PAYLOAD_SIZE[MsgType.SETPOINT], up, up * PAYLOAD_SIZE[MsgType.STATE])


def summarize(res: SimResult, cpu_s: float) -> dict[str, Any]:
    reasons = {int(k): int(v) for k, v in zip(*np.unique(res.event_reason, return_counts=True), strict=True)}
    return {
        "controller": res.mode,
        "duration_s": res.duration_s,
        "transmissions": offline_transmissions(res),
        "events_by_reason": {TriggerReason(k).name: v for k, v in sorted(reasons.items())},
        "tracking": tracking_block(res.theta_rad, res.desired_rad),
        "inter_event_s": inter_event_block(res.event_t_s),
        "max_abs_voltage_v": [float(v) for v in res.max_abs_voltage_v],
        "saturated_steps": res.saturated_steps,
        TIMING_KEY: {"cpu_s": cpu_s},
    }


def run_simulation(cfg: SeaHilConfig, mode: str, out: Path, cycles: int | None, quantise: bool = False
                   ) -> dict[str, Any]:
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.process_time()
    res = simulate(cfg, mode, cycles, quantise=quantise)
    summary = {**summarize(res, time.process_time() - t0), "quantised": quantise,
               "inner_steps": int(round(res.duration_s * cfg.can.feedback_rate_hz))}
    summary["verdict"] = verdict(summary, cfg.verdict)   # offline: saturated inner steps (no drive, no link)
    title = "ET-SMC" if mode == "et" else "TT-SMC"
    tracking_figure(out / f"tracking_{mode}.png", res.t_s, res.theta_rad, res.desired_rad, title)
    inter_event_figure(out / f"inter_event_{mode}.png", res.event_t_s, title)
    write_summary(out / "summary.json", summary)
    return summary


def run_compare(cfg: SeaHilConfig, out: Path, cycles: int | None, quantise: bool = False
                ) -> tuple[dict[str, Any], dict[str, Any], str]:
    tt = run_simulation(cfg, "tt", out / "tt", cycles, quantise)
    et = run_simulation(cfg, "et", out / "et", cycles, quantise)
    table = compare_table(tt, et)
    (out / "compare.md").write_text("# TT-SMC vs ET-SMC (offline simulation)\n\n" + table, encoding="utf-8")
    return tt, et, table
