"""Issue 16 on the kernel path: the trigger at the edge with prediction at the controller, the controller in its own
network namespace behind ``tc netem`` (delay and jitter on both veth ends), plant/edge/recorder on vcan0 in the
other. Lockstep: the link the nodes emulate is simulated (5 ms +- 1 ms, 1 % loss each way), netem adds real delay
underneath, which lockstep must not see: the session equals the offline engine with the same config bit for bit, its
uplink is event-triggered (far fewer states than outer samples), and every setpoint crossed the delayed veth twice.
"""
from __future__ import annotations

from pathlib import Path

import pytest
from netns_helpers import CLIENT_ADDR, SERVER_ADDR, run
from session_nodes import NodeSession, run_node_session, write_client_config, write_gait_slice_config

DELAY_MS = 10
DURATION_S = 1.0
LINK = "delay=5ms,jitter=1ms,dist=normal,loss=1%"
COMPARED = ("transmissions", "tracking", "events_by_reason", "inter_event_s", "duration_s", "uplink_outside_msgs")


@pytest.fixture
def delayed_namespaces(veth_namespaces: tuple[str, str]) -> tuple[str, str]:
    bus_ns, ctl_ns = veth_namespaces
    run("ip", "-n", bus_ns, "link", "add", "vcan0", "type", "vcan")
    run("ip", "-n", bus_ns, "link", "set", "vcan0", "up")
    for ns, dev in ((bus_ns, "v0"), (ctl_ns, "v1")):
        run("ip", "netns", "exec", ns, "tc", "qdisc", "add", "dev", dev, "root", "netem", "delay", f"{DELAY_MS}ms",
            "2ms")
    return bus_ns, ctl_ns


def test_edge_trigger_with_prediction_across_netem(tmp_path: Path, delayed_namespaces: tuple[str, str]) -> None:
    from sea_hil.config.loader import load_config
    from sea_hil.offline.session_engine import run_engine
    from sea_hil.protocol.link import parse_link_spec
    from sea_hil.protocol.zsession import free_tcp_port
    from sea_hil.report.session_summary import session_summary
    bus_ns, ctl_ns = delayed_namespaces
    cfg_path = write_gait_slice_config(tmp_path, DURATION_S, paper=False)
    link = '{ delay_s = 0.005, jitter_s = 0.001, jitter_dist = "normal", loss = 0.01 }'     # = LINK
    cfg_path.write_text(cfg_path.read_text(encoding="utf-8") + (
        '\n[trigger]\nplacement = "edge"\nedge_model = true\n\n[controller]\ncompensation = "predict"\n\n'
        f'[link]\nseed = 1\nuplink = {link}\ndownlink = {link}\n'), encoding="utf-8")
    assert load_config(cfg_path).link.uplink == load_config(overrides={"link": {"uplink": parse_link_spec(LINK)}}
                                                            ).link.uplink
    session = NodeSession(config=cfg_path, client_config=write_client_config(tmp_path), can="socketcan:vcan0",
                          listen_host=SERVER_ADDR, port=free_tcp_port(), bus_netns=bus_ns, controller_netns=ctl_ns)
    assert CLIENT_ADDR != SERVER_ADDR
    summary = run_node_session(session, tmp_path).summary
    offline = session_summary(run_engine(load_config(cfg_path), "et").data, "et")
    assert {k: summary[k] for k in COMPARED} == {k: offline[k] for k in COMPARED}
    assert summary["edge"]["edge_events"] > 0
    assert summary["transmissions"]["uplink_msgs"] < 0.6 * DURATION_S / 0.01      # event-triggered uplink
    assert summary["timing"]["latency_us"]["min"] >= 2 * DELAY_MS * 1000 * 0.5   # netem (jittered) on the path
