"""Child processes of a session, the same way everywhere: started so that they cannot outlive their parent, ended
with SIGTERM, a bounded wait, then SIGKILL, always reaped.

- `end_process(proc)`: SIGTERM, wait, SIGKILL, reap.
- `spawn_child(cmd)`: `subprocess.Popen` that tells the child who its parent is (`SEA_HIL_PARENT_PID`); the child's
  `exit_with_parent()` (called by `sea_hil.cli.main`) asks Linux for SIGTERM when that parent dies, so a parent
  that is SIGKILLed (no close path runs) leaves no controller behind. The recorder child needs no such signal: it
  finalises its file and exits when its stdin (the parent's pipe) reaches end of file.
- `stop_on_signals()`: in the main thread, SIGTERM and SIGHUP raise `Terminated` in it, so `sea-hil run` leaves
  its `with` blocks (the session's close path: the controller is ended, the recording closed) instead of dying
  with its children still running. Later signals during the close are ignored (every step of it is bounded).
"""
from __future__ import annotations

import ctypes
import os
import signal
import subprocess
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any

from sea_hil.errors import Terminated

PARENT_ENV = "SEA_HIL_PARENT_PID"
_PR_SET_PDEATHSIG = 1    # <linux/prctl.h>


def end_process(proc: subprocess.Popen, timeout_s: float = 5.0) -> int:
    """Terminate `proc` if it still runs, kill it if it has not ended within `timeout_s`, reap it; its exit code."""
    if proc.poll() is None:
        proc.terminate()
    try:
        return proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.wait()


def spawn_child(cmd: Sequence[str], **kw: Any) -> subprocess.Popen:
    """`subprocess.Popen(cmd, **kw)` with `SEA_HIL_PARENT_PID` set to this process (see `exit_with_parent`)."""
    env = dict(kw.pop("env", None) or os.environ)
    env[PARENT_ENV] = str(os.getpid())
    return subprocess.Popen(list(cmd), env=env, **kw)


def exit_with_parent() -> bool:
    """In a child started by `spawn_child`: SIGTERM this process when the parent dies (Linux `PR_SET_PDEATHSIG`;
    elsewhere nothing). The variable is removed so grandchildren do not inherit it. A parent that died before the
    request is caught by comparing the parent pid. True if the request was made."""
    parent = os.environ.pop(PARENT_ENV, None)
    if parent is None or not parent.isdigit():
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0) != 0:
            return False
    except (OSError, AttributeError):   # not Linux
        return False
    if os.getppid() != int(parent):     # the parent is already gone (re-parented before the request)
        os.kill(os.getpid(), signal.SIGTERM)
    return True


@contextmanager
def stop_on_signals(signals: tuple[signal.Signals, ...] = (signal.SIGTERM, signal.SIGHUP)) -> Iterator[None]:
    """Within the block (main thread only; elsewhere nothing is installed) the first of `signals` raises
    `Terminated` in the main thread; later ones are ignored while the block unwinds. Old handlers are restored."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    fired: list[int] = []

    def handler(signum: int, _frame: object) -> None:
        if fired:
            return
        fired.append(signum)
        raise Terminated(signum, f"stopped by {signal.Signals(signum).name}")
    old = {sig: signal.signal(sig, handler) for sig in signals}
    try:
        yield
    finally:
        for sig, h in old.items():
            signal.signal(sig, h)
