"""The remote controller in its own network namespace, reaching the edge over Zenoh TCP across a veth pair with
``tc netem delay`` on both ends: the latencies the session records must contain the configured link delay.

Namespace ``bus`` holds its own vcan0 with the plant, the edge (listening on 192.0.2.1) and the recorder;
namespace ``ctl`` holds only the controller (192.0.2.2), which connects to the edge's endpoint. Lockstep, so the
session's result does not depend on the delay; only its latency figures do: the edge's closed-loop latency (state
published -> setpoint for that state applied, on the edge's one clock) must be >= 2 D for every setpoint. Without
netem it is a few ms in the guest, so the bound fails if the delay is not on the path. (The recording's one-way
figure, `state_to_setpoint_latency_us`, is not checked: in lockstep a state's stamp is its release on the simulated
clock and the controller's send time a wall-clock one, so their difference bounds nothing.) Addresses are
TEST-NET-1 (RFC 5737).

Issue 32's third topology: the recording's per-channel counts equal the nodes' own counters (their final records
in the file, and their `--json` results), no figure is -1, and the summary equals `sea-hil run --lockstep`'s on the
same config in every deterministic field (tests/summary_compare.py): lockstep waits for every message, so the real
delay changes only wall-clock figures.
"""
from __future__ import annotations

from pathlib import Path

import pytest
from netns_helpers import CLIENT_ADDR, SERVER_ADDR, run
from session_nodes import GaitSlice, NodeSession, run_node_session, write_client_config
from summary_compare import deterministic, minus_one_figures

DELAY_MS = 25
EDGE_ADDR, CONTROLLER_ADDR = SERVER_ADDR, CLIENT_ADDR
US_PER_MS = 1000


@pytest.fixture
def delayed_namespaces(veth_namespaces: tuple[str, str]) -> tuple[str, str]:
    """conftest's veth pair (edge side 192.0.2.1, controller side 192.0.2.2) plus a vcan0 in the edge's
    namespace and netem delay on both veth ends -> (bus namespace, controller namespace)."""
    bus_ns, ctl_ns = veth_namespaces
    run("ip", "-n", bus_ns, "link", "add", "vcan0", "type", "vcan")
    run("ip", "-n", bus_ns, "link", "set", "vcan0", "up")
    for ns, dev in ((bus_ns, "v0"), (ctl_ns, "v1")):
        run("ip", "netns", "exec", ns, "tc", "qdisc", "add", "dev", dev, "root", "netem", "delay", f"{DELAY_MS}ms")
    return bus_ns, ctl_ns


def test_session_latency_contains_netem_delay(tmp_path: Path, delayed_namespaces: tuple[str, str],
                                             gait_slice: GaitSlice) -> None:
    from sea_hil.protocol.zsession import free_tcp_port
    bus_ns, ctl_ns = delayed_namespaces
    config = gait_slice.config
    session = NodeSession(config=config,
                          client_config=write_client_config(tmp_path), can="socketcan:vcan0",
                          listen_host=EDGE_ADDR, port=free_tcp_port(), bus_netns=bus_ns, controller_netns=ctl_ns)
    result = run_node_session(session, tmp_path)
    summary = result.summary

    # the session completed across the delayed link
    assert summary["duration_s"] == pytest.approx(gait_slice.duration_s, abs=0.01)
    tx = summary["transmissions"]
    assert 0 < tx["downlink_msgs"] < summary["edge"]["uplink_msgs"], (tx, summary["edge"])
    assert summary["timing"]["latency_samples"] == tx["downlink_msgs"], summary
    # the recorder (a client of the edge) holds every message the far-side controller sent (issue 32), counted
    # against the nodes' own results too
    comp = summary["completeness"]
    assert comp["complete"] and comp["can_frames_lost"] == 0, comp
    edge, ctrl = result.nodes["edge"]["counters"], result.nodes["controller"]["counters"]
    channels = comp["channels"]
    assert channels["state"]["recorded"] == edge["uplink_msgs"] - edge.get("uplink_pending", 0) > 0, (channels, edge)
    assert channels["downlink"]["recorded"] == ctrl["setpoints_sent"] == edge["downlink_applied"] > 0, (channels, ctrl)
    assert channels["can_command"]["recorded"] == edge["commands_sent"] + edge.get("arrival_commands", 0) > 0, channels
    assert minus_one_figures(summary) == []

    # closed loop (edge): every setpoint crossed the veth twice
    latency_us = summary["timing"]["latency_us"]
    assert latency_us["min"] >= 2 * DELAY_MS * US_PER_MS, latency_us
    assert latency_us["p50"] >= 2 * DELAY_MS * US_PER_MS, latency_us
    print(f"netem delay {DELAY_MS} ms per direction: closed-loop latency [us] {latency_us}")

    # the same session in one `sea-hil run --lockstep` on the virtual bus: every deterministic field equal
    assert deterministic(summary) == deterministic(gait_slice.reference)
