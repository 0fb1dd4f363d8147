"""Test-suite set-up: pytest's own `pytester` (tests/test_api.py runs a user's test with the sea-hil plugin), and
three long runs started in the background as soon as their test is collected, so they overlap the rest of the run
(tests/background.py): the with-vcan guest's socketcan suite (tests/uml_suite.py), then the chaos session
(tests/chaos_run.py), then the fuzz files (tests/cpu_suite.py; the last two not under xdist: a worker runs them in
its process); all are ended when pytest ends. Under pytest-xdist
(`SEA_HIL_TEST_WORKERS=2 scripts/test` runs `-n 2 --dist loadgroup`) the controller process starts and ends it,
once, and the tests that run sessions share one xdist group (`SERIAL_GROUP`), so no two of them run at a time."""
from __future__ import annotations

import shutil
import tempfile
from pathlib import Path
from typing import Any

import pytest
from background import AfterRun
from chaos_run import CHAOS_RUN_KEY, CHAOS_TEST, can_run, chaos_run
from cpu_suite import CPU_RUN_KEY, CPU_SUITE_TEST, cpu_run, in_child, moved
from uml_suite import BACKGROUND_KEY, RUN_DIR_KEY, SUITE_ARGS, SUITE_TEST, WORKER_RUN_DIR, can_boot, guest_run

pytest_plugins = ["pytester"]

SERIAL_GROUP = "sessions"
# Tests that run a live session (real-time or lockstep nodes, threads or child processes) or that are
# timing-sensitive: under xdist they all go to one worker, one at a time, beside the other worker's pure tests.
SERIAL_FILES = frozenset({
    "test_api.py", "test_bench_smoke.py", "test_bench_soak.py", "test_bus_timing.py", "test_can_fd_session.py",
    "test_chaos.py", "test_cli_errors.py", "test_compose_topology.py", "test_console.py", "test_edge_arrival.py",
    "test_examples.py", "test_faults.py", "test_fuzz_can.py", "test_fuzz_zenoh.py", "test_limbs.py", "test_live.py",
    "test_lockstep_link.py", "test_mcap_node.py", "test_period_option.py", "test_plant_node.py",
    "test_pre_refactor_equality.py", "test_recorder_process.py", "test_recording.py", "test_replay.py",
    "test_robustness_session.py", "test_run_secure.py", "test_runtime.py", "test_safety.py", "test_secure.py",
    "test_session.py", "test_session_engine.py", "test_session_signals.py", "test_sessionwatch.py",
    "test_ipc_bus.py", "test_udp_multicast.py", "test_uml_vcan.py", "test_verdict.py", "test_zsession.py",
})


def _is_worker(config: pytest.Config) -> bool:
    return hasattr(config, "workerinput")


def pytest_configure(config: pytest.Config) -> None:
    if _is_worker(config):
        config.stash[RUN_DIR_KEY] = Path(config.workerinput[WORKER_RUN_DIR])  # type: ignore[attr-defined]
    else:
        config.stash[RUN_DIR_KEY] = Path(tempfile.mkdtemp(prefix="sea-hil-uml-"))


@pytest.hookimpl(optionalhook=True)
def pytest_configure_node(node: Any) -> None:
    """xdist controller: every worker waits for the guest run in the controller's run directory."""
    node.workerinput[WORKER_RUN_DIR] = str(node.config.stash[RUN_DIR_KEY])


def _start_background(config: pytest.Config) -> None:
    if BACKGROUND_KEY not in config.stash and can_boot():
        config.stash[BACKGROUND_KEY] = guest_run(config.stash[RUN_DIR_KEY], *SUITE_ARGS)


@pytest.hookimpl(trylast=True)      # after -k / -m / --deselect: only what really runs is taken or waited for
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        if item.path.name in SERIAL_FILES:
            item.add_marker(pytest.mark.xdist_group(SERIAL_GROUP))
    # the fuzz files run in the background when their waiting test runs in this (one) process: out of this run
    if not (_is_worker(config) or in_child() or config.option.collectonly) and \
            any(item.nodeid == CPU_SUITE_TEST for item in items):
        taken = [item for item in items if moved(item.nodeid)]
        if taken:
            config.hook.pytest_deselected(items=taken)
            items[:] = [item for item in items if not moved(item.nodeid)]
            config.stash[CPU_RUN_KEY] = None            # to be started at the end of the collection
    # the background runs' tests wait for them: last, so the run goes on meanwhile
    items.sort(key=lambda item: item.nodeid in (CHAOS_TEST, CPU_SUITE_TEST))


def pytest_collection_finish(session: pytest.Session) -> None:
    if session.config.option.collectonly or _is_worker(session.config):
        return
    if any(item.nodeid == SUITE_TEST for item in session.items):
        _start_background(session.config)
    if any(item.nodeid == CHAOS_TEST for item in session.items) and can_run():
        directory = Path(tempfile.mkdtemp(prefix="sea-hil-chaos-"))
        guest = session.config.stash.get(BACKGROUND_KEY, None)
        # after the guest suite when it runs (the chaos nodes' SCHED_FIFO would starve it), else at once
        session.config.stash[CHAOS_RUN_KEY] = (chaos_run(directory, "on") if guest is None else
                                               AfterRun(directory, guest.result, lambda: chaos_run(directory, "on")))
    if CPU_RUN_KEY in session.config.stash:
        # after the chaos session (else the guest suite): the idle core is at the end; beside them it slowed both
        before = session.config.stash.get(CHAOS_RUN_KEY, None) or session.config.stash.get(BACKGROUND_KEY, None)
        cpu_dir = Path(tempfile.mkdtemp(prefix="sea-hil-cpu-"))
        session.config.stash[CPU_RUN_KEY] = (cpu_run(cpu_dir) if before is None else
                                             AfterRun(cpu_dir, before.result, lambda: cpu_run(cpu_dir)))


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_node_collection_finished(node: Any, ids: list[str]) -> None:
    """xdist controller: start the guest run when the first worker reports that it collected its host test."""
    if SUITE_TEST in ids and not node.config.option.collectonly:
        _start_background(node.config)


def pytest_unconfigure(config: pytest.Config) -> None:
    for key in (BACKGROUND_KEY, CHAOS_RUN_KEY, CPU_RUN_KEY):
        background = config.stash.get(key, None)
        if background is not None:
            background.stop()
    for key in (CHAOS_RUN_KEY, CPU_RUN_KEY):
        if config.stash.get(key, None) is not None:
            shutil.rmtree(config.stash[key].directory, ignore_errors=True)
    if not _is_worker(config):
        shutil.rmtree(config.stash[RUN_DIR_KEY], ignore_errors=True)
