"""The chaos session of tests/test_chaos.py (tests/multicast/chaos.py in private network and PID namespaces) as a
background run (tests/background.py). The default variant (limits on) is started by tests/conftest.py once pytest
has collected its test: when the UML guest suite runs, as soon as that has ended (beside it, the chaos nodes'
SCHED_FIFO starved the guest), else at once. Its ~70 s of a real-time session overlap the host tests instead of
following them, and its test, moved last, waits for it (docs/reliability.md, "Chaos"). Under xdist the test runs it
itself."""
from __future__ import annotations

import json
import os
import shlex
import sys
import uuid
from pathlib import Path
from typing import Any

import pytest
from background import BackgroundRun

REPO = Path(__file__).resolve().parents[1]
CHAOS = REPO / "tests" / "multicast" / "chaos.py"
CHAOS_TEST = "tests/test_chaos.py::test_chaos_kills_and_restarts_keep_the_invariants[on]"
CHAOS_RUN_KEY = pytest.StashKey["BackgroundRun | AfterRun"]()   # its `directory` holds the config and output
TIMEOUT_S = 240
SEED = 19
# the compose services' config (client mode, through the router) with a short flush period: a SIGKILLed recorder
# loses at most its open chunk, and a state is in the file within ~0.1 s. The drive's safety envelope is the default
# one (soft limits on position, velocity and spring force): a soft-limit fault is left to the operator, so one trip
# ends the session and fails the test
OVERLAY = """
[record]
flush_period_s = 0.1
"""
# the drive's soft limits off: the same fault-recovery invariants without the envelope (the opt-in variant)
LIMITS_OFF = """
[safety.drive]
enabled = false
"""


def config_path(directory: Path) -> Path:
    return directory / "chaos.toml"


def chaos_run(directory: Path, limits: str) -> BackgroundRun:
    """Write the session's config into `directory` and start the chaos helper there, in its own network and PID
    namespaces (and /proc, so the helper sees exactly the session's processes): if the helper dies, even SIGKILLed
    on the timeout, every node process dies with it."""
    overlay = OVERLAY + (LIMITS_OFF if limits == "off" else "")
    config = config_path(directory)
    config.write_text((REPO / "configs" / "session.toml").read_text() + overlay, encoding="utf-8")
    out = directory / "session"
    out.mkdir()
    can = f"ipc:chaos-{uuid.uuid4().hex[:12]}"   # a fresh channel: other runs on the host share the filesystem
    script = (f"ip link set lo up && exec {shlex.quote(sys.executable)} "
              f"{shlex.quote(str(CHAOS))} {shlex.quote(str(config))} {shlex.quote(str(out))} {can} {SEED}")
    return BackgroundRun(directory, ["unshare", "--net", "--pid", "--fork", "--kill-child", "--mount-proc", "sh", "-c",
                                     script], TIMEOUT_S)


def can_run() -> bool:
    """True when the chaos session can run here: a private network namespace, and not inside the UML guest."""
    from test_udp_multicast import netns_available
    return not os.environ.get("SEA_HIL_IN_UML") and netns_available() is None


def report_of(status: int | None, output: str) -> dict[str, Any]:
    """The helper's fault log (its last JSON line), or the test's failure with what the run printed."""
    if status is None:   # how far it got: the helper's progress lines
        pytest.fail(f"chaos session over {TIMEOUT_S} s; progress:\n" + "\n".join(
            ln for ln in output.splitlines() if ln.startswith("chaos:"))[-4000:])
    # the nodes' warnings (restarts seen, out-of-envelope setpoints rejected) are expected; show the helper's error
    assert status == 0, "\n".join(ln for ln in output.splitlines() if " WARNING: " not in ln)[-4000:]
    for line in reversed(output.splitlines()):
        if line.startswith('{"'):
            return json.loads(line)
    raise AssertionError(f"no fault log in the chaos helper's output:\n{output[-4000:]}")
