"""The edge's local fallback against the zero-order hold (docs/deviations.md section 17) over link seeds: per link,
scenario and `trigger.edge_fallback`, the new ET's total link messages, max tracking error and longest stale hold
(`EdgeEvents.max_stale_ns`: the edge ran on a setpoint computed before the oldest state it still waited an answer
to) for seeds 1-N, on the offline session engine (= the lockstep session; deterministic per seed).

Scenarios as bench/studies/study_et_acceptance.py: `nominal` and `robust` (`--mismatch`, default all=+10 %, and a 0.03 N m,
0.5 Hz sine on both joints).

Run: python -m bench.studies.study_et_fallback [--seeds N] [--mismatch SPEC] [LINK_SPEC ...]
     (default link: the issue's 20 ms, 5 ms jitter, GE 0.01/0.3/0.8 each way)
"""
from __future__ import annotations

import argparse
import logging

from sea_hil.config.shorthand import scenario_config
from sea_hil.offline.session_engine import run_engine
from sea_hil.protocol.link import parse_link_spec
from sea_hil.report.session_summary import session_summary

BURSTY = "delay=20ms,jitter=5ms,ge=0.01/0.3/0.8"


def point(spec: str, seed: int, fallback: str, disturbance: str | None, mismatch: str | None) -> tuple[int, float, int]:
    """(total msgs, max error [rad], longest stale hold [ms]) of one session."""
    link = parse_link_spec(spec)
    ov = {"link": {"seed": seed, "uplink": link, "downlink": link}, "disturbance": {"seed": seed},
          "controller": {"compensation": "predict"},
          "trigger": {"placement": "edge", "edge_model": True, "edge_fallback": fallback}}
    res = run_engine(scenario_config(None, ov, disturbance, mismatch), "et")
    s = session_summary(res.data, "et")
    t = s["transmissions"]
    assert res.edge is not None, "the trigger at the edge runs the edge's event core"
    stale_ms = res.edge.max_stale_ns // 10**6
    return t["uplink_msgs"] + t["downlink_msgs"], max(s["tracking"]["max_abs_error_rad"]), stale_ms


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("links", nargs="*", default=[BURSTY])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--mismatch", default="all=+10%")
    args = ap.parse_args()
    logging.disable(logging.WARNING)
    scenarios = {"nominal": (None, None), "robust": ("sine:0.03Nm@0.5Hz", args.mismatch)}
    print("| link, each way | scenario | edge_fallback | per seed: msgs / max err [rad] / stale [ms] "
          "| max err min-max |")
    print("|---|---|---|---|---|")
    for spec in args.links:
        for name, (dist, mism) in scenarios.items():
            for fallback in ("local", "hold"):
                pts = [point(spec, seed, fallback, dist, mism) for seed in range(1, args.seeds + 1)]
                cells = ", ".join(f"{m} / {e:.4f} / {st}" for m, e, st in pts)
                errs = [e for _, e, _ in pts]
                print(f"| {spec} | {name} | {fallback} | {cells} | {min(errs):.4f}-{max(errs):.4f} |", flush=True)


if __name__ == "__main__":
    main()
