"""Replay safety: stale or duplicated sequence numbers are ignored and counted -- setpoints/voltages at the edge,
states at the controller -- and a restarted sender (a new session epoch) is accepted only after its old stream timed
out; the old epoch is refused from then on (replays across sessions: tests/test_epoch.py)."""
from __future__ import annotations

import uuid
from collections.abc import Iterator

import pytest
from paper_scheme import paper  # these nodes speak the paper's STATE protocol

from sea_hil.config.loader import load_config
from sea_hil.controller.edge import EdgeNode
from sea_hil.controller.remote import RemoteController
from sea_hil.protocol.payloads import SetpointPayload, StatePayload, TriggerReason, VoltagePayload, encode
from sea_hil.session.builder import SessionBuilder

MS = 1_000_000


@pytest.fixture
def nodes() -> Iterator[tuple[EdgeNode, RemoteController]]:
    with SessionBuilder(load_config(overrides=paper())) as b:
        session = b.zenoh()
        yield b.edge(b.bus(f"virtual:replay-{uuid.uuid4().hex[:8]}"), session, 1), b.controller(session, "tt")


def setpoint(seq: int, d1: float = 0.001, reason: TriggerReason = TriggerReason.ERROR_BOUND, epoch: int = 1) -> bytes:
    return encode(SetpointPayload(seq, 0, seq, (d1, 0.0), (0.0, 0.0), reason, epoch=epoch))


def state(seq: int, sample_t_ns: int, epoch: int = 1) -> bytes:
    return encode(StatePayload(seq, 0, sample_t_ns, (0.05, 0.28), (0.0, 0.0), (0.0, 0.0), (0.0, 0.0), epoch=epoch))


def apply(edge: EdgeNode, now_ns: int) -> None:
    edge.core.sample_t_ns = now_ns
    edge.take_downlink(now_ns)


def test_edge_ignores_and_counts_duplicated_and_older_setpoints(nodes: tuple[EdgeNode, RemoteController]) -> None:
    edge, _ = nodes
    verdicts = [edge.on_downlink(setpoint(s, d1=s * 1e-4)) for s in (1, 2, 2, 5, 3, 5, 1, 6)]
    assert verdicts == [True, True, False, True, False, False, False, True]
    apply(edge, 0)
    c = edge.core.counters
    assert c.stale_setpoints == 4 and c.setpoints == 4            # 1, 2, 5, 6 applied
    assert edge.core.inner.deflection_m == pytest.approx((6e-4, 0.0))
    st = edge.stats_dict()
    assert (st["stale_setpoints"], st["seq_duplicates"], st["seq_reordered"]) == (4, 3, 1)


def test_edge_voltage_stream_shares_the_replay_guard() -> None:
    with SessionBuilder(load_config(overrides=paper())) as b:   # voltages: the inner loop in the controller
        edge = b.edge(b.bus(f"virtual:replay-{uuid.uuid4().hex[:8]}"), b.zenoh(), 1, inner="remote")
        v = [encode(VoltagePayload(s, 0, s, (float(s), 0.0))) for s in (10, 10, 9, 11)]
        assert [edge.on_downlink(x, channel="voltage") for x in v] == [True, False, False, True]
        apply(edge, 0)
        assert edge.core.counters.voltages == 2 and edge.core.voltage == (11.0, 0.0)
        assert edge.core.counters.stale_setpoints == 2


def test_restarted_controller_is_accepted_only_after_the_stream_timed_out(
        nodes: tuple[EdgeNode, RemoteController]) -> None:
    edge, _ = nodes
    edge.core.sample_t_ns = 1000 * MS
    for s in range(1, 101):
        assert edge.on_downlink(setpoint(s))
    apply(edge, 1000 * MS)
    timeout_ms = edge.core.intake.timeout_ns // MS
    edge.core.sample_t_ns = (1000 + timeout_ms) * MS                 # still fresh: a new epoch's seq 1 is refused
    assert not edge.on_downlink(setpoint(1, reason=TriggerReason.INITIAL, epoch=2))
    assert not edge.on_downlink(setpoint(1, reason=TriggerReason.INITIAL))   # the old epoch's seq 1 is stale
    edge.core.sample_t_ns = (1001 + timeout_ms) * MS                 # timed out (driver safe): the old epoch's seq 1
    assert not edge.on_downlink(setpoint(1))                     # is still stale (a restart has a new epoch),
    assert not edge.on_downlink(setpoint(edge.core.intake.sp_seq.window, epoch=2))   # a new epoch with seq >= window
    assert edge.on_downlink(setpoint(1, reason=TriggerReason.INITIAL, epoch=2))  # refused, a fresh sender's not
    assert not edge.on_downlink(setpoint(1, epoch=2))            # and the new stream is guarded again
    assert edge.on_downlink(setpoint(2, epoch=2))
    assert not edge.on_downlink(setpoint(101))                   # the old epoch is retired
    assert edge.core.counters.controller_restarts == 1 and edge.core.counters.stale_setpoints == 3
    st = edge.stats_dict()
    assert (st["controller_restarts"], st["epoch_foreign"], st["epoch_old"]) == (1, 2, 1)


def test_controller_ignores_and_counts_duplicated_and_older_states(nodes: tuple[EdgeNode, RemoteController]) -> None:
    _, ctrl = nodes
    for s, t_ms in ((1, 0), (2, 10), (2, 10), (4, 30), (3, 20), (1, 0), (5, 40)):
        ctrl.handle(state(s, t_ms * MS), now_ns=t_ms * MS)
    assert ctrl.states == 4 and ctrl.setpoint_seq == 4           # TT: one setpoint per handled state
    st = ctrl.stats_dict()
    assert st["ignored_states"] == 3 and st["state_seq_duplicates"] == 2 and st["state_seq_reordered"] == 1


def test_controller_accepts_a_restarted_edge_after_silence_and_continues_the_trajectory(
        nodes: tuple[EdgeNode, RemoteController]) -> None:
    _, ctrl = nodes
    for s in range(1, 201):
        ctrl.handle(state(s, s * 10 * MS), now_ns=s * 10 * MS)
    gap_ns = ctrl.restart_gap_ns
    stopped_at = ctrl._last_t_ns        # 1990 ms after the first state, minus the lead-in
    assert stopped_at == 1990 * MS - ctrl.lead_in_ns
    ctrl.handle(state(1, 7 * MS, epoch=2), now_ns=2000 * MS)     # within the gap: refused
    ctrl.handle(state(1, 7 * MS), now_ns=2000 * MS + gap_ns + 1)  # the old epoch after the gap: stale
    assert ctrl.states == 200 and ctrl.edge_restarts == 0
    ctrl.handle(state(1, 7 * MS, epoch=2), now_ns=2000 * MS + gap_ns + 1)  # new edge: sample time restarts near 0
    assert ctrl.states == 201 and ctrl.edge_restarts == 1
    assert ctrl._last_t_ns == stopped_at                           # trajectory time continues where it stopped
    ctrl.handle(state(2, 17 * MS, epoch=2), now_ns=2100 * MS + gap_ns)
    assert ctrl.states == 202 and ctrl._last_t_ns == stopped_at + 10 * MS
    ctrl.handle(state(201, 2010 * MS), now_ns=2110 * MS + gap_ns)  # the old epoch, newer seq: retired, refused
    st = ctrl.stats_dict()
    assert ctrl.states == 202 and (st["epoch_foreign"], st["epoch_old"], st["ignored_states"]) == (1, 1, 1)
