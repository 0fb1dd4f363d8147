"""Issue 19 study on the offline engine: the edge's late-answer drop (`[safety.setpoint] max_answer_age_s`) on links
slower than the tools' tables, both trigger placements, with the default 0.2 s and off (0). Deterministic (seed 1).
Prints total link messages and the max tracking error per joint (docs/deviations.md section 16).

Run: python -m bench.studies.study_late_answers [LINK ...]   (default: delay=150ms and delay=60ms,jitter=80ms each way)
"""
from __future__ import annotations

import logging
import sys
from typing import Any

from sea_hil.config.loader import load_config
from sea_hil.offline.session_engine import (
    EngineOptions,
    run_engine,
)
from sea_hil.protocol.link import parse_link_spec
from sea_hil.report.session_summary import session_summary

LINKS = ("delay=150ms", "delay=60ms,jitter=80ms")
PLACEMENTS: dict[str, dict[str, Any]] = {
    "edge": {}, "controller": {"trigger": {"placement": "controller"}, "controller": {"compensation": "none"}}}


def run(link: str, placement: str, max_age_s: float) -> tuple[int, list[float]]:
    ov = {"link": {"seed": 1, "uplink": parse_link_spec(link), "downlink": parse_link_spec(link)},
          "safety": {"setpoint": {"max_answer_age_s": max_age_s}}, **PLACEMENTS[placement]}
    cfg = load_config(None, ov)
    s = session_summary(run_engine(cfg, "et", opts=EngineOptions.from_config(cfg)).data, "et")
    t = s["transmissions"]
    return t["uplink_msgs"] + t["downlink_msgs"], [round(x, 4) for x in s["tracking"]["max_abs_error_rad"]]


def main(links: list[str]) -> None:
    logging.disable(logging.WARNING)      # the envelope's rejections are logged per setpoint
    for link in links:
        for placement in PLACEMENTS:
            for age in (0.2, 0.0):
                msgs, err = run(link, placement, age)
                print(f"{link:24s} trigger at {placement:10s} max_answer_age_s {age:.1f}: msgs {msgs:5d} "
                      f"max err hip/knee {err} rad", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:] or list(LINKS))
