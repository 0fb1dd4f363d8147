"""The hypothesis fuzz files (pure in-process CPU work, ~33 s) as a background pytest run (tests/background.py), so
they use the core that is otherwise idle at the end of the default run. /proc/stat sampled every 5 s beside a full
run: once the chaos session has ended, the two cores were 38-58 % busy while the host's tests went on one at a time.

tests/conftest.py starts the run after the chaos session (after the guest suite, or at collection, when those do
not run) and takes the files out of this run; `test_cpu_suite.py` waits for it and asserts that it passed, with its
output. Collected without that test (`pytest tests/test_fuzz_can.py`), under xdist, or in the background child itself
(`CHILD_ENV`), the files run in-process as usual."""
from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest
from background import BackgroundRun

FILES = ("tests/test_fuzz_can.py", "tests/test_fuzz_zenoh.py")
CPU_SUITE_TEST = "tests/test_cpu_suite.py::test_the_fuzz_files_pass_in_the_background"
CHILD_ENV = "SEA_HIL_CPU_SUITE_CHILD"
TIMEOUT_S = 600
CPU_RUN_KEY = pytest.StashKey["object"]()        # the BackgroundRun or AfterRun; its `directory` holds the output


def in_child() -> bool:
    return bool(os.environ.get(CHILD_ENV))


def moved(nodeid: str) -> bool:
    """True for a test of the files the background run takes."""
    return nodeid.split("::", 1)[0] in FILES


def cpu_run(directory: Path) -> BackgroundRun:
    """`python -m pytest FILES` in the background, in `directory` (output and status)."""
    return BackgroundRun(directory, [sys.executable, "-m", "pytest", "-q", "-rA", "-p", "no:cacheprovider", *FILES],
                         TIMEOUT_S, env={**os.environ, CHILD_ENV: "1"})
