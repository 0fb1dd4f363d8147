"""`udp_multicast` CAN between processes: a driver process and a commanding process share a multicast group.

python-can's udp_multicast bus needs a multicast route; the test makes its own network namespace
(``unshare --net``, root) with ``lo`` up and 224.0.0.0/4 routed to it, so nothing leaves the namespace.
Skipped where unshare is not permitted, except under CI=true where it must run.
"""
from __future__ import annotations

import json
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

PROBE = Path(__file__).resolve().parent / "multicast" / "probe.py"
GROUP = "239.74.163.9"


def netns_available() -> str | None:
    """None if `unshare --net` with a multicast route works here, else why not."""
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        return "unshare/ip not installed"
    probe = subprocess.run(["unshare", "--net", "sh", "-c", "ip link set lo up && ip route add 224.0.0.0/4 dev lo"],
                           capture_output=True, text=True, timeout=30, check=False)
    return None if probe.returncode == 0 else f"no private network namespace: {probe.stderr.strip()}"


def require_netns(what: str) -> None:
    """Skip the calling test where a private network namespace is not available; fail it under CI=true."""
    why = netns_available()
    if why is not None:
        if os.environ.get("CI") == "true":
            pytest.fail(f"CI must run the {what} test: {why}")
        pytest.skip(why)


def test_plant_over_udp_multicast_answers_another_process() -> None:
    require_netns("udp_multicast")
    script = (f"ip link set lo up && ip route add 224.0.0.0/4 dev lo && "
              f"exec {shlex.quote(sys.executable)} {shlex.quote(str(PROBE))} {GROUP}")
    result = subprocess.run(["unshare", "--net", "sh", "-c", script], capture_output=True, text=True, timeout=90,
                            check=False, stdin=subprocess.DEVNULL)
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout.strip().splitlines()[-1])
    assert report["feedback"] > 10, report
    assert "RUNNING" in report["states"], report
    assert abs(report["last_rad"] - report["first_rad"]) > 0.01, report
    assert report["rejected"] == 0, report
