"""Ending child processes the same way everywhere: SIGTERM, a bounded wait, then SIGKILL, always reaped."""
from __future__ import annotations

import subprocess


def end_process(proc: subprocess.Popen, timeout_s: float = 5.0) -> int:
    """Terminate `proc` if it still runs, kill it if it has not ended within `timeout_s`, reap it; its exit code."""
    if proc.poll() is None:
        proc.terminate()
    try:
        return proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.wait()
