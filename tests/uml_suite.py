"""The tests/socketcan suite in the with-vcan guest, started in the background when pytest has collected
`tests/test_uml_vcan.py::test_socketcan_suite_passes_on_real_vcan` (tests/conftest.py), so the guest's ~100 s run
overlaps the host's tests instead of following them; the test then waits for it and asserts its result.
The guest process is ended at the latest when pytest ends (`stop`). Under pytest-xdist the controller starts it
(once, when a worker has collected that test) and ends it; the test runs in a worker and waits through the files of
the run directory (`wait_result`)."""
from __future__ import annotations

import fcntl
import importlib.machinery
import importlib.util
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path
from types import ModuleType

import pytest

REPO = Path(__file__).resolve().parents[1]
WITH_VCAN = REPO / "scripts" / "with-vcan"
GUEST_TIMEOUT_S = 720   # ~220 s alone in CI; at nice 5 beside the host tests longer (the host run takes ~500 s anyway)
HOST_TIMEOUT_S = GUEST_TIMEOUT_S + 60
GUEST_NICE = 5         # the guest yields CPU to the host's real-time tests it overlaps (CI: 2 cores), without starving
SUITE_TEST = "tests/test_uml_vcan.py::test_socketcan_suite_passes_on_real_vcan"
SUITE_ARGS = ("--timeout", str(GUEST_TIMEOUT_S), "--", sys.executable, "-m", "pytest", "-q", "-rA", "-p",
              "no:cacheprovider", "tests/socketcan")


BACKGROUND_KEY = pytest.StashKey["BackgroundRun"]()
RUN_DIR_KEY = pytest.StashKey[Path]()
WORKER_RUN_DIR = "sea_hil_uml_dir"   # xdist workerinput key: the controller's run directory


def load_with_vcan() -> ModuleType:
    """Import scripts/with-vcan (no .py suffix) as a module, to reuse its probes."""
    loader = importlib.machinery.SourceFileLoader("with_vcan", str(WITH_VCAN))
    spec = importlib.util.spec_from_loader("with_vcan", loader)
    assert spec is not None
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module


def can_boot() -> bool:
    """True when with-vcan can run here: a native vcan0, or a UML kernel (and we are not inside the guest)."""
    if os.environ.get("SEA_HIL_IN_UML"):
        return False
    module = load_with_vcan()
    if module.interface_is_up("vcan0"):
        return True
    try:
        module.find_uml_kernel()
    except Exception:  # noqa: BLE001 - WithVcanError of the loaded script module
        return False
    return True


class BackgroundRun:
    """`scripts/with-vcan ARGS` running in its own process group. Its output goes to `DIR/output.txt`, its exit
    status to `DIR/status` when it has ended; until then this process holds an exclusive `flock` on `DIR/lock`, so
    any process (an xdist worker whose test waits for a run the controller started) waits with `wait_result(DIR)`
    without polling. A watcher thread enforces `timeout_s` (then stops the run) and releases the lock."""

    def __init__(self, directory: Path, *args: str, timeout_s: float = HOST_TIMEOUT_S) -> None:
        self.directory = directory
        self._lock = open(directory / "lock", "w")  # noqa: SIM115 - released and closed by the watcher
        fcntl.flock(self._lock, fcntl.LOCK_EX)
        self._log = open(directory / "output.txt", "w", encoding="utf-8")  # noqa: SIM115 - closed by the watcher
        self.proc = subprocess.Popen(["nice", "-n", str(GUEST_NICE), sys.executable, str(WITH_VCAN), *args], cwd=REPO,
                                     stdin=subprocess.DEVNULL,
                                     stdout=self._log, stderr=subprocess.STDOUT, text=True, start_new_session=True)
        self._watcher = threading.Thread(target=self._watch, args=(timeout_s,), name="with-vcan watcher", daemon=True)
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
        """SIGTERM (with-vcan then kills its guest), SIGKILL of the group after 60 s."""
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
        raise AssertionError(f"the process that started with-vcan ended before the guest run did:\n{output}")
    status = status_file.read_text(encoding="utf-8")
    return (None if status == "timeout" else int(status)), output
