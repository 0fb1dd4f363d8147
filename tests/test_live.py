"""The live view (issue 18): a lockstep `sea-hil run --foxglove 0 --foxglove-wait` session watched by an independent
Foxglove WebSocket client (bench/foxglove_ws_client.py, no foxglove-sdk code); what it receives matches the MCAP
recording of the same session."""
from __future__ import annotations

import asyncio
import json
import queue
import re
import subprocess
import sys
import threading

import pytest

from bench.foxglove_ws_client import receive
from sea_hil.live.channels import CHANNELS, END_MESSAGE, LOG_LEVELS
from sea_hil.live.verdict import SUMMARY_ONLY
from sea_hil.protocol.can_codec import load_database
from sea_hil.protocol.can_frames import CMD_MASK
from sea_hil.recorder.reader import read_session
from sea_hil.report.session_summary import session_summary
from sea_hil.runtime.processes import end_process

pytestmark = pytest.mark.slow
URL = re.compile(r"Foxglove live view: (ws://\S+)")
HEARTBEAT_CMD = load_database().get_message_by_name("HEARTBEAT").frame_id & CMD_MASK


def _lines(stream, sink: queue.Queue) -> None:
    for line in iter(stream.readline, b""):
        sink.put(line.decode(errors="replace"))
    sink.put(None)


def _served_url(lines: queue.Queue) -> str:
    """The address the process announces on stderr (its lines arrive on `lines`)."""
    seen = []
    while True:
        line = lines.get(timeout=120)
        assert line is not None, "the process ended before serving: " + "".join(seen)
        seen.append(line)
        if m := URL.search(line):
            return m.group(1)


@pytest.fixture(scope="module")
def watched(tmp_path_factory):
    """(client's view, recording) of one short lockstep session started with --foxglove 0 --foxglove-wait."""
    tmp = tmp_path_factory.mktemp("live")
    (tmp / "short.toml").write_text("[trajectory]\nperiod_s = 2.0\n", encoding="utf-8")
    cmd = [sys.executable, "-m", "sea_hil.cli", "run", "--lockstep", "--controller", "et", "--cycles", "1",
           "--out", str(tmp / "run"), "--quiet", "--config", str(tmp / "short.toml"), "--foxglove", "0",
           "--foxglove-wait"]
    with open(tmp / "stdout.json", "wb") as stdout:
        proc = subprocess.Popen(cmd, stdout=stdout, stderr=subprocess.PIPE)
    lines: queue.Queue = queue.Queue()
    reader = threading.Thread(target=_lines, args=(proc.stderr, lines), daemon=True)
    reader.start()
    try:
        url = _served_url(lines)
        got = asyncio.run(receive(url, set(CHANNELS), end_message=END_MESSAGE, timeout_s=240))
        assert proc.wait(timeout=120) == 0
    finally:
        end_process(proc)
        reader.join(timeout=10)
    return got, read_session(tmp / "run" / "session.mcap")


def test_client_negotiates_and_receives_the_advertised_channels(watched):
    got, _ = watched
    assert got.subprotocol in ("foxglove.sdk.v1", "foxglove.websocket.v1")
    assert got.server_info["op"] == "serverInfo"
    chans = got.by_topic()
    assert set(chans) == set(CHANNELS)
    for topic, (schema_name, schema) in CHANNELS.items():
        assert chans[topic]["encoding"] == "json" and chans[topic]["schemaEncoding"] == "jsonschema"
        assert chans[topic]["schemaName"] == schema_name and json.loads(chans[topic]["schema"]) == schema
    assert chans["/live/events"]["schemaName"] == "foxglove.Log"
    assert got.ended and got.unknown_subscription == 0
    assert {t for t, msgs in got.messages.items() if msgs} == set(CHANNELS)


TRACKED = ("state_seq", "t_s", "theta1_rad", "theta2_rad", "theta1_d_rad", "theta2_d_rad", "event", "reason")
SETPOINT = ("seq", "state_seq", "delta1_ref_m", "delta2_ref_m", "s1", "s2", "reason")


def _rows(pairs, fields):
    return sorted((t, *(p[k] for k in fields)) for t, p in pairs)


def test_tracking_and_setpoints_match_the_recording(watched):
    got, rec = watched
    recorded = _rows(((m.log_time_ns, m.payload) for m in rec.messages["/tracking"]), TRACKED)
    live = got.messages["/live/tracking"]
    # --foxglove-wait: subscribed before the first sample; the end-of-session line comes after the last. A state
    # the lockstep edge re-sent can have two /tracking messages: rows are compared as multisets with their log time
    rows = _rows(live, TRACKED)
    assert len(rows) == len(recorded) > 100, f"{len(rows)} of {len(recorded)} tracking messages"
    assert rows == recorded
    for _, msg in live:
        assert msg["e1_rad"] == pytest.approx(msg["theta1_d_rad"] - msg["theta1_rad"], abs=1e-15)
        assert msg["e2_rad"] == pytest.approx(msg["theta2_d_rad"] - msg["theta2_rad"], abs=1e-15)
    setpoints = _rows(((m.log_time_ns, m.payload) for m in rec.messages["/zenoh/setpoint"]), SETPOINT)
    assert _rows(got.messages["/live/setpoint"], SETPOINT) == setpoints and len(setpoints) > 10


def test_events_driver_state_and_statistics_match_the_recording(watched):
    got, rec = watched
    logs = [m for _, m in got.messages["/live/events"]]
    events = [m for m in logs if m["name"] == "controller"]
    triggered = [m for m in rec.messages["/zenoh/setpoint"] if m.payload["reason"] != "TIME"]
    assert len(events) == len(triggered) and all(m["level"] == LOG_LEVELS["INFO"] for m in events)
    assert events[0]["message"].startswith(f"event: setpoint #1 ({triggered[0].payload['reason']})")
    assert logs[-1]["message"] == END_MESSAGE
    heartbeats = [m for m in rec.messages["/can/raw"] if m.payload["can_id"] & CMD_MASK == HEARTBEAT_CMD]
    driver = got.messages["/live/driver"]
    assert len(driver) == len(heartbeats) > 0
    assert [t for t, _ in driver] == [m.log_time_ns for m in heartbeats]
    assert driver[-1][1]["state_name"] == "RUNNING"
    link = got.messages["/live/link"][-1][1]
    assert link["up_msgs"] == len(rec.messages["/zenoh/state"])
    assert link["down_msgs"] == len(rec.messages["/zenoh/setpoint"]) + len(rec.messages["/zenoh/voltage"])
    assert link["up_bytes"] == sum(m.payload["payload_bytes"] for m in rec.messages["/zenoh/state"])
    # lockstep: log times are the session's sample time, and the controller answers a state within its sample
    assert link["rtt_count"] > 100 and link["rtt_p50_us"] == link["rtt_max_us"] == 0.0
    bus = got.messages["/live/bus"][-1][1]
    assert bus["frames"] == len(rec.messages["/can/raw"])
    assert 0 < bus["load_pct_session"] < 100
    assert len(got.messages["/live/node_stats"]) == len(rec.messages["/stats"])


def test_controller_serves_the_edges_traffic_through_its_record_child(tmp_path):
    """`sea-hil controller --foxglove`: its `record` child joins as a Zenoh client of the controller, so it also sees
    the state the edge (a peer connected to the controller) publishes; plant and edge run here, in lockstep."""
    from sea_hil.config.loader import load_config
    from sea_hil.controller.edge import EdgeNode
    from sea_hil.plant_emulator.node import PlantNode
    from sea_hil.protocol.canbus import open_bus
    from sea_hil.protocol.zsession import free_tcp_port, make_config, open_session
    from sea_hil.runtime.lockstep import clock_for
    (tmp_path / "short.toml").write_text("[trajectory]\nperiod_s = 1.0\n", encoding="utf-8")
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    ctl = subprocess.Popen([sys.executable, "-m", "sea_hil.cli", "controller", "--listen", endpoint, "--config",
                            str(tmp_path / "short.toml"), "--lockstep", "--cycles", "1", "--timeout", "200",
                            "--foxglove", "0", "--foxglove-wait"], stdin=subprocess.DEVNULL, stderr=subprocess.PIPE)
    lines: queue.Queue = queue.Queue()
    reader = threading.Thread(target=_lines, args=(ctl.stderr, lines), daemon=True)
    reader.start()
    cfg = load_config(overrides={"trajectory": {"period_s": 1.0}})
    session = buses = None
    try:
        url = _served_url(lines)
        session = open_session(make_config(connect=[endpoint]))
        buses = [open_bus("virtual:live-test"), open_bus("virtual:live-test")]
        clock = clock_for(True)
        plant = PlantNode(cfg, buses[0], (1,), clock=clock)
        edge = EdgeNode(cfg, buses[1], session, 1, clock=clock)
        nodes = [threading.Thread(target=plant.run, daemon=True), threading.Thread(target=edge.run, daemon=True)]
        for t in nodes:
            t.start()
        got = asyncio.run(receive(url, set(CHANNELS), end_message=END_MESSAGE, timeout_s=240))
        assert ctl.wait(timeout=120) == 0
        plant.stop()
        edge.stop()
        for t in nodes:
            t.join(timeout=10)
        edge.close()
    finally:
        end_process(ctl)
        reader.join(timeout=10)
        for b in buses or ():
            b.shutdown()
        if session is not None:
            session.close()
    assert got.ended and len(got.messages["/live/tracking"]) > 50
    link = got.messages["/live/link"][-1][1]
    assert link["up_msgs"] >= len(got.messages["/live/tracking"])   # the edge's states, forwarded by the controller
    assert link["down_msgs"] == len(got.messages["/live/setpoint"]) > 0
    assert "/live/driver" not in got.messages   # no CAN bus in the controller's view


def test_the_final_verdict_is_summary_jsons(watched):
    """The running verdict's last message (`final`) says what summary.json says of the same session (the reasons
    summary.json alone judges, from the recording itself, aside: sea_hil/live/verdict.py)."""
    got, rec = watched
    verdicts = [m for _, m in got.messages["/live/verdict"]]
    assert verdicts and verdicts[-1]["final"] and not any(m["final"] for m in verdicts[:-1])
    judged = session_summary(rec, "et")["verdict"]
    reasons = [r for r in judged["reasons"] if r["code"] not in SUMMARY_ONLY]
    assert verdicts[-1]["status"] == judged["status"]
    assert verdicts[-1]["codes"] == [r["code"] for r in reasons]
    assert verdicts[-1]["reasons"] == [r["message"] for r in reasons]
    changes = [m for _, m in got.messages["/live/events"] if m["name"] == "verdict"]
    statuses = [m["status"] for m in verdicts]
    assert len(changes) == sum(a != b for a, b in zip(["ok", *statuses], statuses, strict=False))
