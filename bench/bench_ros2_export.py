"""Issue 30: export time of a 10 s session to a rosbag2 directory (`sea-hil export RUN.mcap --ros2 DIR`).

Run: python -m bench.bench_ros2_export [--runs 3] [--session FILE.mcap] [--json OUT]
The source is `--session` (a `sea-hil run` recording) or, by default, a fresh lockstep
`sea-hil run --controller et --cycles 1` (10 s gait + 0.5 s lead-in; lockstep only makes the recording faster to
produce here, its message mix is a real-time session's: every frame of 1 kHz feedback and commands). Each run is the
real CLI in a child process, timed from start to exit (interpreter start, imports, reading the recording, converting,
encoding CDR, writing and renaming the bag), into a new directory. Goal (issue 30): below 10 s.
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench.benchlib import REPO, bench_args, emit, record, sea_hil_run, sea_hil_run_cmd
from sea_hil.errors import SeaHilError
from sea_hil.recorder.reader import read_session

GOAL_S = 10.0


def export_once(src: Path, out: Path) -> tuple[float, float]:
    """(wall seconds, CPU seconds user + system) of one `sea-hil export SRC --ros2 OUT` in a child process. The CPU
    time tells the export's own cost apart from waiting for a CPU on a shared machine."""
    cmd = [sys.executable, "-m", "sea_hil.cli", "export", str(src), "--ros2", str(out)]
    before = os.times()
    t0 = time.perf_counter()
    res = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=600)
    secs = time.perf_counter() - t0
    after = os.times()
    if res.returncode != 0:
        raise SeaHilError(f"export failed ({res.returncode}): {res.stderr.strip()[-500:]}")
    return secs, (after.children_user - before.children_user) + (after.children_system - before.children_system)


def main(argv: list[str] | None = None) -> int:
    ap = bench_args(__doc__.splitlines()[0], runs=3)
    ap.add_argument("--session", type=Path, metavar="FILE", help="recording to export")
    args = ap.parse_args(argv)
    runs = 1 if args.quick else args.runs
    with tempfile.TemporaryDirectory(prefix="bench-ros2-") as tmp:
        src = args.session
        source = f"{src}" if src else sea_hil_run_cmd("et", True)
        if src is None:
            sea_hil_run(Path(tmp) / "session", controller="et", lockstep=True)
            src = Path(tmp) / "session" / "session.mcap"
        data = read_session(src)
        span_s = max(ms[-1].log_time_ns for ms in data.messages.values() if ms) * 1e-9 - \
            min(ms[0].log_time_ns for ms in data.messages.values() if ms) * 1e-9
        secs, details = [], []
        for i in range(runs):
            load = os.getloadavg()[0]
            s, cpu = export_once(src, Path(tmp) / f"bag{i}")
            bag_bytes = sum(p.stat().st_size for p in (Path(tmp) / f"bag{i}").iterdir())
            secs.append(s)
            details.append({"run": i + 1, "seconds": s, "cpu_s": cpu, "load_average_1min": load,
                            "bag_bytes": bag_bytes})
            print(f"run {i + 1}/{runs}: {s:.2f} s wall, {cpu:.2f} s CPU (load average {load:.1f}), bag "
                  f"{bag_bytes / 1e6:.2f} MB", flush=True)
    cpu_list = ", ".join(f"{d['cpu_s']:.2f}" for d in details)
    rec = record("ros2", "rosbag2 export of a 10 s session", runs=runs,
                 metric="wall seconds of `sea-hil export RUN.mcap --ros2 DIR` (child process, start to exit)",
                 unit="s", per_run=secs, p99=float("nan"), baseline=span_s,
                 baseline_label="time span of the recording (s)", goal=f"< {GOAL_S:g} s for a 10 s session",
                 goal_met=max(secs) < GOAL_S, details=details,
                 notes=f"source: {source}; {data.message_count} recorded messages over {span_s:.1f} s; CPU seconds "
                       f"(user + system) per run: {cpu_list}.")
    emit([rec], args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
