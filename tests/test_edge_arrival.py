"""The edge applies a setpoint on arrival in real time (`EdgeNode.on_arrival`): the voltage it gives with the newest
feedback goes out at once, not at the next feedback sample; lockstep keeps applying at the sample."""
from __future__ import annotations

import uuid
from collections.abc import Iterator

import can
import pytest

from sea_hil.config.loader import load_config
from sea_hil.controller.edge import EdgeNode
from sea_hil.mechanics import limb_params
from sea_hil.plant_emulator.disturbance import make_disturbance
from sea_hil.plant_emulator.driver import DriverCore
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import VoltageCmd
from sea_hil.protocol.payloads import SetpointPayload, TriggerReason, encode
from sea_hil.session.builder import SessionBuilder

NODE = 1


@pytest.fixture
def rig() -> Iterator[tuple[EdgeNode, can.BusABC, DriverCore]]:
    cfg = load_config()
    channel = f"virtual:arrival-{uuid.uuid4().hex[:8]}"
    drv = DriverCore.create(NODE, limb_params(cfg.plant), 1e-3, 0.1, cfg.sim.substeps,
                            tuple(cfg.plant.initial_theta_rad), make_disturbance(cfg.disturbance))
    with SessionBuilder(cfg) as b:
        edge = b.edge(b.bus(channel), b.zenoh(), NODE)
        yield edge, b.bus(channel), drv


def _feed(edge: EdgeNode, drv: DriverCore, codec: SeaCodec) -> None:
    for msg in codec.encode_feedback(drv.step(), saturate=True):
        edge.on_can(msg, 0)


def _commands(peer: can.BusABC, codec: SeaCodec) -> list[VoltageCmd]:
    out = []
    while (msg := peer.recv(timeout=0)) is not None:
        frame = codec.decode(msg)
        if isinstance(frame, VoltageCmd):
            out.append(frame)
    return out


def _setpoint(seq: int, state_seq: int, deflection_m: tuple[float, float]) -> bytes:
    return encode(SetpointPayload(seq, 0, state_seq, deflection_m, (0.1, -0.1), TriggerReason.ERROR_BOUND))


def test_setpoint_is_applied_on_arrival_with_the_newest_feedback(rig) -> None:
    edge, peer, drv = rig
    codec = SeaCodec([NODE])
    for _ in range(10):                       # sample 10: the edge publishes state 1
        _feed(edge, drv, codec)
    edge.on_arrival(_setpoint(1, 1, (1e-4, 1e-4)), rx_ns=1)
    first = _commands(peer, codec)
    assert len(first) == 1 and edge.core.counters.arrival_commands == 1   # sent at once, before the next sample
    assert first[0].seq == edge.core.last_fb.seq                         # computed from the newest feedback
    edge.on_arrival(_setpoint(2, 1, (-2e-4, 3e-4)), rx_ns=2)
    second = _commands(peer, codec)
    assert len(second) == 1 and second[0].voltage_v != first[0].voltage_v   # the new v_x changed the voltage
    edge.on_arrival(_setpoint(2, 1, (5e-4, 5e-4)), rx_ns=3)                # stale seq: dropped, nothing sent
    assert _commands(peer, codec) == [] and edge.core.counters.stale_setpoints == 1
    assert edge.stats_dict()["arrival_commands"] == 2 and edge.core.counters.setpoints == 2


def test_arrival_before_any_feedback_or_after_stop_sends_nothing(rig) -> None:
    edge, peer, drv = rig
    codec = SeaCodec([NODE])
    edge.on_arrival(_setpoint(1, 1, (1e-4, 1e-4)), rx_ns=1)   # no feedback yet: held, applied at the first sample
    assert _commands(peer, codec) == [] and edge.core.counters.arrival_commands == 0
    _feed(edge, drv, codec)
    assert len(_commands(peer, codec)) == 1 and edge.core.counters.setpoints == 1
    edge.stop_event.set()
    edge.on_arrival(_setpoint(2, 1, (1e-4, 1e-4)), rx_ns=2)
    assert _commands(peer, codec) == [] and edge.core.counters.arrival_commands == 0


def test_delayed_setpoint_waits_for_its_sample(rig) -> None:
    edge, peer, drv = rig
    codec = SeaCodec([NODE])
    cfg = load_config(overrides={"link": {"downlink": {"delay_s": 0.003}}})
    edge.core.intake.downlink = type(edge.core.intake.downlink)(cfg.link.downlink, "t/down")
    for _ in range(10):
        _feed(edge, drv, codec)
    _commands(peer, codec)
    edge.on_arrival(_setpoint(1, 1, (1e-4, 1e-4)), rx_ns=1)
    assert _commands(peer, codec) == [] and edge.core.counters.setpoints == 0    # the emulated link still holds it
    for _ in range(3):
        _feed(edge, drv, codec)
    assert edge.core.counters.setpoints == 1 and edge.core.counters.arrival_commands == 0
    cmds = _commands(peer, codec)     # no setpoint yet -> no command; then the sample that released it answers
    assert [c.seq for c in cmds] == [edge.core.last_fb.seq] == [13]
