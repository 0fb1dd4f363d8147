"""The compose topology for real (issue 19 item 5): router + plant, edge, controller and recorder as separate processes
in client mode (tests/multicast/topology.py, run in a private network namespace) complete a lockstep cycle whose
summary equals the peer-to-peer `sea-hil run --lockstep` on the same config and seed.

Compared: every deterministic field (tracking, transmissions, lead-in, events, inter-event times, the edge's
counters), i.e. all but the wall-clock ones (`TIMING`, `EDGE_TIMING_PREFIX`, the fields the project's summary
comparison drops, and `RESEND_COPIES`, duplicates caused by wall-clock resends) and `max_abs_voltage_v`, which
comes from the recorded CAN frames: the compose recorder has no CAN bus (its container is not on the host
network), so it records the Zenoh side only.
"""
from __future__ import annotations

import json
import shlex
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from test_udp_multicast import require_netns

from sea_hil.config.loader import load_config
from sea_hil.report.summary import deterministic as summary_deterministic
from sea_hil.session.run import RunOptions, run_session

TOPOLOGY = Path(__file__).resolve().parent / "multicast" / "topology.py"
GROUP = "239.74.163.19"
REPO = Path(__file__).resolve().parents[1]
# configs/session.toml (the compose services' shared config: client mode) plus a short session: a 1 s gait after a
# 0.25 s lead-in; the drive limits and the setpoint envelope are derived for the default 10 s gait
# (docs/can-protocol.md) and this one is 10x faster (100x the accelerations): off
SHORT = """
[trajectory]
period_s = 1.0
lead_in_s = 0.25

[safety.drive]
enabled = false

[safety.setpoint]
enabled = false
"""
# wall-clock fields are under `timing` (sea_hil.report.summary.deterministic drops them); the compose recorder has
# no CAN bus, so it records no voltage commands and knows no limb's bus (a deployment fact, not a result)
NOT_COMPARED = ("max_abs_voltage_v",)


def deterministic(summary: dict[str, Any]) -> dict[str, Any]:
    out = {k: v for k, v in summary_deterministic(summary).items() if k not in NOT_COMPARED}
    out["limbs"] = [{k: v for k, v in limb.items() if k != "bus"} for limb in out.get("limbs", [])]
    return out


@pytest.mark.slow
def test_compose_topology_through_a_router_equals_peer_to_peer(tmp_path: Path) -> None:
    require_netns("compose topology")
    config = tmp_path / "compose.toml"
    config.write_text((REPO / "configs" / "session.toml").read_text() + SHORT, encoding="utf-8")
    out = tmp_path / "compose"
    out.mkdir()
    script = (f"ip link set lo up && ip route add 224.0.0.0/4 dev lo && exec {shlex.quote(sys.executable)} "
              f"{shlex.quote(str(TOPOLOGY))} {shlex.quote(str(config))} {shlex.quote(str(out))} {GROUP}")
    # its own PID namespace too: if the script dies (even by SIGKILL on the timeout) every node process dies with it
    result = subprocess.run(["unshare", "--net", "--pid", "--fork", "--kill-child", "sh", "-c", script],
                            capture_output=True, text=True, timeout=400, check=False, stdin=subprocess.DEVNULL)
    assert result.returncode == 0, result.stderr[-3000:]
    report = json.loads(result.stdout.strip().splitlines()[-1])
    assert report["codes"] == {"controller": 0, "edge": 0, "plant": 0, "recorder": 0}, report
    compose = json.loads(Path(report["summary"]).read_text())
    assert load_config(config).zenoh.mode == "client"

    peer = run_session(load_config(config), RunOptions(controller="et", cycles=1, out=tmp_path / "peer",
                                                       lockstep=True, progress=False, figures=False))
    assert compose["transmissions"]["downlink_msgs"] > 10 and compose["edge"]["feedback_samples"] > 1000
    assert deterministic(compose) == deterministic(json.loads(json.dumps(peer)))
