"""The compose topology for real (issue 19 item 5): router + plant, edge, controller and recorder as separate processes
in client mode (tests/multicast/topology.py, run in a private network namespace) complete a lockstep cycle whose
summary equals the peer-to-peer `sea-hil run --lockstep` on the same config and seed.

Compared: every deterministic field (tracking, transmissions, lead-in, events, inter-event times, the edge's
counters), i.e. all but the wall-clock ones (`TIMING`, `EDGE_TIMING_PREFIX`, the fields the project's summary
comparison drops, and `RESEND_COPIES`, duplicates caused by wall-clock resends) and `max_abs_voltage_v`, which
comes from the recorded CAN frames: the compose recorder has no CAN bus (its container is not on the host
network), so it records the Zenoh side only.

The README's peer-to-peer topology (issue 32, tests/multicast/peer_topology.py: no router, the edge listens) is
compared the same way, CAN side included, and checked for a complete recording and every node's own result; with
its recorder SIGKILLed mid-session (tests/multicast/cutoff_topology.py), the torn file and the nodes' `--json`
results must give a verdict naming each incomplete channel with its missing count.
"""
from __future__ import annotations

import json
import shlex
import signal
import subprocess
import sys
import uuid
from pathlib import Path
from typing import Any

import jsonschema
import pytest
from summary_compare import deterministic, minus_one_figures
from test_udp_multicast import require_netns

from sea_hil.cli import main
from sea_hil.config.loader import load_config
from sea_hil.recorder.reader import SessionData, read_session
from sea_hil.report.node_summary import NODE_SUMMARY_SCHEMA
from sea_hil.report.summary_schema import SUMMARY_SCHEMA
from sea_hil.session.run import RunOptions, run_session

TOPOLOGY = Path(__file__).resolve().parent / "multicast" / "topology.py"
PEER_TOPOLOGY = Path(__file__).resolve().parent / "multicast" / "peer_topology.py"
CUTOFF_TOPOLOGY = Path(__file__).resolve().parent / "multicast" / "cutoff_topology.py"
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
@pytest.fixture(scope="module")
def short_config(tmp_path_factory: pytest.TempPathFactory) -> Path:
    config = tmp_path_factory.mktemp("topology") / "compose.toml"
    config.write_text((REPO / "configs" / "session.toml").read_text() + SHORT, encoding="utf-8")
    return config


@pytest.fixture(scope="module")
def lockstep_run(short_config: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """`sea-hil run --lockstep` on the topologies' config: what every topology's summary must equal."""
    peer = run_session(load_config(short_config), RunOptions(controller="et", cycles=1,
                                                             out=tmp_path_factory.mktemp("run") / "peer",
                                                             lockstep=True, progress=False, figures=False))
    return json.loads(json.dumps(peer))


def _in_netns(script_path: Path, config: Path, out: Path) -> dict[str, Any]:
    """Run a topology script in its own network and PID namespaces, CAN on an ipc bus of its own (a fresh channel
    name: other test runs on the host share the filesystem); its JSON line."""
    can = f"ipc:topology-{uuid.uuid4().hex[:12]}"
    script = (f"ip link set lo up && exec {shlex.quote(sys.executable)} "
              f"{shlex.quote(str(script_path))} {shlex.quote(str(config))} {shlex.quote(str(out))} {can}")
    # its own PID namespace too: if the script dies (even by SIGKILL on the timeout) every node process dies with it
    result = subprocess.run(["unshare", "--net", "--pid", "--fork", "--kill-child", "sh", "-c", script],
                            capture_output=True, text=True, timeout=400, check=False, stdin=subprocess.DEVNULL)
    assert result.returncode == 0, result.stderr[-3000:]
    return dict(json.loads(result.stdout.strip().splitlines()[-1]))


@pytest.mark.slow
def test_compose_topology_through_a_router_equals_peer_to_peer(short_config: Path, lockstep_run: dict[str, Any],
                                                              tmp_path: Path) -> None:
    require_netns("compose topology")
    out = tmp_path / "compose"
    out.mkdir()
    report = _in_netns(TOPOLOGY, short_config, out)
    assert report["codes"] == {"controller": 0, "edge": 0, "plant": 0, "recorder": 0}, report
    compose = json.loads(Path(report["summary"]).read_text())
    assert load_config(short_config).zenoh.mode == "client"
    assert compose["transmissions"]["downlink_msgs"] > 10 and compose["edge"]["feedback_samples"] > 1000
    assert compose["completeness"]["complete"], compose["completeness"]
    assert deterministic(compose, can=False) == deterministic(lockstep_run, can=False)


@pytest.mark.slow
def test_readme_peer_to_peer_topology_records_every_channel(short_config: Path, lockstep_run: dict[str, Any],
                                                           tmp_path: Path) -> None:
    """Issue 32: the README's four commands with no router (the edge listens, recorder and controller connect):
    the recording's per-channel counts equal what the nodes say they sent, the summary equals `run --lockstep`'s
    in every deterministic field (the CAN side included: this recorder taps the bus), no figure is -1, each node
    ends with its result (`--json` validating against the node schema), and a recorder started after the
    controller had finished says which channels it lacks and by how much."""
    require_netns("peer-to-peer topology")
    peer_config = tmp_path / "peer.toml"    # the topologies' config without session.toml's client mode
    peer_config.write_text(SHORT, encoding="utf-8")
    out = tmp_path / "peer"
    out.mkdir()
    report = _in_netns(PEER_TOPOLOGY, peer_config, out)
    assert report["codes"] == {"controller": 0, "edge": 0, "plant": 0, "recorder": 0, "late": 0}, report
    edge, ctrl, late = (json.loads(report["stdout"][n]) for n in ("edge", "controller", "late"))
    for node in (edge, ctrl, late):
        jsonschema.validate(node, NODE_SUMMARY_SCHEMA)
    assert "recording complete" in report["stdout"]["recorder"] and "│ yes" in report["stdout"]["recorder"]
    summary = report["summary"]
    jsonschema.validate(summary, SUMMARY_SCHEMA)
    comp = summary["completeness"]
    assert comp["complete"] and comp["can_frames_lost"] == 0, comp
    channels = comp["channels"]
    assert channels["state"]["recorded"] == edge["counters"]["uplink_msgs"] > 100
    assert channels["downlink"]["recorded"] == ctrl["counters"]["setpoints_sent"] == \
        edge["counters"]["downlink_applied"] > 100
    assert channels["can_command"]["recorded"] == edge["counters"]["commands_sent"] > 1000
    assert all(v >= 0 for v in summary["timing"]["latency_us"].values()), summary["timing"]
    assert minus_one_figures(summary) == []
    assert ctrl["finished"] and "latency_us" in edge
    assert deterministic(summary) == deterministic(lockstep_run)
    # the late recorder: only the edge's final statistics reached it
    missing = late["completeness"]
    assert missing["incomplete"] == ["state"] and missing["unverified"] == ["downlink"], missing
    assert missing["channels"]["state"]["missing"] == edge["counters"]["uplink_msgs"]
    assert missing["never_seen"] == ["controller final stats"]
    # ... and with the controller's own --json result from its host, how much of the downlink it lacks
    (tmp_path / "controller.json").write_text(report["stdout"]["controller"], encoding="utf-8")
    assert main(["report", str(out / "late.mcap"), "--out", str(tmp_path / "late"), "--json",
                 "--node-summary", str(tmp_path / "controller.json")]) == 0
    checked = json.loads((tmp_path / "late" / "summary.json").read_text())["completeness"]
    assert checked["incomplete"] == ["state", "downlink"] and checked["unverified"] == [], checked
    assert checked["channels"]["downlink"]["missing"] == ctrl["counters"]["setpoints_sent"]


def _held(data: SessionData) -> dict[str, int]:
    """What a recording holds per completeness channel, counted here from its messages (unique key and seq)."""
    def unique(*topics: str) -> int:
        return len({(t, m.payload.get("key"), m.payload.get("seq")) for t in topics for m in data.messages.get(t, [])})
    commands = sum(m.payload.get("kind") == "voltage" for m in data.messages.get("/can/command", []))
    return {"state": unique("/zenoh/state"), "downlink": unique("/zenoh/setpoint", "/zenoh/voltage"),
            "can_command": commands}


@pytest.mark.slow
def test_recorder_cut_off_mid_session_names_each_incomplete_channel(tmp_path: Path) -> None:
    """Issue 32: the README's peer-to-peer session whose recorder is SIGKILLed while the controller still runs. The
    torn file (complete chunks only, no final statistics of anyone) with the edge's and the controller's `--json`
    results (`sea-hil report --node-summary`) gives a verdict that names every channel as incomplete with its
    missing count: the node's counter minus what the file holds."""
    require_netns("recorder cut-off")
    config = tmp_path / "cut.toml"    # the peer test's config; the recorder closes a chunk every 0.1 s
    config.write_text(SHORT + "\n[record]\nflush_period_s = 0.1\n", encoding="utf-8")
    out = tmp_path / "cut"
    out.mkdir()
    report = _in_netns(CUTOFF_TOPOLOGY, config, out)
    assert report["codes"] == {"recorder": -signal.SIGKILL, "controller": 0, "edge": 0, "plant": 0}, report
    assert report["cut_mid_session"], "the controller had finished before the recorder was killed"
    results = {}
    for name in ("edge", "controller"):
        results[name] = json.loads(report["stdout"][name])
        jsonschema.validate(results[name], NODE_SUMMARY_SCHEMA)
        (tmp_path / f"{name}.json").write_text(report["stdout"][name], encoding="utf-8")
    edge, ctrl = results["edge"]["counters"], results["controller"]["counters"]
    data = read_session(out / "session.mcap")
    assert not data.complete and "sea-hil.final" not in data.metadata
    held = _held(data)
    sent = {"state": edge["uplink_msgs"] - edge.get("uplink_pending", 0), "downlink": ctrl["setpoints_sent"],
            "can_command": edge["commands_sent"] + edge.get("arrival_commands", 0)}
    assert all(0 < held[ch] < sent[ch] for ch in sent), (held, sent)

    # the file alone: nothing to check against (no final statistics in it), and the verdict says so
    assert main(["report", str(out / "session.mcap"), "--out", str(tmp_path / "alone"), "--json"]) == 0
    alone = json.loads((tmp_path / "alone" / "summary.json").read_text())
    assert alone["completeness"]["unverified"] == list(sent) and not alone["completeness"]["complete"]
    assert sorted(r["channel"] for r in alone["verdict"]["reasons"] if r["code"] == "recording_unverified") == \
        sorted(sent)

    # with the nodes' own results: each channel incomplete, by the node's count less the file's
    assert main(["report", str(out / "session.mcap"), "--out", str(tmp_path / "checked"), "--json",
                 "--node-summary", str(tmp_path / "edge.json"),
                 "--node-summary", str(tmp_path / "controller.json")]) == 0
    summary = json.loads((tmp_path / "checked" / "summary.json").read_text())
    jsonschema.validate(summary, SUMMARY_SCHEMA)
    comp = summary["completeness"]
    assert comp["incomplete"] == list(sent) and comp["unverified"] == [] and not comp["complete"], comp
    assert comp["counters_from_node_summaries"] == ["controller", "edge"], comp
    for ch in sent:
        c = comp["channels"][ch]
        assert (c["expected"], c["recorded"], c["missing"]) == (sent[ch], held[ch], sent[ch] - held[ch]), (ch, c)
    missing = {r["channel"]: r["value"] for r in summary["verdict"]["reasons"] if r["code"] == "recording_incomplete"}
    assert missing == {ch: sent[ch] - held[ch] for ch in sent}, summary["verdict"]
    assert summary["verdict"]["status"] == "degraded"
    print(f"\nrecorder SIGKILLed mid-session: held {held} of {sent}")
