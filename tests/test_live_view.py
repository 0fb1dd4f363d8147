"""The live view's pure core, its options, its layout and its server's errors (fast; the session-level acceptance
test is tests/test_live.py)."""
from __future__ import annotations

import argparse
import json
import math
import socket
import struct
from pathlib import Path
from typing import Any, cast

import pytest

from sea_hil.config.live import LiveConfig
from sea_hil.config.loader import config_to_toml, load_config
from sea_hil.config.verdict import VerdictConfig
from sea_hil.live import layout
from sea_hil.live.channels import CHANNELS, LOG_LEVELS
from sea_hil.live.cli import add_live_args, live_overrides
from sea_hil.live.view import LiveView
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import DriverState, ErrorFlags, Heartbeat
from sea_hil.protocol.cia402_decode import decoder_for
from sea_hil.protocol.cia402_od import EMCY_CODES
from sea_hil.recorder.can_tap import CanTap, RawFrame
from sea_hil.recorder.meta import CONFIG_ATTACHMENT
from sea_hil.recorder.process import ATTACHMENT, CANS, _apply
from sea_hil.recorder.writer import SessionRecorder
from sea_hil.verdict.rules import verdict

REPO = Path(__file__).resolve().parent.parent
MS = 1_000_000


def _raw(msg) -> dict:
    return {"can_id": msg.arbitration_id, "dlc": msg.dlc, "data_hex": bytes(msg.data).hex(), "direction": "rx",
            "is_extended": False, "node_id": msg.arbitration_id >> 5}


def _heartbeat(state: DriverState, flags: ErrorFlags = ErrorFlags(0), seq: int = 0) -> dict:
    return _raw(SeaCodec().encode(Heartbeat(1, state, flags, 3, 0, seq)))


def test_tracking_errors_and_statistics_on_log_time():
    v = LiveView(bitrate_bps=1_000_000, period_s=0.1, window_s=1.0)
    out = v.feed("/tracking", 5 * MS, {"t_s": 0.0, "state_seq": 7, "theta1_rad": 0.1, "theta2_rad": 0.2,
                                       "theta1_d_rad": 0.15, "theta2_d_rad": None, "event": True, "reason": "INITIAL"})
    (msg,) = out
    assert msg.topic == "/live/tracking" and msg.log_time_ns == 5 * MS
    assert msg.message["e1_rad"] == pytest.approx(0.05) and msg.message["e2_rad"] is None
    for i in range(10):   # states every 10 ms, each answered 2 ms later
        t = 10 * MS * (i + 1)
        assert v.feed("/zenoh/state", t, {"seq": i, "payload_bytes": 88}) == []
        v.feed("/zenoh/setpoint", t + 2 * MS, {"seq": i, "state_seq": i, "payload_bytes": 53, "reason": "TIME",
                                               "delta1_ref_m": 0.0, "delta2_ref_m": 0.0, "s1": 0.0, "s2": 0.0})
    stats = {m.topic: m.message for m in v.finish()}
    link = stats["/live/link"]
    assert (link["up_msgs"], link["up_bytes"], link["down_msgs"], link["down_bytes"]) == (10, 880, 10, 530)
    assert link["rtt_count"] == 10 and link["rtt_p50_us"] == pytest.approx(2000, rel=0.02)
    assert link["up_msgs_per_s"] == pytest.approx(10 / 0.092)   # 10 states from 10 ms to now = 102 ms


def test_statistics_are_emitted_every_period_of_log_time():
    v = LiveView(bitrate_bps=1_000_000, period_s=0.1)
    topics = [m.topic for t in range(0, 1000 * MS, MS) for m in v.feed("/can/raw", t, _raw(
        SeaCodec().encode(Heartbeat(1, DriverState.RUNNING, ErrorFlags(0), 0, 0, 0))) if t == 0 else
        {"can_id": 35, "dlc": 8, "data_hex": "00" * 8, "is_extended": False})]
    assert topics.count("/live/bus") == topics.count("/live/link") == 9   # at 100, 200, ... 900 ms
    assert v.bus.frames == 1000


def test_driver_state_changes_and_faults_are_logged():
    v = LiveView(bitrate_bps=1_000_000)
    logs = []
    for i, (state, flags) in enumerate([(DriverState.INIT, ErrorFlags(0)), (DriverState.RUNNING, ErrorFlags(0)),
                                        (DriverState.RUNNING, ErrorFlags(0)),
                                        (DriverState.FAULT, ErrorFlags.WATCHDOG | ErrorFlags.OVERRUN)]):
        out = v.feed("/can/raw", i * 100 * MS, _heartbeat(state, flags, i))
        assert [m.topic for m in out][0] == "/live/driver"
        logs += [m.message for m in out if m.topic == "/live/events" and m.message["name"] != "verdict"]
    assert [(m["level"], m["message"]) for m in logs] == [
        (LOG_LEVELS["INFO"], "state INIT"), (LOG_LEVELS["INFO"], "state RUNNING (was INIT)"),
        (LOG_LEVELS["ERROR"], "state FAULT (was RUNNING)"),
        (LOG_LEVELS["WARNING"], "error flags set: WATCHDOG, OVERRUN (rejected 3, overruns 0)")]
    assert logs[-1]["timestamp"] == {"sec": 0, "nsec": 300 * MS}


def test_bad_input_is_counted_not_raised():
    v = LiveView(bitrate_bps=1_000_000)
    assert v.feed("/can/raw", 1, {"can_id": "x"}) == []
    assert v.feed("/can/raw", 2, {"can_id": 39 | 32, "dlc": 7, "data_hex": "zz"}) == []   # a heartbeat id, no hex
    assert v.feed("/can/raw", 3, {"can_id": 33, "dlc": 99}) == []
    assert v.ignored == 3
    assert v.feed("/unknown", 4, {}) == []


def test_options_enable_the_view_and_keep_the_config_port():
    p = argparse.ArgumentParser()
    add_live_args(p)
    assert live_overrides(p.parse_args([])) == {}
    cfg = load_config(overrides=live_overrides(p.parse_args(["--foxglove"])))
    assert cfg.live.enabled and cfg.live.port == 8765 and cfg.live.host == "127.0.0.1"
    cfg = load_config(overrides=live_overrides(p.parse_args(["--foxglove", "0", "--foxglove-host", "0.0.0.0",
                                                             "--foxglove-wait"])))
    assert (cfg.live.port, cfg.live.host, cfg.live.wait) == (0, "0.0.0.0", True)
    with pytest.raises(SystemExit):
        p.parse_args(["--foxglove", "70000"])


def _message_paths(layout: dict[str, Any]) -> list[str]:
    """Every `/topic.field` and bare `/topic` the layout's panels read."""
    out: list[str] = []
    for panel in layout["configById"].values():
        out += [p["value"] for p in panel.get("paths", [])]
        out += [panel[k] for k in ("topicPath", "topicToRender") if k in panel]
    return out


def test_shipped_layout_is_generated_and_reads_only_live_fields():
    shipped = (REPO / "docs" / "foxglove" / "sea-hil-layout.json").read_text(encoding="utf-8")
    assert shipped == layout.text()
    paths = _message_paths(json.loads(shipped))
    assert {p.split(".")[0] for p in paths} >= {"/live/tracking", "/live/events", "/live/link", "/live/bus"}
    for path in paths:
        topic, _, field = path.partition(".")
        assert topic in CHANNELS, path
        if field:
            assert field in CHANNELS[topic][1]["properties"], path


def test_a_taken_port_is_a_clear_error():
    from sea_hil.live.server import LiveError, LiveServer
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        with pytest.raises(LiveError, match="cannot serve the Foxglove live view on 127.0.0.1:"):
            LiveServer(LiveConfig(port=s.getsockname()[1]))


def test_non_finite_values_are_sent_as_null_and_bad_messages_counted():
    from sea_hil.live.server import LiveServer
    from sea_hil.live.view import LiveMessage
    notices = []
    srv = LiveServer(LiveConfig(port=0), notices.append)
    try:
        assert notices[0]["event"] == "listening" and notices[0]["port"] == srv.port > 0
        srv.publish(LiveMessage("/live/bus", 1, {"load_pct": math.nan}))
        srv.publish(LiveMessage("/live/bus", 2, {"load_pct": object()}))
        srv.publish(LiveMessage("/live/nowhere", 3, {}))
        assert (srv.published, srv.nonfinite, srv.rejected) == (1, 1, 2)
    finally:
        srv.close()


def test_a_node_serves_through_a_record_child_on_its_own_zenoh_network():
    from sea_hil.errors import ConfigError
    from sea_hil.live.child import reachable, record_cmd
    assert reachable("tcp/0.0.0.0:7447") == "tcp/127.0.0.1:7447"
    assert reachable("tcp/10.0.0.2:7447") == "tcp/10.0.0.2:7447"
    args = argparse.Namespace(config="x.toml", foxglove_record=None)
    cfg = load_config(overrides={"live": {"enabled": True, "port": 9000, "wait": True},
                                 "zenoh": {"connect": ["tcp/10.0.0.2:7447"], "listen": ["tcp/0.0.0.0:7448"]}})
    cmd = record_cmd(args, cfg, "socketcan:vcan0")
    assert cmd[cmd.index("record"):] == [
        "record", "--foxglove", "9000", "--foxglove-host", "127.0.0.1", "--foxglove-wait", "--limb", "limb1",
        "--connect", "tcp/127.0.0.1:7448", "--connect", "tcp/10.0.0.2:7447", "--can", "socketcan:vcan0",
        "--config", "x.toml"]
    assert "--can" not in record_cmd(args, cfg, "virtual:sea-hil")   # an in-process bus cannot be shared
    with pytest.raises(ConfigError, match="needs --connect or --listen"):
        record_cmd(args, load_config(overrides={"live": {"enabled": True}}), None)


def test_close_sends_the_end_line_and_waits_for_the_clients_to_leave():
    import asyncio
    import threading

    import websockets

    from bench.foxglove_ws_client import SUBPROTOCOLS
    from sea_hil.live.channels import END_MESSAGE
    from sea_hil.live.server import LiveServer
    srv = LiveServer(LiveConfig(port=0))
    closer = threading.Thread(target=srv.close, kwargs={"linger_s": 120.0})
    subscribed = threading.Event()
    srv.listener.notify = lambda msg: subscribed.set() if msg["event"] == "subscribed" else None

    async def client() -> dict:
        async with websockets.connect(f"ws://127.0.0.1:{srv.port}", subprotocols=SUBPROTOCOLS) as ws:
            chans = {}
            while "/live/events" not in chans:
                msg = json.loads(await ws.recv())
                chans.update({c["topic"]: c for c in msg.get("channels", [])})
            await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                {"id": 1, "channelId": chans["/live/events"]["id"]}]}))
            await asyncio.to_thread(subscribed.wait, 30)
            closer.start()   # the session ends while this client is subscribed
            while isinstance(frame := await ws.recv(), str):
                pass
            return json.loads(frame[13:])
    last = asyncio.run(client())   # then the client leaves
    assert last["message"] == END_MESSAGE and last["name"] == "sea-hil"
    closer.join(timeout=60)
    assert not closer.is_alive()   # returned once the client had gone, not after linger_s


# ---- the running verdict (sea_hil/live/verdict.py): summary.json's rules on what the view has seen ----------------
def _verdicts(out) -> list[dict]:
    return [m.message for m in out if m.topic == "/live/verdict"]


def _edge_stats(**counters) -> dict:
    return {"node": "edge", "node_id": 1, "final": False, "t_ns": 0, "key": "sea/limb1/stats", **counters}


def test_a_latch_turns_the_verdict_invalid_once_a_later_sample_is_measured():
    """The heartbeat's latch counts (as in summary.json) once a measured sample follows it: a latch after the last
    measured sample is the designed safe state at the end of a session, not judged."""
    v = LiveView(bitrate_bps=1_000_000, period_s=0.1)
    out = v.feed("/can/raw", 0, _heartbeat(DriverState.RUNNING))
    out += v.feed("/tracking", 50 * MS, {"t_s": 0.0, "state_seq": 1})
    out += v.feed("/can/raw", 100 * MS, _heartbeat(DriverState.FAULT, ErrorFlags.POSITION_LIMIT, 1))
    out += v.feed("/can/raw", 150 * MS, {"can_id": 35, "dlc": 8, "data_hex": "00" * 8, "is_extended": False})
    assert [m["status"] for m in _verdicts(out)] == ["ok"]   # at 150 ms: the latch is after the last sample
    assert v.verdict.summary()["drive_faults"][0]["after_session"] is True
    out = v.feed("/tracking", 200 * MS, {"t_s": 0.15, "state_seq": 2})
    out += v.feed("/can/raw", 260 * MS, {"can_id": 35, "dlc": 8, "data_hex": "00" * 8, "is_extended": False})
    (msg,) = _verdicts(out)
    assert msg["status"] == "invalid" and msg["codes"] == ["drive_fault"] and msg["final"] is False
    assert "drive 1 latched FAULT POSITION_LIMIT at 0.100 s" in msg["reasons"][0]
    logs = [m.message for m in out if m.topic == "/live/events" and m.message["name"] == "verdict"]
    assert [(m["level"], m["message"][:16]) for m in logs] == [(LOG_LEVELS["ERROR"], "verdict invalid:")]
    (final,) = _verdicts(v.finish())
    assert final["final"] is True and final["status"] == "invalid"
    assert [m for m in v.finish() if m.topic == "/live/events"] == []   # no change: no second line


def test_the_edges_latest_counters_are_judged_under_the_sessions_thresholds():
    cfg = VerdictConfig(envelope_rejections_max=2)
    v = LiveView(bitrate_bps=1_000_000, verdict=cfg, lockstep=True)
    v.feed("/stats", 0, _edge_stats(setpoints_out_of_envelope=2, stale_setpoints=50))
    assert v.verdict.judge()["status"] == "ok"   # 2 is within 2; stale setpoints: real time only
    v.feed("/stats", MS, _edge_stats(setpoints_out_of_envelope=3, stale_setpoints=50, uplink_dropped=4))
    v.feed("/stats", 2 * MS, {"node": "controller", "final": False, "t_ns": 0, "state_seq_lost": 9})
    got = v.verdict.judge()
    assert [r["code"] for r in got["reasons"]] == ["lost_states", "envelope_rejections"]
    assert [r["value"] for r in got["reasons"]] == [5, 3]   # 9 gaps - 4 of the model's own
    assert got == verdict(v.verdict.summary(), cfg)
    realtime = LiveView(bitrate_bps=1_000_000, lockstep=False)
    realtime.feed("/stats", 0, _edge_stats(stale_setpoints=50))
    assert [r["code"] for r in realtime.verdict.judge()["reasons"]] == ["stale_setpoints"]


def test_each_limbs_edge_is_judged_on_its_own():
    v = LiveView(bitrate_bps=1_000_000)
    v.feed("/stats", 0, _edge_stats(seq_lost=0))
    v.feed("/stats", 0, {**_edge_stats(seq_lost=3), "node_id": 2, "key": "sea/limb2/stats"})
    (r,) = v.verdict.judge()["reasons"]
    assert r["code"] == "lost_setpoints" and r["limb"] == "limb2" and r["message"].startswith("limb2: ")


def test_without_heartbeats_the_edges_latch_count_judges():
    """No heartbeat seen (a node's own live view on a `virtual:` bus, a cia402 bus): the latches the edge counted in
    its /stats record, as summary.json's `drive_faults` takes them from a recording without a CAN tap."""
    v = LiveView(bitrate_bps=1_000_000)
    v.feed("/zenoh/state", 0, {"seq": 5, "sample_t_ns": 1_000 * MS, "payload_bytes": 96})
    v.feed("/tracking", 1, {"t_s": 0.0, "state_seq": 5})
    v.feed("/tracking", 2, {"t_s": 1.0, "state_seq": 6})
    latch = {"drive_latches": 1, "drive_latch_origin_t_ns": 900 * MS, "drive_latch_1_t_ns": 1_500 * MS,
             "drive_latch_1_until_t_ns": 1_600 * MS, "drive_latch_1_state": int(DriverState.ESTOP),
             "drive_latch_1_flags": int(ErrorFlags.ESTOP), "drive_latch_1_cleared": 0}
    v.feed("/stats", 3, _edge_stats(**latch))
    (r,) = v.verdict.judge()["reasons"]
    assert r["code"] == "estop" and r["t_s"] == pytest.approx(0.6)
    v.feed("/stats", 4, _edge_stats(**{**latch, "drive_latch_1_t_ns": 2_100 * MS}))   # after the last sample
    assert v.verdict.judge()["status"] == "ok"


def test_a_stats_record_the_verdict_cannot_read_is_shown_counted_and_not_judged():
    v = LiveView(bitrate_bps=1_000_000)
    v.feed("/stats", 0, _edge_stats(seq_lost=2))
    out = v.feed("/stats", MS, _edge_stats(seq_lost=0, drive_latches=1))   # a latch count without its details
    out += v.feed("/stats", MS, {"node": "controller", "final": False, "t_ns": 0, "state_seq_lost": "many"})
    assert [m.topic for m in out] == ["/live/node_stats"] * 2 and v.ignored == 2
    assert [r["code"] for r in v.verdict.judge()["reasons"]] == ["lost_setpoints"]   # the last readable record
    assert [m.topic for m in v.finish()] == ["/live/link", "/live/bus", "/live/verdict", "/live/events"]


def _cia402_frames() -> list[tuple[int, bytes]]:
    """Node 7 of a cia402 bus (COB-IDs whose low five bits are the DBC's HEARTBEAT command, 7): enabled, a TPDO 2 at
    rest near zero (position 2 urad, velocity 0: the bytes of a DBC heartbeat in FAULT), an EMCY for the position
    limit, FAULT, fault reset back to OPERATION ENABLED."""
    emcy = struct.pack("<HB5x", EMCY_CODES[ErrorFlags.POSITION_LIMIT], 0x01)
    return [(0x187, bytes([0x27, 0x00, 0xFF])), (0x287, struct.pack("<ii", 2, 0)), (0x87, emcy),
            (0x187, bytes([0x08, 0x00, 0xFF])), (0x187, bytes([0x27, 0x00, 0xFF]))]


def test_a_cia402_bus_reports_driver_state_from_statuswords_not_the_dbc():
    """A cia402 recording's driver state (sea_hil/live/view.py `follow_canopen`): from the statusword TPDOs and EMCYs
    (protocol.cia402_drive_state, the report's rule); the TPDO 2 that the DBC would read as driver 20's FAULT
    heartbeat gives no /live/driver message."""
    frames = _cia402_frames()
    hb = SeaCodec(fd=None).decode_raw(0x287, frames[1][1], 8)     # the hazard: the DBC's reading of the TPDO 2
    assert isinstance(hb, Heartbeat) and (hb.node_id, hb.state) == (20, DriverState.FAULT)
    v = LiveView(bitrate_bps=1_000_000)
    v.follow_canopen(decoder_for(load_config(overrides={"can": {"profile": "cia402",
                                                                "cia402": {"node_ids": [7, 8]}}})))
    drivers, logs = [], []
    for i, (can_id, data) in enumerate(frames):
        out = v.feed("/can/raw", i * MS, {"can_id": can_id, "dlc": len(data), "data_hex": data.hex(),
                                          "direction": "rx", "is_extended": False, "node_id": 7})
        drivers += [m.message for m in out if m.topic == "/live/driver"]
        logs += [m.message["message"] for m in out if m.topic == "/live/events"]
    assert [(d["node_id"], d["state_name"], d["err_position_limit"]) for d in drivers] == \
        [(7, "RUNNING", False), (7, "FAULT", True), (7, "RUNNING", False)]
    assert logs == ["state RUNNING", "state FAULT (was RUNNING)",
                    "error flags set: POSITION_LIMIT (rejected 0, overruns 0)", "state RUNNING (was FAULT)",
                    "error flags cleared: POSITION_LIMIT"]
    assert v.ignored == 0 and v.bus.frames == len(frames)


class _Feed:
    """A live feed without a server: the recorder child's `LiveFeed.view` and `feed`, collecting what it makes."""

    def __init__(self) -> None:
        self.view = LiveView(bitrate_bps=1_000_000)
        self.out: list = []

    def feed(self, topic: str, log_time_ns: int, payload: dict) -> None:
        self.out += self.view.feed(topic, log_time_ns, payload)


@pytest.mark.parametrize("profile", ["sea", "cia402"])
def test_the_recorder_child_points_the_live_view_at_its_sessions_profile(tmp_path: Path, profile: str):
    """The recorder child (sea_hil/recorder/process.py) hands the live view the bus's CANopen decoder when the
    attached config is a cia402 session's: its statuswords make /live/driver; the sea profile keeps the DBC."""
    cfg = load_config(overrides={"can": {"profile": profile, "cia402": {"node_ids": [7, 8]}}})
    feed = _Feed()
    frames = tuple(RawFrame(k * MS, c, len(d), d) for k, (c, d) in enumerate(_cia402_frames()))
    with SessionRecorder(tmp_path / "s.mcap") as rec:
        _apply(rec, CanTap(), [(ATTACHMENT, CONFIG_ATTACHMENT, config_to_toml(cfg).encode(), "text/plain", 0),
                               (CANS, frames)], cast(Any, feed))
    drivers = [(m.message["node_id"], m.message["state_name"]) for m in feed.out if m.topic == "/live/driver"]
    assert drivers == ([(7, "RUNNING"), (7, "FAULT"), (7, "RUNNING")] if profile == "cia402" else [(20, "FAULT")])
