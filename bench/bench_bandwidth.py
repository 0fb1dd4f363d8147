"""Figure 5: downlink bandwidth of event-triggered (ET) vs time-triggered (TT) control, with tracking errors.

Run: python -m bench.bench_bandwidth [--runs 1] [--json OUT] [--workdir DIR]
Per run: `sea-hil run --controller {et,tt} --cycles 1` in real time and with `--lockstep`. Figures come from each
summary.json (computed from the MCAP recording): downlink messages and payload bytes per walking cycle, uplink
messages, max/RMS tracking errors. Lockstep runs are deterministic (seed 0), so one run each suffices.
"""
from __future__ import annotations

import sys
import tempfile
from pathlib import Path
from typing import Any

from bench.benchlib import bench_args, command_line, emit, record, sea_hil_run


def _row(s: dict[str, Any], timing: str, run: int) -> dict[str, Any]:
    tx, tr = s["transmissions"], s["tracking"]
    return {"run": run, "timing": timing, "controller": s["controller"], "downlink_msgs": tx["downlink_msgs"],
            "downlink_bytes": tx["downlink_bytes"], "uplink_msgs": tx["uplink_msgs"],
            "max_err_hip_rad": tr["max_abs_error_rad"][0], "max_err_knee_rad": tr["max_abs_error_rad"][1],
            "rms_err_hip_rad": tr["rms_error_rad"][0], "rms_err_knee_rad": tr["rms_error_rad"][1],
            "duration_s": s["duration_s"], "wall_s": s["timing"]["wall_s"]}


def _record(timing: str, fig: str, rows: list[dict[str, Any]], runs: int, command: str) -> dict[str, Any]:
    et = [r for r in rows if r["timing"] == timing and r["controller"] == "et"]
    tt = [r for r in rows if r["timing"] == timing and r["controller"] == "tt"]
    ratios = [e["downlink_msgs"] / t["downlink_msgs"] for e, t in zip(et, tt, strict=True) if t["downlink_msgs"]]
    tt_msgs = sorted(t["downlink_msgs"] for t in tt)[len(tt) // 2]
    err = max(max(e["max_err_hip_rad"], e["max_err_knee_rad"]) for e in et)
    err_tt = max(max(t["max_err_hip_rad"], t["max_err_knee_rad"]) for t in tt)
    rec = record(fig, f"downlink per walking cycle, ET vs TT, {timing}", runs=runs,
                 metric="ET downlink messages per cycle (median, min-max over runs); ratio = ET / TT messages",
                 unit="msgs/cycle", per_run=[e["downlink_msgs"] for e in et], p99=float("nan"),
                 baseline=float(tt_msgs), baseline_label="TT downlink messages per cycle, same run",
                 goal="ET <= 1/3 of TT messages, max error <= 1.2x TT (issue 4 acceptance)", command=command,
                 details=[r for r in rows if r["timing"] == timing],
                 notes=f"ET/TT message ratio per run {', '.join(f'{x:.3f}' for x in ratios)}; ET bytes/cycle "
                       f"{sorted(e['downlink_bytes'] for e in et)[len(et) // 2]} vs TT "
                       f"{sorted(t['downlink_bytes'] for t in tt)[len(tt) // 2]}; worst max |error| ET {err:.4f} rad, "
                       f"TT {err_tt:.4f} rad.")
    rec["goal_met"] = bool(ratios) and max(ratios) <= 1 / 3 and err <= 1.2 * err_tt
    return rec


def main(argv: list[str] | None = None) -> int:
    ap = bench_args(__doc__.splitlines()[0], runs=1)
    ap.add_argument("--workdir", type=Path, help="keep the run directories here (default: a temporary directory)")
    ap.add_argument("--timing", choices=("both", "realtime", "lockstep"), default="both")
    args = ap.parse_args(argv)
    runs = 1 if args.quick else args.runs
    timings = {"both": ("realtime", "lockstep")}.get(args.timing, (args.timing,))
    if args.quick:
        timings = ("lockstep",)
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="bench-bandwidth-") as tmp:
        base = args.workdir or Path(tmp)
        for i in range(runs):
            for timing in timings:
                for ctl in ("et", "tt"):
                    out = base / f"{timing}-{ctl}-{i + 1}"
                    s = sea_hil_run(out, controller=ctl, lockstep=timing == "lockstep")
                    rows.append(_row(s, timing, i + 1))
                    r = rows[-1]
                    print(f"run {i + 1}/{runs} {timing:8s} {ctl}: downlink {r['downlink_msgs']} msgs "
                          f"{r['downlink_bytes']} B, max err {r['max_err_hip_rad']:.4f}/{r['max_err_knee_rad']:.4f} "
                          f"rad, wall {r['wall_s']:.1f} s", flush=True)
    records = [_record(t, "5a" if t == "realtime" else "5b", rows, runs, command_line()) for t in timings]
    emit(records, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
