"""`python -m bench.studies.soak_tracemalloc OUT.txt T1_S T2_S -- <sea-hil cli args>`: run the `sea-hil` command line in
this process; at T1_S after the start begin tracing (tracemalloc, 25 frames; not earlier, so the imports and the
session's start-up run at full speed) and take a snapshot, at T2_S another, and write the allocations that grew most
between them (snapshot diff by traceback, top 15), i.e. what was allocated after T1_S and is still alive at T2_S, to
OUT.txt: the soak's leak finder (`bench_soak.py --tracemalloc`) for the `run` process, which hosts the plant, the
edge and the recorder taps. Tracing slows the process: the figures of a traced soak are not the soak's figures."""
from __future__ import annotations

import runpy
import sys
import threading
import time
import tracemalloc
from pathlib import Path


def _diff(out: Path, t1_s: float, t2_s: float) -> None:
    t0 = time.monotonic()
    time.sleep(t1_s)      # a timer thread: when to snapshot, not synchronisation of the session
    tracemalloc.start(25)
    first = tracemalloc.take_snapshot()
    time.sleep(max(t2_s - (time.monotonic() - t0), 0.0))
    second = tracemalloc.take_snapshot()
    keep = [tracemalloc.Filter(False, tracemalloc.__file__)]
    stats = second.filter_traces(keep).compare_to(first.filter_traces(keep), "traceback")
    lines = [f"tracemalloc diff {t1_s:g} s -> {t2_s:g} s after the start; traced now "
             f"{tracemalloc.get_traced_memory()[0] / 2**20:.1f} MB"]
    for st in stats[:15]:
        lines.append(f"\n{st.size_diff / 2**20:+.2f} MB in {st.count_diff:+d} blocks (now {st.size / 2**20:.2f} MB):")
        lines.extend("    " + ln for ln in st.traceback.format(limit=8))
    out.write_text("\n".join(lines) + "\n", encoding="utf-8")


def main() -> None:
    out, t1, t2, sep, *cli = sys.argv[1:]
    if sep != "--":
        raise SystemExit(__doc__)
    threading.Thread(target=_diff, args=(Path(out), float(t1), float(t2)), daemon=True).start()
    sys.argv = ["sea-hil", *cli]
    runpy.run_module("sea_hil.cli", run_name="__main__")


if __name__ == "__main__":
    main()
