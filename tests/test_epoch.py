"""Session epochs (issue 19, protocol/epoch.py): bytes recorded in one session and re-published into a second are
rejected and counted at the edge (SETPOINT) and at the controller (STATE) -- while the same bytes stamped with the
current epoch would be accepted -- and a peer of another payload version gets one log line, not one per message."""
from __future__ import annotations

import logging
import struct
import threading
import uuid

import zenoh
from faults_helpers import wait_for
from paper_scheme import paper  # these nodes speak the paper's STATE protocol

from sea_hil.config.loader import load_config
from sea_hil.controller.edge import EdgeNode
from sea_hil.controller.remote import RemoteController
from sea_hil.protocol.can_frames import Feedback
from sea_hil.protocol.epoch import EpochVerdict, PeerEpoch, new_epoch
from sea_hil.protocol.payloads import FOREIGN_VERSION_LOG, HEADER_SIZE, decode
from sea_hil.session.builder import SessionBuilder

MS = 1_000_000
SAMPLES = 100


class Capture:
    """Every payload on `keys`, as the bytes on the wire (what a capture of the first session holds)."""

    def __init__(self, session: zenoh.Session, keys: list[str]) -> None:
        self.data: dict[str, list[bytes]] = {k: [] for k in keys}
        self._lock = threading.Lock()
        self._subs = [session.declare_subscriber(k, self._add) for k in keys]

    def _add(self, s: zenoh.Sample) -> None:
        with self._lock:
            self.data[str(s.key_expr)].append(s.payload.to_bytes())

    def count(self, key: str) -> int:
        with self._lock:
            return len(self.data[key])


def feedback(k: int) -> Feedback:
    return Feedback(1, k & 0xFFFF, (k * 10_000) & 0xFFFF, (0.05 + 1e-4 * k, 0.28), (0.01, 0.0), (0.0, 0.0),
                    (0.0, 0.0))


def drive(edge: EdgeNode, ctrl: RemoteController, samples: range) -> None:
    """The edge publishes one state per sample and the controller (TT: one setpoint per state) answers it."""
    for k in samples:
        edge.core.sample_t_ns = k * 10 * MS
        _, data, _ = edge.core.publisher.publish(feedback(k), edge.core.sample_t_ns)
        ctrl.handle(data, now_ns=edge.core.sample_t_ns)


def with_epoch(data: bytes, epoch: int) -> bytes:
    return data[:HEADER_SIZE - 8] + struct.pack("<Q", epoch) + data[HEADER_SIZE:]


def test_replay_of_an_earlier_session_is_rejected_and_counted() -> None:
    cfg = load_config(overrides=paper())
    with SessionBuilder(cfg) as b:                       # session 1, captured on the wire
        session = b.zenoh()
        edge1 = b.edge(b.bus(f"virtual:epoch1-{uuid.uuid4().hex[:8]}"), session, 1)
        ctrl1 = b.controller(session, "tt")
        keys = edge1.keys
        cap = Capture(session, [keys.state, keys.setpoint])
        drive(edge1, ctrl1, range(1, SAMPLES + 1))
        assert wait_for(lambda: cap.count(keys.setpoint) == SAMPLES and cap.count(keys.state) == SAMPLES, 10.0)
        first = (edge1.core.publisher.epoch, ctrl1.epoch)
    with SessionBuilder(cfg) as b:                       # session 2: new nodes, new epochs
        session = b.zenoh()
        edge = b.edge(b.bus(f"virtual:epoch2-{uuid.uuid4().hex[:8]}"), session, 1)
        ctrl = b.controller(session, "tt")
        assert 0 not in (edge.core.publisher.epoch, ctrl.epoch) and {edge.core.publisher.epoch, ctrl.epoch}.isdisjoint(first)
        drive(edge, ctrl, range(1, 11))
        assert wait_for(lambda: edge.core.intake.sp_seq.accepted == 10, 10.0)    # the edge learned the controller's epoch
        states, setpoints = ctrl.states, edge.core.intake.sp_seq.accepted
        replay = session.declare_publisher(keys.setpoint)
        for data in cap.data[keys.setpoint]:             # session 1's setpoints 1..100, re-published
            replay.put(data)
        assert wait_for(lambda: edge.stats_dict()["epoch_foreign"] == SAMPLES, 10.0), edge.stats_dict()
        for data in cap.data[keys.state]:                # session 1's states 1..100 into the controller's intake
            ctrl.handle(data, now_ns=11 * 10 * MS)
        st, cs = edge.stats_dict(), ctrl.stats_dict()
        assert (st["epoch_foreign"], st["epoch_old"], st["controller_restarts"], st["stale_setpoints"]) == \
            (SAMPLES, 0, 0, 0)
        assert (cs["epoch_foreign"], cs["epoch_old"], cs["edge_restarts"], cs["ignored_states"]) == (SAMPLES, 0, 0, 0)
        assert edge.core.intake.sp_seq.accepted == setpoints and ctrl.states == states    # nothing of it was used
        # control: the same bytes with the current epochs would have been taken (seq 11.. are newer)
        edge.on_downlink(with_epoch(cap.data[keys.setpoint][-1], ctrl.epoch))
        ctrl.handle(with_epoch(cap.data[keys.state][-1], edge.core.publisher.epoch), now_ns=12 * 10 * MS)
        assert edge.core.intake.sp_seq.accepted == setpoints + 1 and ctrl.states == states + 1
        replay.undeclare()


def test_peer_epoch_learns_restarts_only_when_allowed_and_retires_the_old_one() -> None:
    pe = PeerEpoch("peer", logging.getLogger("test"))
    assert pe.check(7, lambda: False) is EpochVerdict.CURRENT          # learned on first contact
    assert pe.check(7, lambda: False) is EpochVerdict.CURRENT
    assert pe.check(8, lambda: False) is EpochVerdict.REJECTED         # stream alive: foreign
    assert pe.check(8, lambda: True) is EpochVerdict.RESTART           # restart condition holds
    assert pe.check(7, lambda: True) is EpochVerdict.REJECTED          # retired, even when a restart would do
    assert (pe.current, pe.restarts, pe.as_dict()) == (8, 1, {"epoch_old": 1, "epoch_foreign": 1})
    assert len({new_epoch() for _ in range(1000)}) == 1000


def test_rejections_and_foreign_versions_are_logged_once_not_per_message(caplog) -> None:
    pe = PeerEpoch("peer", logging.getLogger("sea_hil.test"))
    pe.check(1, lambda: False)
    with caplog.at_level(logging.WARNING):
        for _ in range(1000):
            pe.check(2, lambda: False)
    assert [r.getMessage().split(" rejected")[0] for r in caplog.records] == \
        ["peer: payload of foreign epoch 0000000000000002"] * 4          # at 1, 10, 100, 1000
    caplog.clear()
    with SessionBuilder(load_config(overrides=paper())) as b:
        edge = b.edge(b.bus(f"virtual:epochv-{uuid.uuid4().hex[:8]}"), b.zenoh(), 1)
        old = struct.pack("<2sBBIQ", b"SH", 1, 2, 5, 0) + struct.pack("<I4dB", 5, 1e-3, 0.0, 0.0, 0.0, 1)  # version 1
        FOREIGN_VERSION_LOG.reset()             # once per process: forget what earlier tests logged
        with caplog.at_level(logging.WARNING):
            assert not any(edge.on_downlink(old) for _ in range(500))
        assert edge.core.payloads.as_dict()["rejected"] == {"version": 500}
        assert [r.getMessage() for r in caplog.records if "version" in r.getMessage()] == \
            ["a peer sends payload version 1, this node speaks 2: its messages are dropped and counted "
             "(payload_rejected_version); run the same sea-hil release on both sides"]
        assert decode(edge.core.publisher.publish(feedback(1), 0)[1]).epoch == edge.core.publisher.epoch
