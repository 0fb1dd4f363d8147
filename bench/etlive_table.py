"""Issue 16 acceptance table: total link messages (uplink states + downlink setpoints of the measured cycle) and max
tracking error of the new ET (trigger at the edge, model lookahead, prediction), the paper's ET and periodic TT at
several outer periods (with and without prediction), on the four links of the issue, nominal and with a 10 % model
mismatch plus a 0.03 N·m 0.5 Hz sine on both joints. Default config, seed 1, one 10 s cycle after the lead-in.

Runs the offline session engine, which equals `sea-hil run --lockstep` with the same config bit for bit in every
deterministic summary field (tests/test_session_engine.py, the paper's scheme and the new one), so the figures are
the lockstep session's. Deterministic; no timing.

Run: python bench/etlive_table.py [nominal|robust ...]   (writes markdown rows to stdout)
"""
from __future__ import annotations

import logging
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # runnable from a source checkout

from sea_hil.config.shorthand import scenario_config  # noqa: E402
from sea_hil.offline.session_engine import run_engine  # noqa: E402
from sea_hil.protocol.link import parse_link_spec  # noqa: E402
from sea_hil.report.session_summary import session_summary  # noqa: E402

LINKS = {"ideal": "", "5 ms, 1 ms normal, 1 %": "delay=5ms,jitter=1ms,dist=normal,loss=1%",
         "10 ms, 2 ms normal, 2 %": "delay=10ms,jitter=2ms,dist=normal,loss=2%",
         "20 ms, 5 ms, GE 0.01/0.3/0.8": "delay=20ms,jitter=5ms,ge=0.01/0.3/0.8"}
SCENARIOS = {"nominal": (None, None),
             "robust": ("hip=sine:0.03Nm@0.5Hz,knee=sine:0.03Nm@0.5Hz", "all=+10%")}
NEW = {"trigger": {"placement": "edge", "edge_model": True}, "controller": {"compensation": "predict"}}
PAPER = {"trigger": {"placement": "controller"}, "controller": {"compensation": "none"}}
PREDICT = {"trigger": {"placement": "controller"}, "controller": {"compensation": "predict"}}   # TT + predictor
METHODS: list[tuple[str, str, dict[str, Any], int]] = [
    *[(f"TT {p} ms", "tt", PAPER, p) for p in (10, 20, 30, 50)],
    *[(f"TT {p} ms + predict", "tt", PREDICT, p) for p in (10, 20, 30, 50)],
    ("ET paper", "et", PAPER, 10), ("ET new (edge + model + predict)", "et", NEW, 10)]


def _merge(a: dict[str, Any], b: dict[str, Any]) -> dict[str, Any]:
    out = dict(a)
    for k, v in b.items():
        out[k] = _merge(out.get(k, {}), v) if isinstance(v, dict) else v
    return out


def run(link: str, scenario: str, mode: str, extra: dict[str, Any], period_ms: int) -> tuple[int, float]:
    ov: dict[str, Any] = {"link": {"seed": 1}, "disturbance": {"seed": 1}}
    if LINKS[link]:
        ov["link"].update(uplink=parse_link_spec(LINKS[link]), downlink=parse_link_spec(LINKS[link]))
    ov = _merge(ov, extra)
    if period_ms != 10:   # the outer sample period on the wire (the inner loop stays at 1 kHz)
        ov = _merge(ov, {"controller": {"sample_period_s": period_ms / 1000}})
    dist, mism = SCENARIOS[scenario]
    s = session_summary(run_engine(scenario_config(None, ov, dist, mism), mode).data, mode)
    t = s["transmissions"]
    return t["uplink_msgs"] + t["downlink_msgs"], max(s["tracking"]["max_abs_error_rad"])


def main(scenarios: list[str]) -> None:
    logging.disable(logging.WARNING)
    print("| scenario | link, each way | method | total msgs | ratio to TT 10 ms | max error [rad] |")
    print("|---|---|---|---|---|---|")
    for scenario in scenarios:
        for link in LINKS:
            tt_total = None
            for name, mode, extra, period_ms in METHODS:
                total, err = run(link, scenario, mode, extra, period_ms)
                tt_total = tt_total or total
                print(f"| {scenario} | {link} | {name} | {total} | {total / tt_total:.3f} | {err:.4f} |", flush=True)
    total, err = run("ideal", "nominal", "tt", PREDICT, 10)
    total5, err5 = run_fixed_delay()
    print(f"\nTT + predict, 10 ms: ideal {err:.4f} rad, 5 ms each way {err5:.4f} rad ({err5 / err:.2f}x)")


def run_fixed_delay() -> tuple[int, float]:
    LINKS["5 ms fixed"] = "delay=5ms"
    return run("5 ms fixed", "nominal", "tt", PREDICT, 10)


if __name__ == "__main__":
    main(sys.argv[1:] or list(SCENARIOS))
