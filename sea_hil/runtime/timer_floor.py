"""The host's floor for the 1 kHz loops: tick misses of an empty absolute-deadline loop (benchmark figure 4f,
docs/timing.md "The host's floor"). One thread sleeps to each deadline (start + k x period), reads the clock and
counts a miss when it wakes more than a whole period late (the deadlines passed are skipped, as `RealTimePacer` does).
No project work runs between wake-ups, so what it misses is the machine's (timer and wake-up latency), not the
emulator's. `sea-hil run` measures it for `[verdict] floor_measure_s` at start-up; bench/bench_timer_floor.py runs it
for longer."""
from __future__ import annotations

import os
import threading
import time
from typing import Any

import numpy as np


def empty_loop(duration_s: float, period_ns: int = 1_000_000) -> dict[str, Any]:
    """Run the empty loop for `duration_s` of deadlines: ticks run, deadlines, misses, miss_pct and the wake-up
    lateness percentiles in us (`lateness_us_p50`, `_p99`, `_p999`, `_max`)."""
    deadlines = int(duration_s * 1e9 // period_ns)
    start_ns = time.monotonic_ns() + period_ns
    lateness_ns: list[int] = []
    k = misses = 0
    while k < deadlines:
        due_ns = start_ns + k * period_ns
        wait_ns = due_ns - time.monotonic_ns()
        if wait_ns > 0:
            time.sleep(wait_ns / 1e9)
        late_ns = time.monotonic_ns() - due_ns
        lateness_ns.append(late_ns)
        skipped = max(0, late_ns) // period_ns   # a wake-up later than a period: those deadlines are lost
        misses += skipped
        k += 1 + skipped
    us = np.array(lateness_ns, dtype=float) / 1000 if lateness_ns else np.zeros(1)
    p50, p99, p999 = (float(v) for v in np.percentile(us, (50, 99, 99.9)))
    return {"ticks": len(lateness_ns), "deadlines": deadlines, "misses": misses,
            "miss_pct": 100.0 * misses / deadlines if deadlines else 0.0, "lateness_us_p50": p50,
            "lateness_us_p99": p99, "lateness_us_p999": p999, "lateness_us_max": float(us.max())}


def measure_floor(duration_s: float, priority: int = 0) -> dict[str, Any]:
    """`empty_loop` for `duration_s` in a thread of its own, at SCHED_FIFO `priority` where permitted (the driver's
    `[timing] realtime_priority`, so the floor is measured as the driver runs; 0 = normal scheduling), plus
    `duration_s` and `sched_fifo` (the priority that took effect, 0 if none). The thread's policy ends with it."""
    out: dict[str, Any] = {}

    def run() -> None:
        fifo = 0
        if priority > 0:
            try:
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
                fifo = priority
            except (AttributeError, PermissionError, OSError):
                pass
        out.update(empty_loop(duration_s), duration_s=duration_s, sched_fifo=fifo)

    t = threading.Thread(target=run, name="sea-hil-floor", daemon=True)
    t.start()
    t.join()
    return out
