"""Chaos (issue 19 item 6): seeded kills and restarts of the edge, the controller and the recorder, 10 faults in
60 s, in a real-time session of separate processes (tests/multicast/chaos.py, in private network and PID
namespaces). The invariants are asserted in the helper after each fault (safe state within the setpoint timeout +
watchdog, resumption, every state recorded before a recorder kill); here its report is checked: all faults
injected, the bound met by each, every node ended and no process left."""
from __future__ import annotations

import json
import shlex
import subprocess
import sys
from pathlib import Path

from test_udp_multicast import require_netns

CHAOS = Path(__file__).resolve().parent / "multicast" / "chaos.py"
REPO = Path(__file__).resolve().parents[1]
GROUP = "239.74.163.23"
SEED = 19
# the compose services' config (client mode, through the router) with a short flush period: a SIGKILLed recorder
# loses at most its open chunk, and a state is in the file within ~0.1 s. The drive's soft limits are off: the
# catch-up after a safe-state stop (0.3-0.7 s at zero voltage) can exceed the spring-force limit, and a soft-limit
# fault is left to the operator by design (docs/reliability.md), which would end the session this test restarts
OVERLAY = """
[record]
flush_period_s = 0.1

[safety.drive]
enabled = false
"""


def test_chaos_kills_and_restarts_keep_the_invariants(tmp_path: Path) -> None:
    require_netns("chaos")
    config = tmp_path / "chaos.toml"
    config.write_text((REPO / "configs" / "session.toml").read_text() + OVERLAY, encoding="utf-8")
    script = (f"ip link set lo up && ip route add 224.0.0.0/4 dev lo && exec {shlex.quote(sys.executable)} "
              f"{shlex.quote(str(CHAOS))} {shlex.quote(str(config))} {shlex.quote(str(tmp_path))} {GROUP} {SEED}")
    # its own PID namespace (and /proc, so the helper sees exactly the session's processes): if the helper dies (even
    # SIGKILLed on the timeout) every node process dies with it
    result = subprocess.run(["unshare", "--net", "--pid", "--fork", "--kill-child", "--mount-proc", "sh", "-c", script],
                            capture_output=True, text=True, timeout=240, check=False, stdin=subprocess.DEVNULL)
    # the nodes' warnings (restarts seen, out-of-envelope setpoints rejected) are expected; show the helper's error
    assert result.returncode == 0, "\n".join(ln for ln in result.stderr.splitlines() if " WARNING: " not in ln)[-4000:]
    report = json.loads(result.stdout.strip().splitlines()[-1])
    faults = report["faults"]
    assert len(faults) == 10 and {f["kind"] for f in faults} == {"edge", "controller", "recorder"}, faults
    assert all(f["safe_s"] <= report["safe_bound_s"] for f in faults if f["kind"] != "recorder"), faults
    assert all(0 < f["logged"] <= f["kept"] for f in faults if f["kind"] == "recorder"), faults
    assert report["left"] == [], report          # no process of the session left in its PID namespace
    assert report["started"] == 4 + 10
    # the last generation of each node ended by the helper's SIGTERM: cleanly, the controller with 3 (stopped before
    # its cycles were done)
    assert report["codes"] == {"plant": 0, "edge": 0, "recorder": 0, "controller": 3}, report["codes"]
    print(f"\nchaos seed {SEED}: {len(faults)} faults in {report['span_s']:.0f} s; " + "; ".join(
        f"{f['kind']} " + (f"safe {f['safe_s']:.2f} s (wall {f['safe_wall_s']:.2f}) " if "safe_s" in f else
                           f"kept {f['kept']} of {f['logged']} logged, state gaps {f['state_gaps']} ")
        + f"resume {f['resume_s']:.1f} s" for f in faults))
