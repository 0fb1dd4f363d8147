"""Host-level tests of scripts/with-vcan: the tests/socketcan suite passes on a real vcan0 (User Mode Linux guest
when this kernel has no CAN), the command's exit status, stdout/stderr, cwd and environment come back, and the
timeout kills the guest.

Without ``linux.uml`` (and no native vcan0) these tests skip, except under CI=true where they fail: CI must run them.
"""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest
from uml_suite import (
    HOST_TIMEOUT_S,
    REPO,
    RUN_DIR_KEY,
    SUITE_ARGS,
    WITH_VCAN,
    guest_run,
    load_with_vcan,
    started,
    wait_result,
)

pytestmark = pytest.mark.uml


def require_uml_kernel() -> None:
    """Skip (or fail under CI=true) when no User Mode Linux kernel is installed; skip inside the guest."""
    if os.environ.get("SEA_HIL_IN_UML"):
        pytest.skip("already inside the with-vcan guest (no recursion)")
    try:
        load_with_vcan().find_uml_kernel()
    except Exception as exc:  # noqa: BLE001 - WithVcanError of the loaded script module
        if os.environ.get("CI") == "true":
            pytest.fail(f"CI must run the UML tests: {exc}")
        pytest.skip(str(exc))


@pytest.fixture
def with_vcan_runner() -> Callable[..., subprocess.CompletedProcess[str]]:
    """Function running ``scripts/with-vcan ARGS`` -> CompletedProcess; skips when it cannot boot a guest."""
    if not load_with_vcan().interface_is_up("vcan0"):
        require_uml_kernel()
    elif os.environ.get("SEA_HIL_IN_UML"):
        pytest.skip("already inside the with-vcan guest (no recursion)")
    return run_with_vcan


def run_with_vcan(*args: str, cwd: Path = REPO, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    """Run with-vcan; on a host-side timeout send SIGTERM so that with-vcan itself kills the guest."""
    proc = subprocess.Popen([sys.executable, str(WITH_VCAN), *args], cwd=cwd, env=env, stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        stdout, stderr = proc.communicate(timeout=HOST_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGTERM)
        stdout, stderr = proc.communicate(timeout=60)
        pytest.fail(f"with-vcan did not finish within {HOST_TIMEOUT_S} s:\n{stdout}\n{stderr}")
    return subprocess.CompletedProcess(proc.args, proc.returncode, stdout, stderr)


Runner = Callable[..., subprocess.CompletedProcess[str]]


def test_socketcan_suite_passes_on_real_vcan(with_vcan_runner: Runner, request: pytest.FixtureRequest,
                                             tmp_path: Path) -> None:
    """The guest run was started in the background when pytest (or the xdist controller) had collected this test
    (tests/conftest.py); started here when it was not."""
    run_dir = request.config.stash[RUN_DIR_KEY]
    if started(run_dir):
        returncode, output = wait_result(run_dir)
    else:
        background = guest_run(tmp_path, *SUITE_ARGS)
        try:
            returncode, output = background.result()
        finally:
            background.stop()
    assert returncode is not None, f"with-vcan did not finish within {HOST_TIMEOUT_S} s:\n{output}"
    assert returncode == 0, output
    summary = re.search(r"(\d+) passed", output)
    assert summary is not None and int(summary.group(1)) >= 6, output
    for test in ("test_two_buses_exchange_frames", "test_cansend_reaches_python_can",
                 "test_python_can_frame_seen_by_candump"):
        assert f"PASSED tests/socketcan/test_vcan_basics.py::{test}" in output, output
    for test in ("test_session_vcan.py::test_multiprocess_session_on_vcan0_matches_virtual_bus",
                 "test_netem_zenoh.py::test_session_latency_contains_netem_delay",
                 "test_netem_edge_trigger.py::test_edge_trigger_with_prediction_across_netem",
                 "test_export_canplayer.py::test_canplayer_replays_an_exported_log_onto_vcan0"):
        assert f"PASSED tests/socketcan/{test}" in output, output


def test_exit_status_streams_cwd_and_env_come_back(with_vcan_runner: Runner, tmp_path: Path) -> None:
    probe = "two words, 'quotes' and $dollar\nnewline"
    script = 'printf "%s|" "$SEAHIL_PROBE"; pwd; echo to-stderr >&2; exit 3'
    result = with_vcan_runner("--", "sh", "-c", script, cwd=tmp_path, env={**os.environ, "SEAHIL_PROBE": probe})
    assert result.returncode == 3, result.stderr
    assert result.stdout == f"{probe}|{tmp_path}\n"
    assert "to-stderr" in result.stderr and "to-stderr" not in result.stdout


def test_timeout_kills_the_guest() -> None:
    require_uml_kernel()
    result = run_with_vcan("--uml", "--timeout", "3", "--", "sleep", "120")
    assert result.returncode == 124, result.stderr
    assert "timeout after 3 s" in result.stderr


def test_a_fetched_kernel_comes_first_with_its_own_modules(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """scripts/install-uml puts a kernel that boots on this CPU in SEA_HIL_UML_PREFIX only where the system's cannot:
    with-vcan takes it, and the module tree beside it (never the system's tree of another release); without it, the
    system's kernel and /usr/lib/uml/modules; SEA_HIL_UML_KERNEL / _MODULES override both."""
    module = load_with_vcan()
    prefix = tmp_path / "uml"
    (prefix / "modules" / "7.2.7").mkdir(parents=True)
    (prefix / "modules" / "7.2.7" / "modules.dep").write_text("")
    monkeypatch.setenv("SEA_HIL_UML_PREFIX", str(prefix))
    monkeypatch.delenv("SEA_HIL_UML_KERNEL", raising=False)
    monkeypatch.delenv("SEA_HIL_UML_MODULES", raising=False)
    kernel = prefix / "linux.uml"
    kernel.write_text("#!/bin/sh\n")
    kernel.chmod(0o755)
    assert module.find_uml_kernel() == kernel
    assert module.find_module_dir(kernel) == prefix / "modules" / "7.2.7"
    other = tmp_path / "bin" / "linux.uml"
    other.parent.mkdir()
    other.write_text("#!/bin/sh\n")
    other.chmod(0o755)
    monkeypatch.setenv("SEA_HIL_UML_KERNEL", str(other))
    assert module.find_uml_kernel() == other
    monkeypatch.setattr(module, "UML_MODULE_GLOB", str(tmp_path / "none" / "*"))
    with pytest.raises(module.WithVcanError, match="no UML module tree"):
        module.find_module_dir(other)      # not the fetched tree: another kernel's modules would not load
    kernel.unlink()
    monkeypatch.delenv("SEA_HIL_UML_KERNEL")
    monkeypatch.setattr(module.shutil, "which", lambda name: None)
    monkeypatch.setattr(module.os, "access", lambda path, mode: str(path) == "/usr/bin/linux.uml")
    assert module.find_uml_kernel() == Path("/usr/bin/linux.uml")    # the system's, once nothing was fetched
