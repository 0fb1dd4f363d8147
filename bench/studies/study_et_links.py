"""Issue 16 design study on the offline engine: total link messages and max tracking error per method and link
(the table of docs/studies/et-over-links.md). Deterministic (seed 1).

Run: python -m bench.studies.study_et_links [ideal|5ms|10ms|20ms ...]
"""
from __future__ import annotations

import sys
import time
from typing import Any

from sea_hil.config.loader import load_config
from sea_hil.offline.session_engine import (
    EngineOptions,
    run_engine,
)
from sea_hil.protocol.link import parse_link_spec
from sea_hil.report.session_summary import session_summary

LINKS = {"ideal": "", "5ms": "delay=5ms,jitter=1ms,dist=normal,loss=1%",
         "10ms": "delay=10ms,jitter=2ms,dist=normal,loss=2%", "20ms": "delay=20ms,jitter=5ms,ge=0.01/0.3/0.8"}
PREDICT = EngineOptions(compensation="predict")
METHODS: list[tuple[str, str, EngineOptions, int]] = [
    ("TT 10ms", "tt", EngineOptions(), 10), ("TT 10ms pred", "tt", PREDICT, 10), ("TT 20ms pred", "tt", PREDICT, 20),
    ("TT 30ms pred", "tt", PREDICT, 30), ("TT 50ms pred", "tt", PREDICT, 50), ("TT 100ms pred", "tt", PREDICT, 100),
    ("ET paper", "et", EngineOptions(), 10), ("ET ctrl pred", "et", PREDICT, 10),
    ("ET edge", "et", EngineOptions(placement="edge"), 10),
    ("ET edge pred", "et", EngineOptions(placement="edge", compensation="predict"), 10),
    ("ET edge1k pred", "et", EngineOptions(placement="edge", compensation="predict", edge_check="sample"), 10),
    ("ET edge1k model", "et", EngineOptions(placement="edge", compensation="predict", edge_check="sample",
                                            edge_model=True), 10),
    ("ET edge model", "et", EngineOptions(placement="edge", compensation="predict", edge_model=True), 10)]


def run(link: str, mode: str, opts: EngineOptions, period_ms: int) -> tuple[int, float, dict[str, Any]]:
    """(total messages, max error over both joints, transmissions block) of one engine session."""
    ov: dict[str, Any] = {"link": {"seed": 1}, "disturbance": {"seed": 1}}
    if LINKS[link]:
        ov["link"].update(uplink=parse_link_spec(LINKS[link]), downlink=parse_link_spec(LINKS[link]))
    if period_ms != 10:   # the outer sample period on the wire (the inner loop stays at 1 kHz)
        ov["controller"] = {"sample_period_s": period_ms / 1000}
    s = session_summary(run_engine(load_config(None, ov), mode, opts=opts).data, mode)
    t = s["transmissions"]
    return t["uplink_msgs"] + t["downlink_msgs"], max(s["tracking"]["max_abs_error_rad"]), t


def main(links: list[str], only: str = "") -> None:
    for link in links:
        tt_total = None
        for name, mode, opts, period_ms in METHODS:
            if only and name != "TT 10ms" and only not in name:
                continue
            t0 = time.perf_counter()
            total, err, t = run(link, mode, opts, period_ms)
            tt_total = tt_total or total
            print(f"{link:6s} {name:16s} total {total:5d} (up {t['uplink_msgs']:4d} down {t['downlink_msgs']:4d}) "
                  f"ratio {total / tt_total:.3f} max err {err:.4f} rad  [{time.perf_counter() - t0:.1f} s]", flush=True)


if __name__ == "__main__":
    args = sys.argv[1:]
    only = args.pop(args.index("--only") + 1) if "--only" in args else ""
    main([a for a in args if a != "--only"] or list(LINKS), only)
