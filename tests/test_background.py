"""tests/background.py, the harness of the long background runs (UML guest suite, chaos session): a run's status and
output come back through its directory; `AfterRun` starts only after the first run, and a stop before that start
cancels it."""
from __future__ import annotations

import sys
import threading
from pathlib import Path

from background import AfterRun, BackgroundRun, started, wait_result


def test_a_run_reports_status_and_output_through_its_directory(tmp_path: Path) -> None:
    run = BackgroundRun(tmp_path, [sys.executable, "-c", "print('hello'); raise SystemExit(3)"], timeout_s=60)
    try:
        assert started(tmp_path)
        assert run.result() == (3, "hello\n") == wait_result(tmp_path)
    finally:
        run.stop()


def test_after_run_starts_only_once_the_first_has_returned(tmp_path: Path) -> None:
    first_done = threading.Event()
    starts: list[bool] = []

    def start() -> BackgroundRun:
        starts.append(first_done.is_set())
        return BackgroundRun(tmp_path, [sys.executable, "-c", "print('second')"], timeout_s=60)
    after = AfterRun(tmp_path, first_done.wait, start)
    assert not started(tmp_path) and starts == []
    first_done.set()
    try:
        assert after.result() == (0, "second\n") and starts == [True]
    finally:
        after.stop()


def test_a_cancel_before_the_first_has_returned_stops_the_start(tmp_path: Path) -> None:
    release = threading.Event()
    after = AfterRun(tmp_path, release.wait, lambda: BackgroundRun(tmp_path, [sys.executable, "-c", "pass"], timeout_s=60))
    after.cancel()         # what stop() does first; stop() then waits for the first run to end
    release.set()          # the first run ends (as the guest suite's stop ends it in pytest_unconfigure)
    after.stop()
    assert not started(tmp_path)
