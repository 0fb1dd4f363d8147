"""The tests/socketcan suite in the with-vcan guest, started in the background (tests/background.py) when pytest has
collected `tests/test_uml_vcan.py::test_socketcan_suite_passes_on_real_vcan` (tests/conftest.py), so the guest's
~100 s run overlaps the host's tests instead of following them. Under pytest-xdist the controller starts it (once,
when a worker has collected that test) and ends it; the test runs in a worker and waits for it."""
from __future__ import annotations

import importlib.machinery
import importlib.util
import os
import sys
from pathlib import Path
from types import ModuleType

import pytest
from background import BackgroundRun, started, wait_result

__all__ = ["BACKGROUND_KEY", "HOST_TIMEOUT_S", "REPO", "RUN_DIR_KEY", "SUITE_ARGS", "SUITE_TEST", "WITH_VCAN",
           "WORKER_RUN_DIR", "can_boot", "guest_run", "load_with_vcan", "started", "wait_result"]

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


def guest_run(directory: Path, *args: str) -> BackgroundRun:
    """`scripts/with-vcan ARGS` in the background at `GUEST_NICE`, ended after `HOST_TIMEOUT_S`."""
    return BackgroundRun(directory, ["nice", "-n", str(GUEST_NICE), sys.executable, str(WITH_VCAN), *args],
                         HOST_TIMEOUT_S)
