"""bench/sessionwatch.py: a session whose progress stops is reported as stalled (with a dump file), its process tree
ended; one that advances and exits 0 is ok. The "session" is a stand-in printing `sea-hil run` progress lines."""
from __future__ import annotations

import sys
import textwrap
from pathlib import Path

import psutil

from bench.sessionwatch import watch_run

REPO = Path(__file__).resolve().parent.parent

FAKE = textwrap.dedent("""
    import subprocess, sys, threading
    child = subprocess.Popen([sys.executable, "-c", "import threading; threading.Event().wait(600)"])
    print(child.pid, flush=True)
    tick = threading.Event()
    for k in range(int(sys.argv[1])):
        print(f"[ {k * 0.1:5.1f} s] sim {k * 0.1:6.2f}/10.50 s  lead-in  setpoints {k}  states {k}  latency p50 9 us",
              file=sys.stderr, flush=True)
        tick.wait(0.1)
    if sys.argv[2] == "hang":   # progress lines keep coming, nothing advances
        while True:
            print("[  9.9 s] sim   0.90/10.50 s  lead-in  setpoints 9  states 9  latency p50 9 us", file=sys.stderr,
                  flush=True)
            tick.wait(0.2)
    child.kill()
""")


def _run(tmp_path: Path, mode: str):
    script = tmp_path / "fake_run.py"
    script.write_text(FAKE, encoding="utf-8")
    return watch_run([sys.executable, str(script), "10", mode], tmp_path / mode, cwd=tmp_path, stall_s=1.5,
                     silent_s=30.0, timeout_s=60.0, dump_rounds=1)


def test_a_stalled_session_is_reported_with_dumps_and_ended(tmp_path: Path) -> None:
    res = _run(tmp_path, "hang")
    assert res.status == "stalled" and res.dumps is not None and res.dumps.exists()
    assert "sim   0.90" in res.last_progress
    assert "pid" in res.dumps.read_text()
    grandchild = int((tmp_path / "hang" / "stdout.txt").read_text().split()[0])
    assert not psutil.pid_exists(grandchild) or psutil.Process(grandchild).status() == psutil.STATUS_ZOMBIE


def test_an_advancing_session_is_ok(tmp_path: Path) -> None:
    res = _run(tmp_path, "finish")
    assert res.status == "ok" and res.returncode == 0 and res.dumps is None
