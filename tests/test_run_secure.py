"""`sea-hil run --secure` (issue 19 part 1): a lockstep session with mutual TLS and the ACL, certificates generated
into the output folder, while on the same loopback port

- an intruder holding a valid certificate of the session's CA (CN `sea-hil-intruder`) gets a link (it receives
  the edge's states) and puts forged setpoints (seq far ahead of the edge's newest, the controller's epoch as the
  edge knows it -- the strongest forgery: it would pass every check but the ACL -- 1 cm deflection) and 12 V
  voltage payloads for the whole run: none reaches the edge (its intake counters) and it causes no VOLTAGE_CMD
  frame (every recorded frame is one of the edge's answers to a feedback sample);
- a plain-TCP peer gets no link at all;

and the session's results equal the offline engine's replay of the same config (which equals an insecure lockstep
run: tests/test_session.py, tests/test_session_engine.py) in every block the engine replays. The node-level control
(the same intruder gets through with the ACL off) is tests/test_secure.py.
"""
from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

import pytest
from faults_helpers import wait_for

from sea_hil.config.loader import load_config
from sea_hil.offline.session_engine import run_engine
from sea_hil.protocol.keys import Keys
from sea_hil.protocol.payloads import SetpointPayload, TriggerReason, VoltagePayload, encode
from sea_hil.protocol.zsession import free_tcp_port, make_config, open_session
from sea_hil.recorder.reader import read_session
from sea_hil.report.session_summary import session_summary
from sea_hil.session.run import RunOptions, run_session

pytestmark = pytest.mark.slow
# a 1 s gait after a 0.25 s lead-in; the safety envelope is derived for the default 10 s gait: off
# (tests/test_session.py)
SHORT = {"trajectory": {"period_s": 1.0, "lead_in_s": 0.25},
         "safety": {"drive": {"enabled": False}, "setpoint": {"enabled": False}}}
REPLAYED = ("transmissions", "tracking", "lead_in", "events_by_reason", "inter_event_s", "duration_s",
            "uplink_outside_msgs", "max_abs_voltage_v")


class Intruder:
    """Peers started once the session's nodes run (`RunOptions.on_nodes`): the CA-signed intruder, which forges
    commands until stopped, and a plain-TCP peer."""

    def __init__(self, out: Path, endpoint: str) -> None:
        self.out, self.endpoint, self.stop = out, endpoint, threading.Event()
        self.sent = self.seen_states = 0
        self.linked = self.plain_linked = False
        self.edge: Any = None
        self.errors: list[BaseException] = []
        self.thread = threading.Thread(target=self._run, daemon=True)

    def start(self, _plant: Any, edge: Any, _controller: Any) -> None:
        self.edge = edge
        self.thread.start()

    def _on_state(self, _sample: Any) -> None:
        self.seen_states += 1

    def _run(self) -> None:
        try:
            self._attack()
        except BaseException as err:   # noqa: BLE001  (reported by the test)
            self.errors.append(err)

    def _attack(self) -> None:
        z = load_config(self.out / "certs" / "intruder.toml").zenoh
        z = z.model_validate({**z.model_dump(), "connect": (self.endpoint,), "listen": ()})
        keys = Keys.from_config(z)
        intruder = open_session(z)
        plain = open_session(make_config(connect=["tcp/" + self.endpoint.split("/", 1)[1]]))
        try:
            sub = intruder.declare_subscriber(keys.state, self._on_state)
            sp_pub, v_pub = intruder.declare_publisher(keys.setpoint), intruder.declare_publisher(keys.voltage)
            self.linked = wait_for(lambda: bool(list(intruder.info.peers_zid())), 20.0) is not None
            tick = threading.Event()
            while not self.stop.is_set():
                epoch, last = self.edge.core.intake.epoch.current, self.edge.core.intake.sp_seq.last
                if epoch is not None and last is not None:   # forge far ahead of the controller's newest
                    seq = (last + 1000) & 0xFFFF_FFFF
                    sp_pub.put(encode(SetpointPayload(seq, time.monotonic_ns(), 1, (0.01, 0.01), (0.0, 0.0),
                                                      TriggerReason.ERROR_BOUND, epoch=epoch)))
                    v_pub.put(encode(VoltagePayload(seq, time.monotonic_ns(), 1, (12.0, 12.0), epoch=epoch)))
                    self.sent += 2
                self.plain_linked |= bool(list(plain.info.peers_zid()))
                tick.wait(0.005)
            sub.undeclare()
        finally:
            plain.close()
            intruder.close()


def test_secure_session_refuses_an_intruder_and_a_plain_peer_and_matches_the_replay(tmp_path: Path) -> None:
    cfg = load_config(overrides=SHORT)
    out = tmp_path / "secure"
    endpoint = f"tls/127.0.0.1:{free_tcp_port()}"
    intruder = Intruder(out, endpoint)
    try:
        summary = run_session(cfg, RunOptions(controller="et", out=out, lockstep=True, progress=False, figures=False,
                                              secure=True, listen=(endpoint,), on_nodes=intruder.start))
    finally:
        intruder.stop.set()
        intruder.thread.join(30)
    assert not intruder.thread.is_alive() and not intruder.errors, intruder.errors
    assert (out / "certs" / "ca.pem").is_file() and (out / "certs" / "edge.key").stat().st_mode & 0o077 == 0
    assert intruder.linked and intruder.seen_states > 0 and intruder.sent >= 20, vars(intruder)
    assert not intruder.plain_linked                             # plain TCP to the TLS port: no link
    edge = summary["edge"]
    assert (edge["payload_rejected"], edge["unexpected_payloads"], edge["epoch_foreign"], edge["epoch_old"],
            edge["voltage_msgs_applied"], edge["controller_restarts"]) == (0, 0, 0, 0, 0, 0)
    data = read_session(out / "session.mcap")
    sent = [m.payload for m in data.messages["/zenoh/setpoint"]]
    assert edge["downlink_applied"] == len({p["seq"] for p in sent}) and max(p["seq"] for p in sent) < 1000
    frames = [m for m in data.messages["/can/command"] if m.payload["kind"] == "voltage"]
    assert len(frames) == edge["commands_sent"] > 0             # 0 VOLTAGE_CMD frames beyond the edge's answers
    assert not [m for m in frames if (m.payload["u1_v"], m.payload["u2_v"]) == (12.0, 12.0)]   # the intruder's
    replay = session_summary(run_engine(cfg, "et").data, "et")
    assert {k: summary[k] for k in REPLAYED} == {k: replay[k] for k in REPLAYED}
