"""A test's long run started in the background when pytest has collected it (tests/conftest.py), so it overlaps
the rest of the run instead of following it; the test then waits for it and asserts its result. Used for the
with-vcan guest's socketcan suite (tests/uml_suite.py), the chaos session (tests/chaos_run.py) and the fuzz files
(tests/cpu_suite.py). The process is ended at the latest when pytest ends (`stop`). Under pytest-xdist the
controller starts it and a worker's test waits through the files of the run directory (`wait_result`)."""
from __future__ import annotations

import fcntl
import os
import signal
import subprocess
import threading
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


class BackgroundRun:
    """The command `argv` running in its own process group. Its output goes to `DIR/output.txt`, its exit
    status to `DIR/status` when it has ended; until then this process holds an exclusive `flock` on `DIR/lock`, so
    any process (an xdist worker whose test waits for a run the controller started) waits with `wait_result(DIR)`
    without polling. A watcher thread enforces `timeout_s` (then stops the run) and releases the lock."""

    def __init__(self, directory: Path, argv: list[str], timeout_s: float, env: dict[str, str] | None = None) -> None:
        self.directory = directory
        self._lock = open(directory / "lock", "w")  # noqa: SIM115 - released and closed by the watcher
        fcntl.flock(self._lock, fcntl.LOCK_EX)
        self._log = open(directory / "output.txt", "w", encoding="utf-8")  # noqa: SIM115 - closed by the watcher
        self.proc = subprocess.Popen(argv, cwd=REPO, env=env, stdin=subprocess.DEVNULL,
                                     stdout=self._log, stderr=subprocess.STDOUT, text=True, start_new_session=True)
        self._watcher = threading.Thread(target=self._watch, args=(timeout_s,), name=f"{Path(argv[0]).name} watcher",
                                         daemon=True)
        self._watcher.start()

    def _watch(self, timeout_s: float) -> None:
        try:
            status = str(self.proc.wait(timeout=timeout_s))
        except subprocess.TimeoutExpired:
            self._end()
            status = "timeout"
        finally:
            self._log.close()
        tmp = self.directory / "status.tmp"
        tmp.write_text(status, encoding="utf-8")
        tmp.replace(self.directory / "status")
        fcntl.flock(self._lock, fcntl.LOCK_UN)
        self._lock.close()

    def _end(self) -> None:
        """SIGTERM (with-vcan then kills its guest; `unshare --kill-child` its namespace), SIGKILL of the group
        after 60 s."""
        if self.proc.poll() is not None:
            return
        self.proc.send_signal(signal.SIGTERM)
        try:
            self.proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()

    def result(self) -> tuple[int | None, str]:
        """(exit status or None on timeout, output), once the run has ended."""
        return wait_result(self.directory)

    def stop(self) -> None:
        """End the run if it is still going and wait for the watcher; idempotent."""
        self._end()
        self._watcher.join()


class AfterRun:
    """A background run started only once `first()` has returned (in a thread): the chaos session after the guest
    suite, so that the chaos session's SCHED_FIFO nodes do not starve the guest (a guest recorder once took over 30 s
    to end beside them). `start()` runs in `directory`. `result()` waits for the start and the run; `stop()` cancels a
    start not yet made."""

    def __init__(self, directory: Path, first: Callable[[], object], start: Callable[[], BackgroundRun]) -> None:
        self.directory = directory
        self._run: BackgroundRun | None = None
        self._cancelled = threading.Event()
        self._thread = threading.Thread(target=self._go, args=(first, start), name="after-run starter", daemon=True)
        self._thread.start()

    def _go(self, first: Callable[[], object], start: Callable[[], BackgroundRun]) -> None:
        try:
            first()
        except AssertionError:   # the first run's failure is its own test's; this one starts all the same
            pass
        if not self._cancelled.is_set():
            self._run = start()

    def result(self) -> tuple[int | None, str]:
        self._thread.join()
        if self._run is None:
            raise AssertionError("the background run was cancelled before it started")
        return self._run.result()

    def cancel(self) -> None:
        """No start from now on, if it has not happened yet."""
        self._cancelled.set()

    def stop(self) -> None:
        """Cancel the start if it has not happened (the first run must end for the thread to see it), else end the
        run; idempotent."""
        self.cancel()
        self._thread.join()
        if self._run is not None:
            self._run.stop()


def started(directory: Path) -> bool:
    """True when a background run was started in `directory` (by this process or the xdist controller)."""
    return (directory / "lock").exists()


def wait_result(directory: Path) -> tuple[int | None, str]:
    """Block until the run in `directory` has ended (its owner releases the lock), then (status or None, output)."""
    with open(directory / "lock") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
    output = (directory / "output.txt").read_text(encoding="utf-8", errors="replace")
    status_file = directory / "status"
    if not status_file.exists():
        raise AssertionError(f"the process that started the background run ended before the run did:\n{output}")
    status = status_file.read_text(encoding="utf-8")
    return (None if status == "timeout" else int(status)), output
