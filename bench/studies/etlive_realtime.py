"""Issue 16 in real time: `sea-hil run --controller et --cycles 1` (wall clock, not lockstep), the new ET
(`--trigger edge --compensation predict`, `[trigger] edge_model = true`) and the paper's ET (`--trigger controller
--compensation none`), on the ideal link and at 5 ms, 1 ms normal jitter, 1 % loss each way, RUNS runs each, one
session at a time. Per run: total link messages of the measured cycle and their ratio to TT at 10 ms (2002 on
these links: one state and one setpoint per 10 ms), max tracking error (summary.json), the driver's tick misses,
and from the recording the state the controller answered first (its sample time = how long after the edge's first
sample the controller was listening: the cause of the new scheme's old real-time failure, docs/studies/et-over-links.md).

Real-time figures depend on the machine's load: run it in a quiet window. Each run takes the session's wall time
(about 13 s on an idle machine).

Run: python -m bench.studies.etlive_realtime [RUNS] [OUT_DIR]      (markdown rows to stdout)
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from sea_hil.recorder.reader import read_session

LINK_5MS = "delay=5ms,jitter=1ms,dist=normal,loss=1%"
LINKS = {"ideal": [], "5 ms, 1 ms normal, 1 %": ["--uplink", LINK_5MS, "--downlink", LINK_5MS]}
METHODS = {"ET new": ["--trigger", "edge", "--compensation", "predict"],
           "ET paper": ["--trigger", "controller", "--compensation", "none"]}
NEW_TOML = '[trigger]\nedge_model = true\n'
TT_TOTAL = 2002


def first_answer_s(out: Path) -> float:
    """Sample time (s after the edge's first sample) of the state the controller answered first."""
    data = read_session(out / "session.mcap")
    sample = {m.payload["seq"]: m.payload["sample_t_ns"] for m in data.messages.get("/zenoh/state", [])}
    t0 = min(sample.values())
    answers = data.messages.get("/zenoh/setpoint", [])
    return (sample[answers[0].payload["state_seq"]] - t0) * 1e-9 if answers else float("nan")


def run_once(out: Path, method: str, link: str) -> str:
    cfg = out.parent / "edge_model.toml"
    cfg.write_text(NEW_TOML, encoding="utf-8")
    cmd = [sys.executable, "-m", "sea_hil.cli", "run", "--controller", "et", "--cycles", "1", "--out", str(out),
           "--quiet", "--config", str(cfg), *METHODS[method], *LINKS[link]]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    if proc.returncode != 0:
        return f"| {link} | {method} | exit {proc.returncode} | | | | |"
    s = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    total = s["transmissions"]["total_msgs"]
    err = s["tracking"]["max_abs_error_rad"]
    drv = s["timing"].get("driver", {})
    return (f"| {link} | {method} | {total} | {total / TT_TOTAL:.3f} | {err[0]:.4f} / {err[1]:.4f} | "
            f"{drv.get('tick_misses', '?')} of {drv.get('ticks', '?')} | {first_answer_s(out):.2f} |")


def main(runs: int, out_dir: Path) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    print("| link, each way | method | total msgs | ratio to TT 10 ms | max error hip / knee [rad] | "
          "driver tick misses | first answered state [s] |")
    print("|---|---|---|---|---|---|---|")
    for link in LINKS:
        for method in METHODS:
            for i in range(runs):
                tag = f"{'new' if method == 'ET new' else 'paper'}-{'ideal' if not LINKS[link] else '5ms'}-{i}"
                print(run_once(out_dir / tag, method, link), flush=True)


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 3,
         Path(sys.argv[2]) if len(sys.argv) > 2 else Path("runs/etlive_realtime"))
