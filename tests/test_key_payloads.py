"""Every Zenoh key accepts exactly its payload types (issue 29, part 6): a well-formed payload of another type is
rejected, counted (`payload_rejected_key`) and never moves sequence state, on every key and at every receiver (the
edge's setpoint, voltage and control keys, the controller's state key). Before, a VOLTAGE on the setpoint key with
the inner loop at the edge was applied (`voltage_msgs_applied`) and displaced genuine setpoints (`seq_duplicates`).
Also: a foreign payload version is logged once per process however many nodes decode it, and every rejection class
the edge counts reaches summary.json (`rejections`, `timing.rejections`) and the end-of-run table."""
from __future__ import annotations

import logging
import uuid
from collections.abc import Iterator

import pytest
import zenoh
from paper_scheme import paper

from sea_hil.config.loader import load_config
from sea_hil.controller.edge import EdgeNode
from sea_hil.controller.remote import RemoteController
from sea_hil.protocol.keys import KEY_PAYLOADS
from sea_hil.protocol.payloads import (
    FOREIGN_VERSION_LOG,
    VERSION,
    AckPayload,
    EventStatePayload,
    MsgType,
    PayloadCounters,
    SetpointPayload,
    StatePayload,
    TriggerReason,
    VoltagePayload,
    encode,
)
from sea_hil.recorder.zenoh_tap import ZenohTap
from sea_hil.report.console import end_of_run_rows
from sea_hil.session.builder import SessionBuilder
from sea_hil.verdict.edge_blocks import REJECTION_CLASSES, TIMING_REJECTION_CLASSES, rejections_blocks

MS = 1_000_000
TH = (0.05, 0.28)


def one_of_each(seq: int, epoch: int = 1, trajectory_id: int = 0) -> dict[MsgType, bytes]:
    """A well-formed payload of every type, all with sequence number `seq` (a fresh one for every stream)."""
    z = (0.0, 0.0)
    return {MsgType.STATE: encode(StatePayload(seq, 0, 0, TH, z, z, z, epoch=epoch)),
            MsgType.EVENT_STATE: encode(EventStatePayload(seq, 0, 0, TH, z, z, z, seq, TriggerReason.INITIAL,
                                                          trajectory_id, epoch=epoch)),
            MsgType.SETPOINT: encode(SetpointPayload(seq, 0, seq, (1e-4, 0.0), z, TriggerReason.TIME, epoch=epoch)),
            MsgType.VOLTAGE: encode(VoltagePayload(seq, 0, seq, (1.0, 0.0), epoch=epoch)),
            MsgType.ACK: encode(AckPayload(seq, 0, seq, seq, True, epoch=epoch))}


@pytest.fixture
def builder() -> Iterator[SessionBuilder]:
    with SessionBuilder(load_config(overrides=paper())) as b:
        yield b


def _edge(b: SessionBuilder, inner: str = "edge") -> EdgeNode:
    return b.edge(b.bus(f"virtual:keys-{uuid.uuid4().hex[:8]}"), b.zenoh(), 1, inner=inner)


@pytest.mark.parametrize("inner,channel", [("edge", "setpoint"), ("remote", "voltage")])
def test_the_edges_downlink_key_takes_only_its_type_and_wrong_ones_never_move_the_sequence(
        builder: SessionBuilder, inner: str, channel: str) -> None:
    edge = _edge(builder, inner)
    wrong = [t for t in MsgType if t not in KEY_PAYLOADS[channel]]
    for t in wrong:                           # each with a fresh seq: before, a VOLTAGE like this was applied
        assert not edge.on_downlink(one_of_each(7)[t], channel=channel)
    st = edge.stats_dict()
    assert st["payload_rejected_key"] == len(wrong) and st["payload_rejected"] == len(wrong)
    assert edge.core.intake.sp_seq.last is None and st["seq_duplicates"] == 0 and st["stale_setpoints"] == 0
    (right,) = KEY_PAYLOADS[channel]
    assert edge.on_downlink(one_of_each(7)[right], channel=channel)      # seq 7 is still fresh
    edge.core.sample_t_ns = 0
    edge.take_downlink(0)
    st = edge.stats_dict()
    applied = st["downlink_applied"] if inner == "edge" else st["voltage_msgs_applied"]
    assert applied == 1 and st["voltage_msgs_applied" if inner == "edge" else "downlink_applied"] == 0


def test_a_voltage_on_the_voltage_key_is_refused_with_the_inner_loop_at_the_edge(builder: SessionBuilder) -> None:
    edge = _edge(builder, "edge")
    assert not edge.on_downlink(one_of_each(3)[MsgType.VOLTAGE], channel="voltage")
    st = edge.stats_dict()
    assert st["unexpected_payloads"] == 1 and st["voltage_msgs_applied"] == 0 and edge.core.intake.sp_seq.last is None
    assert edge.on_downlink(one_of_each(3)[MsgType.SETPOINT], channel="setpoint")


def test_the_edges_control_key_takes_only_acks(builder: SessionBuilder) -> None:
    edge = _edge(builder)
    wrong = [t for t in MsgType if t is not MsgType.ACK]
    assert not any(edge.on_ack(one_of_each(5)[t]) for t in wrong)
    assert edge.stats_dict()["payload_rejected_key"] == len(wrong)
    assert edge.on_ack(one_of_each(5)[MsgType.ACK])


@pytest.mark.parametrize("scheme", ["paper", "edge"])
def test_the_controllers_state_key_takes_only_states(builder: SessionBuilder, scheme: str) -> None:
    cfg = load_config(overrides=paper()) if scheme == "paper" else load_config()
    ctrl = RemoteController(cfg, builder.zenoh(), "et", cycles=1)
    try:
        wrong = [t for t in MsgType if t not in KEY_PAYLOADS["state"]]
        for t in wrong:
            ctrl.handle(one_of_each(1)[t], now_ns=MS)
        st = ctrl.stats_dict()
        assert st["payload_rejected_key"] == len(wrong) and ctrl.seq.last is None and st["states_handled"] == 0
        genuine = MsgType.STATE if scheme == "paper" else MsgType.EVENT_STATE
        ctrl.handle(one_of_each(1, trajectory_id=ctrl.trajectory_id)[genuine], now_ns=MS)
        assert ctrl.seq.last == 1                                  # the stream starts at the genuine state
    finally:
        ctrl.close()


def test_the_controller_waits_once_for_a_recorder_before_its_first_record(builder: SessionBuilder) -> None:
    """`sea-hil controller --await-recorder S` (the paper's scheme: the controller records the tracking): the first
    tracking record waits (bounded) for a subscriber of the event key; with none it goes out after the wait, counted
    (`recorder_unmatched`), and no later record waits."""
    cfg = load_config(overrides=paper())
    ctrl = RemoteController(cfg, builder.zenoh(), "et", cycles=1)
    try:
        ctrl.await_recorder_s = 0.05
        for seq in (1, 2):
            ctrl.handle(one_of_each(seq)[MsgType.STATE], now_ns=seq * MS)
        st = ctrl.stats_dict()
        assert st["states_handled"] == 2 and st["recorder_unmatched"] == 1 and ctrl.await_recorder_s == 0.0
    finally:
        ctrl.close()
    session = builder.zenoh()
    ctrl = RemoteController(cfg, session, "et", cycles=1)
    sub = session.declare_subscriber(ctrl.keys.event, zenoh.handlers.FifoChannel(4))   # the recorder is there
    try:
        ctrl.await_recorder_s = 60.0
        ctrl.handle(one_of_each(1)[MsgType.STATE], now_ns=MS)
        assert ctrl.stats_dict()["recorder_unmatched"] == 0 and sub.try_recv() is not None   # its INITIAL record
    finally:
        sub.undeclare()
        ctrl.close()


def test_a_foreign_payload_version_is_logged_once_per_process(builder: SessionBuilder,
                                                               caplog: pytest.LogCaptureFixture) -> None:
    """The edge, the recorder's Zenoh tap and the external-controller watch decode the same payloads in `sea-hil
    run`: one line for a foreign version, not one per node (or per payload)."""
    foreign = bytearray(one_of_each(1)[MsgType.SETPOINT])
    foreign[2] = VERSION + 41
    edge, tap, watch = _edge(builder), ZenohTap(), PayloadCounters()
    FOREIGN_VERSION_LOG.reset()             # once per process: forget what earlier tests logged
    with caplog.at_level(logging.WARNING, logger="sea_hil.protocol"):
        for _ in range(3):
            assert not edge.on_downlink(bytes(foreign))
            assert tap.payloads.try_decode(bytes(foreign)) is None
            assert watch.try_decode(bytes(foreign)) is None
    lines = [r for r in caplog.records if f"payload version {VERSION + 41}" in r.getMessage()]
    assert len(lines) == 1
    assert edge.stats_dict()["payload_rejected_version"] == 3 and tap.payloads.rejected["version"] == 3


def test_every_rejection_class_the_edge_counts_reaches_summary_and_table(builder: SessionBuilder) -> None:
    edge = _edge(builder)
    good = one_of_each(1)[MsgType.SETPOINT]
    driven = {"payload_rejected_length": good[:-1], "payload_rejected_magic": b"XX" + good[2:],
              "payload_rejected_version": good[:2] + bytes([VERSION + 1]) + good[3:],
              "payload_rejected_type": good[:3] + bytes([99]) + good[4:],
              "payload_rejected_key": one_of_each(1)[MsgType.STATE]}
    for data in driven.values():
        assert not edge.on_downlink(data)
    assert edge.on_downlink(good)                                   # epoch 1, seq 1
    assert not edge.on_downlink(good)                               # stale (a duplicate)
    assert not edge.on_downlink(one_of_each(2, epoch=77)[MsgType.SETPOINT])     # a foreign epoch
    assert not edge.on_downlink(encode(SetpointPayload(3, 0, 3, (0.5, 0.0), (0.0, 0.0), TriggerReason.TIME,
                                                       epoch=1)))    # out of the setpoint envelope
    assert not edge.on_downlink(one_of_each(4)[MsgType.VOLTAGE], channel="voltage")   # the inner loop is here
    stats = edge.stats_dict()
    for k in stats:               # every rejection counter the edge has is a class of the summary's map
        if k.startswith(("payload_rejected_", "epoch_")) or k in ("unexpected_payloads", "stale_setpoints",
                                                                   "late_setpoints", "late_samples"):
            assert k in REJECTION_CLASSES + TIMING_REJECTION_CLASSES, k
    det, timing = rejections_blocks(stats)
    expect = {**{k: 1 for k in driven}, "epoch_foreign": 1, "setpoints_out_of_envelope": 1, "unexpected_payloads": 1}
    assert {k: v for k, v in det.items() if v} == expect
    assert timing == {"stale_setpoints": 1}
    rows = dict(end_of_run_rows({"controller": "et", "lockstep": True, "rejections": det,
                                 "timing": {"rejections": timing}}))
    for words in ("malformed payloads (length): 1", "malformed payloads (magic): 1", "malformed payloads (version): 1",
                  "malformed payloads (type): 1", "payloads on the wrong key: 1", "foreign-epoch payloads: 1",
                  "setpoints out of envelope: 1", "unexpected payloads: 1", "stale setpoints: 1"):
        assert words in rows["warnings"], (words, rows["warnings"])


def test_the_recorder_does_not_file_a_wrong_type_under_another_topic() -> None:
    """A VOLTAGE on the setpoint key would have been recorded as /zenoh/voltage (and counted as a downlink message by
    the summary); it is counted as rejected instead, and the key's own type is recorded."""
    tap = ZenohTap()
    assert tap.records("sea/limb1/setpoint", one_of_each(1)[MsgType.VOLTAGE], 10**18) == []
    assert tap.payloads.rejected["key"] == 1
    assert [r.topic for r in tap.records("sea/limb1/setpoint", one_of_each(1)[MsgType.SETPOINT], 10**18)] \
        == ["/zenoh/setpoint"]
