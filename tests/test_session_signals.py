"""`sea-hil run` stopped by a signal leaves no process behind (sea_hil/runtime/processes.py).

- SIGTERM: the session's close path runs (controller ended, recording closed in order), exit status 143;
- SIGKILL (no close path can run): the controller child gets SIGTERM from Linux (`PR_SET_PDEATHSIG`), the recorder
  child finalises its file at the end of its input pipe (`closed_by = eof`);
- with `--driver-process` the driver child (`sea-hil plant --hold`) is one more: SIGTERM'd by the close path, by
  Linux when the parent is SIGKILLed (and its stdin ends).
"""
from __future__ import annotations

import signal
import subprocess
from pathlib import Path

import psutil
import pytest
from faults_helpers import REPO, end_process, sea_hil_cmd, wait_for

from sea_hil.recorder.reader import read_session

START_S = 60.0   # interpreter + imports + zenoh of two children on a loaded 2-core machine
GONE_S = 15.0


def _children(proc: subprocess.Popen[bytes]) -> dict[str, psutil.Process]:
    out = {}
    try:
        for c in psutil.Process(proc.pid).children(recursive=True):
            cmd = " ".join(c.cmdline())
            if "sea_hil.recorder.process" in cmd:
                out["recorder"] = c
            elif " controller " in f" {cmd} ":
                out["controller"] = c
            elif " plant " in f" {cmd} ":
                out["driver"] = c
    except psutil.Error:
        pass
    return out


def _alive(p: psutil.Process) -> bool:
    try:
        return p.is_running() and p.status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


@pytest.mark.parametrize(("sig", "split"), [(signal.SIGTERM, False), (signal.SIGKILL, False), (signal.SIGKILL, True)])
def test_run_stopped_by_a_signal_leaves_no_process(tmp_path: Path, sig: signal.Signals, split: bool) -> None:
    out = tmp_path / "run"
    proc = subprocess.Popen(sea_hil_cmd("run", "--controller", "et", "--cycles", "1", "--quiet", "--out", str(out),
                                        *(["--driver-process"] if split else [])),
                            cwd=REPO, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    kids: dict[str, psutil.Process] = {}
    try:
        assert wait_for(lambda: len(kids.update(_children(proc)) or kids) == 2 + split
                        and (out / "session.mcap").exists(), START_S, poll_s=0.05), "session never started"
        proc.send_signal(sig)
        rc = proc.wait(timeout=60)
        assert rc == (128 + signal.SIGTERM if sig is signal.SIGTERM else -signal.SIGKILL), rc
        gone = wait_for(lambda: not any(_alive(k) for k in kids.values()), GONE_S, poll_s=0.05)
        assert gone is not None, f"left running: {[(n, k.pid, k.cmdline()) for n, k in kids.items() if _alive(k)]}"
    finally:
        end_process(proc)
        for k in kids.values():
            if _alive(k):
                k.kill()
    data = read_session(out / "session.mcap")
    assert data.complete
    closed_by = data.metadata["sea-hil.final"]["closed_by"]
    assert closed_by == ("eof" if sig is signal.SIGKILL else "close"), closed_by
    if sig is signal.SIGTERM:
        assert b"stopped by SIGTERM" in (proc.stderr.read() if proc.stderr else b"")
