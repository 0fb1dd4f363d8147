"""The tests/socketcan suite in the with-vcan guest, started in the background when pytest has collected
`tests/test_uml_vcan.py::test_socketcan_suite_passes_on_real_vcan` (tests/conftest.py), so the guest's ~100 s run
overlaps the host's tests instead of following them; the test then waits for it and asserts its result.
The guest process is ended at the latest when pytest ends (`stop`)."""
from __future__ import annotations

import importlib.machinery
import importlib.util
import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path
from types import ModuleType

import pytest

REPO = Path(__file__).resolve().parents[1]
WITH_VCAN = REPO / "scripts" / "with-vcan"
GUEST_TIMEOUT_S = 480   # the two multi-process session tests take ~40 s each in the guest (more on a busy host)
HOST_TIMEOUT_S = GUEST_TIMEOUT_S + 60
SUITE_TEST = "tests/test_uml_vcan.py::test_socketcan_suite_passes_on_real_vcan"
SUITE_ARGS = ("--timeout", str(GUEST_TIMEOUT_S), "--", sys.executable, "-m", "pytest", "-q", "-rA", "-p",
              "no:cacheprovider", "tests/socketcan")


BACKGROUND_KEY = pytest.StashKey["BackgroundRun"]()


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
    """`scripts/with-vcan ARGS` running in its own process group, output to an unnamed temporary file."""

    def __init__(self, *args: str) -> None:
        self._log = tempfile.TemporaryFile(mode="w+", encoding="utf-8")
        self.proc = subprocess.Popen([sys.executable, str(WITH_VCAN), *args], cwd=REPO, stdin=subprocess.DEVNULL,
                                     stdout=self._log, stderr=subprocess.STDOUT, text=True, start_new_session=True)

    def result(self, timeout_s: float = HOST_TIMEOUT_S) -> tuple[int | None, str]:
        """(exit status or None on timeout, output); on a timeout the run is stopped first."""
        try:
            rc: int | None = self.proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            self.stop()
            rc = None
        self._log.seek(0)
        return rc, self._log.read()

    def stop(self) -> None:
        """SIGTERM (with-vcan then kills its guest), SIGKILL of the group after 60 s; idempotent."""
        if self.proc.poll() is not None:
            return
        self.proc.send_signal(signal.SIGTERM)
        try:
            self.proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()
