"""The CiA 402 limb core alone (frames and time in, frames out; no bus, no master library): NMT and heartbeat timing,
reset node, the drive faults and their EMCY codes (spring force, velocity, watchdog, NMT loss), the voltage mode's
saturation warning and its reset, quick stop, synchronous PDO timing, a malformed SYNC."""
from __future__ import annotations

import struct

from sea_hil.config.loader import load_config
from sea_hil.plant_emulator.canopen_slave import Frame
from sea_hil.plant_emulator.cia402_axis import State
from sea_hil.plant_emulator.cia402_drive import Cia402Limb

MS = 1_000_000
HIP, KNEE = 1, 2


def make() -> Cia402Limb:
    limb = Cia402Limb.create(load_config(overrides={"can": {"profile": "cia402"}}), (HIP, KNEE))
    assert limb.start(0) == [Frame(0x701, b"\0"), Frame(0x702, b"\0")]
    return limb


def sdo_write(limb: Cia402Limb, node: int, index: int, sub: int, fmt: str, value: int, t_ns: int = 0) -> bytes:
    data = struct.pack("<" + fmt, value)
    cmd = 0x23 | (4 - len(data)) << 2
    out = limb.receive(Frame(0x600 + node, struct.pack("<BHB", cmd, index, sub) + data.ljust(4, b"\0")), t_ns)
    return [f.data for f in out if f.can_id == 0x580 + node][0]


def sdo_read(limb: Cia402Limb, node: int, index: int, sub: int = 0, t_ns: int = 0) -> int:
    out = limb.receive(Frame(0x600 + node, struct.pack("<BHB", 0x40, index, sub) + b"\0" * 4), t_ns)
    data = [f.data for f in out if f.can_id == 0x580 + node][0]
    assert data[0] & 0xE0 == 0x40, data
    return struct.unpack_from("<i", data, 4)[0]


def emcys(frames: list[Frame], node: int) -> list[tuple[int, int]]:
    return [struct.unpack_from("<HB", f.data) for f in frames if f.can_id == 0x80 + node]


def enable(limb: Cia402Limb, node: int, mode: int, t_ns: int = 0) -> None:
    limb.receive(Frame(0x000, bytes([0x01, node])), t_ns)
    sdo_write(limb, node, 0x6060, 0, "b", mode, t_ns)
    for cw in (0x06, 0x07, 0x0F):
        sdo_write(limb, node, 0x6040, 0, "H", cw, t_ns)
    assert limb.axes[node - 1].state is State.OPERATION_ENABLED


def test_heartbeat_nmt_states_and_stopped_node() -> None:
    limb = make()
    beats = [f for f in limb.advance(250 * MS) if f.can_id == 0x701]
    assert beats == [Frame(0x701, b"\x7f")] * 2                      # at 100 and 200 ms, pre-operational
    limb.receive(Frame(0, bytes([0x01, 0])), 250 * MS)                   # start all
    assert [f for f in limb.advance(300 * MS) if f.can_id == 0x701] == [Frame(0x701, b"\x05")]
    limb.receive(Frame(0, bytes([0x02, HIP])), 300 * MS)                 # stop the hip only
    assert not [f for f in limb.receive(Frame(0x601, bytes([0x40, 0, 0x10, 0, 0, 0, 0, 0])), 300 * MS)
                if f.can_id == 0x581]                                    # no SDO in STOPPED
    assert Frame(0x701, b"\x04") in limb.advance(400 * MS)
    sdo_write(limb, KNEE, 0x1017, 0, "H", 0, 400 * MS)                   # heartbeat off
    assert not [f for f in limb.advance(700 * MS) if f.can_id == 0x702]


def test_reset_node_restores_defaults_and_boots() -> None:
    limb = make()
    sdo_write(limb, HIP, 0x6072, 0, "H", 500)
    enable(limb, HIP, 10)
    out = limb.receive(Frame(0, bytes([0x81, HIP])), MS)
    assert Frame(0x701, b"\0") in out
    assert sdo_read(limb, HIP, 0x6072, t_ns=MS) == 1000 and limb.axes[0].state is State.SWITCH_ON_DISABLED


def test_spring_force_fault_in_voltage_mode() -> None:
    limb = make()
    enable(limb, HIP, -1)
    sdo_write(limb, HIP, 0x2000, 0, "h", 12000)                          # 12 V on the hip nut
    out: list[Frame] = []
    for k in range(1, 100):
        out += limb.advance(k * MS)
        sdo_write(limb, HIP, 0x2000, 0, "h", 12000, k * MS)              # keeps the watchdog fed
        if emcys(out, HIP):
            break
    assert emcys(out, HIP) == [(0x8311, 0x21)]
    assert limb.axes[0].state is State.FAULT_REACTION_ACTIVE and limb.driver.voltage_v == (0.0, 0.0)
    limb.advance((k + 1) * MS)
    assert limb.axes[0].state is State.FAULT and sdo_read(limb, HIP, 0x6041, t_ns=(k + 1) * MS) & 0x4F == 0x08


def test_velocity_limit_and_watchdog_faults() -> None:
    limb = make()
    enable(limb, KNEE, 10)
    sdo_write(limb, KNEE, 0x607F, 0, "I", 20_000)                        # 0.02 rad/s
    sdo_write(limb, KNEE, 0x6071, 0, "h", 200)
    out = []
    for k in range(1, 200):
        out += limb.advance(k * MS)
        sdo_write(limb, KNEE, 0x6071, 0, "h", 200, k * MS)
    assert emcys(out, KNEE) == [(0x8400, 0x21)]
    enable(limb, HIP, 10, 200 * MS)
    assert emcys(limb.advance(400 * MS), HIP) == []                      # enabled, no target yet: not armed
    sdo_write(limb, HIP, 0x6071, 0, "h", 0, 400 * MS)                     # the first target arms it
    out = limb.advance(501 * MS)                                           # no target for 101 ms
    assert emcys(out, HIP) == [(0x8250, 0x11)] and limb.axes[0].watchdog_trips == 1


def test_leaving_operational_while_enabled_faults() -> None:
    limb = make()
    enable(limb, HIP, 10)
    out = limb.receive(Frame(0, bytes([0x80, HIP])), MS)                   # to pre-operational
    assert emcys(out, HIP) == [(0x8130, 0x11)]


def test_voltage_saturation_warning_in_a_pdo_and_its_reset() -> None:
    limb = make()
    enable(limb, HIP, -1)
    out = limb.receive(Frame(0x401, struct.pack("<h", 30000)), MS)         # RPDO 3, synchronous
    assert limb.driver.voltage_v == (0.0, 0.0)                           # not before the SYNC
    out += limb.receive(Frame(0x080), MS)
    assert limb.driver.voltage_v == (24.0, 0.0) and emcys(out, HIP) == [(0x3310, 0x05)]
    assert sdo_read(limb, HIP, 0x6041, t_ns=MS) & 0x80                    # warning bit
    limb.receive(Frame(0x401, struct.pack("<h", 1000)), MS)
    out = limb.receive(Frame(0x080), 2 * MS)
    assert limb.driver.voltage_v == (1.0, 0.0) and emcys(out, HIP) == [(0x0000, 0x00)]


def test_quick_stop_and_back() -> None:
    limb = make()
    enable(limb, HIP, -1)
    sdo_write(limb, HIP, 0x2000, 0, "h", 2000)
    assert limb.driver.voltage_v == (2.0, 0.0)
    sdo_write(limb, HIP, 0x6040, 0, "H", 0x02)
    assert limb.axes[0].state is State.QUICK_STOP_ACTIVE and limb.driver.voltage_v == (0.0, 0.0)
    assert sdo_read(limb, HIP, 0x6041) & 0x6F == 0x07
    sdo_write(limb, HIP, 0x6040, 0, "H", 0x0F)
    assert limb.axes[0].state is State.OPERATION_ENABLED and limb.driver.voltage_v == (2.0, 0.0)


def test_synchronous_tpdo_every_second_sync_and_bad_sync() -> None:
    limb = make()
    limb.receive(Frame(0, bytes([0x01, 0])), 0)
    sdo_write(limb, HIP, 0x1801, 1, "I", 0x8000_0281)                    # disable TPDO 2 ...
    sdo_write(limb, HIP, 0x1801, 2, "B", 2)                               # ... every 2nd SYNC ...
    assert sdo_write(limb, HIP, 0x1801, 1, "I", 0x0000_0281)[0] == 0x60   # ... enable
    assert sdo_write(limb, HIP, 0x1801, 2, "B", 245)[0] == 0x80           # reserved type: abort
    sent = [sum(f.can_id == 0x281 for f in limb.receive(Frame(0x080), k * MS)) for k in range(1, 7)]
    assert sent == [0, 1, 0, 1, 0, 1]
    out = limb.receive(Frame(0x080, b"\1\2\3"), 7 * MS)
    assert (0x8240, 0x11) in emcys(out, HIP) and limb.axes[0].slave.counters.rejected_frames == 1


def test_bus_error_is_an_emcy_warning_once() -> None:
    limb = make()
    limb.receive(Frame(0, bytes([0x01, 0])), 0)
    out = limb.note_bus_error(0) + limb.note_bus_error(0)
    assert emcys(out, HIP) == [(0x8110, 0x11)] and emcys(out, KNEE) == [(0x8110, 0x11)]
    assert sdo_read(limb, HIP, 0x6041) & 0x80                                # warning bit
    out = limb.receive(Frame(0x601, bytes([0x2F, 0x10, 0x20, 0, 1, 0, 0, 0])), 0)   # 0x2010 = 1: reset counters
    assert emcys(out, HIP) == [(0x0000, 0x00)] and not sdo_read(limb, HIP, 0x6041) & 0x80


def test_two_limbs_on_one_bus_shell() -> None:
    import uuid

    import can

    from sea_hil.plant_emulator.cia402_node import Cia402PlantNode
    channel = f"cia402-{uuid.uuid4().hex[:8]}"
    clock = [0]
    with can.Bus(interface="virtual", channel=channel) as drive_bus, \
            can.Bus(interface="virtual", channel=channel) as master:
        node = Cia402PlantNode(load_config(overrides={"can": {"profile": "cia402"}}), drive_bus, (1, 2, 3, 4),
                               now_ns=lambda: clock[0], jit=False)
        node._on_start(None)
        boot = {master.recv(1.0).arbitration_id for _ in range(4)}
        assert boot == {0x701, 0x702, 0x703, 0x704}
        node.handle(can.Message(arbitration_id=0, data=bytes([0x01, 0]), is_extended_id=False))   # all start
        node.handle(can.Message(arbitration_id=0x603, data=bytes([0x40, 0, 0x10, 0, 0, 0, 0, 0]), is_extended_id=False))
        node.handle(can.Message(arbitration_id=0x655, data=bytes(8), is_extended_id=False))       # node 0x55: not here
        got = [master.recv(1.0) for _ in range(5)]                           # 4 statusword TPDOs, 1 SDO answer
        assert sorted(m.arbitration_id for m in got) == [0x181, 0x182, 0x183, 0x184, 0x583]
        assert node.stats.foreign_frames == 1 and node.limbs[1].node_ids == (3, 4)
