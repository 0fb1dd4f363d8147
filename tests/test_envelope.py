"""The edge's setpoint envelope (controller/envelope.py): an out-of-envelope SETPOINT is rejected, counted and never
applied; the voltage the edge sends is the one of the setpoint it held before."""
from __future__ import annotations

import logging
import math

import pytest
from test_edge_arrival import rig  # noqa: F401  (fixture: an EdgeNode on a virtual bus + a DriverCore)

from sea_hil.config.loader import load_config
from sea_hil.controller.edge import EdgeNode
from sea_hil.controller.envelope import EnvelopeGate, SetpointEnvelope
from sea_hil.controller.inner import limited_voltage
from sea_hil.plant_emulator.driver import DriverCore
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import ClearErrors, DriverState, ErrorFlags, Heartbeat, VoltageCmd
from sea_hil.protocol.payloads import SetpointPayload, TriggerReason, encode

NODE = 1
CFG = load_config()


def test_envelope_checks_each_joint_and_non_finite_values() -> None:
    env = SetpointEnvelope.from_config(CFG.safety.setpoint)
    assert env.deflection_max_m == (0.002, 0.002)
    assert env.check((0.0007, -0.002)).ok and env.check((-0.002, 0.0)).ok
    for bad in ((0.0021, 0.0), (0.0, -0.0021), (0.01, 0.0), (math.nan, 0.0), (0.0, math.inf)):
        verdict = env.check(bad)
        assert not verdict.ok and "v_x" in verdict.reason, bad
    off = SetpointEnvelope.from_config(load_config(overrides={"safety": {"setpoint": {"enabled": False}}})
                                       .safety.setpoint)
    assert off.check((0.03, -0.03)).ok and not off.check((math.nan, 0.0)).ok


def test_gate_counts_every_rejection_and_logs_a_bounded_number(caplog: pytest.LogCaptureFixture) -> None:
    gate = EnvelopeGate(SetpointEnvelope((0.001, 0.001)), logging.getLogger("test.envelope"))
    with caplog.at_level(logging.WARNING, logger="test.envelope"):
        results = [gate.admit(seq, (0.01, 0.0)) for seq in range(1000)]
    assert not any(results) and gate.rejected == 1000
    assert len(caplog.records) == 10 + 6      # 1..10, then 16, 32, 64, 128, 256, 512
    assert gate.admit(1000, (0.0005, 0.0)) and gate.rejected == 1000


def _sample(edge: EdgeNode, drv: DriverCore, peer: object, codec: SeaCodec) -> list[VoltageCmd]:
    """One driver sample through the edge; the VOLTAGE_CMDs it answered with."""
    for msg in codec.encode_feedback(drv.step(), saturate=True):
        edge.on_can(msg, 0)
    out = []
    while (msg := peer.recv(timeout=0)) is not None:   # type: ignore[attr-defined]
        frame = codec.decode(msg)
        if isinstance(frame, VoltageCmd):
            drv.handle(frame, 0)
            out.append(frame)
    return out


def _setpoint(seq: int, deflection_m: tuple[float, float]) -> bytes:
    return encode(SetpointPayload(seq, 0, 1, deflection_m, (0.1, -0.1), TriggerReason.ERROR_BOUND))


def test_out_of_envelope_setpoint_is_rejected_counted_and_never_applied(rig) -> None:  # noqa: F811
    edge, peer, drv = rig
    codec = SeaCodec([NODE])
    for _ in range(10):
        _sample(edge, drv, peer, codec)
    assert edge.on_downlink(_setpoint(1, (3e-4, -1e-4)))       # inside: accepted and applied at the next sample
    _sample(edge, drv, peer, codec)
    held = edge.core.inner.deflection_m
    assert held == (3e-4, -1e-4) and edge.core.counters.setpoints == 1
    # the example: a valid-looking SETPOINT with a 1 cm deflection (~200 N of spring force)
    assert not edge.on_downlink(_setpoint(2, (0.01, -1e-4)))
    assert not edge.on_downlink(_setpoint(3, (3e-4, -0.0025)))   # the knee out (NaN never decodes: payloads.py)
    cmds = _sample(edge, drv, peer, codec)
    assert edge.core.inner.deflection_m == held and edge.core.counters.setpoints == 1   # never applied
    assert edge.stats_dict()["setpoints_out_of_envelope"] == 2
    fb = edge.core.last_fb
    m = (*fb.theta_rad, *fb.omega_rad_s, *fb.delta_m, *fb.nut_vel_m_s)
    held_u = limited_voltage(m, held, edge.core.inner.sliding, edge.core.inner._p, edge.core.inner.gains, 24.0)[:2]
    bad_u = limited_voltage(m, (0.01, -1e-4), edge.core.inner.sliding, edge.core.inner._p, edge.core.inner.gains, 24.0)[:2]
    assert len(cmds) == 1 and cmds[0].voltage_v == pytest.approx(held_u, abs=1e-3)   # the held setpoint's voltage
    assert abs(bad_u[0] - held_u[0]) > 1.0                                          # not the rejected one's
    assert edge.on_downlink(_setpoint(4, (-2e-4, 2e-4)))        # the stream goes on after a rejection
    _sample(edge, drv, peer, codec)
    assert edge.core.inner.deflection_m == (-2e-4, 2e-4) and edge.core.counters.setpoints == 2


@pytest.mark.parametrize("flags,cleared", [(ErrorFlags.WATCHDOG, True), (ErrorFlags.POSITION_LIMIT, False),
                                           (ErrorFlags.WATCHDOG | ErrorFlags.FORCE_LIMIT, False)])
def test_edge_clears_a_watchdog_fault_but_not_a_limit_fault(rig, flags: ErrorFlags,  # noqa: F811
                                                            cleared: bool) -> None:
    edge, peer, drv = rig
    codec = SeaCodec([NODE])
    _sample(edge, drv, peer, codec)
    assert edge.on_downlink(_setpoint(1, (3e-4, -1e-4)))
    _sample(edge, drv, peer, codec)
    edge.on_can(codec.encode(Heartbeat(NODE, DriverState.FAULT, flags, 0, 0, 1)), 0)
    for msg in codec.encode_feedback(drv.step(), saturate=True):
        edge.on_can(msg, 0)
    frames = [codec.decode(m) for m in iter(lambda: peer.recv(timeout=0), None)]
    assert any(isinstance(f, ClearErrors) for f in frames) is cleared
    assert edge.core.counters.clear_errors_sent == int(cleared)
