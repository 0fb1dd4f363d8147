"""Issue 31's acceptance with an independent master on python-can's virtual bus: python canopen's `BaseNode402` (the
shipped EDS files) boots both SEA nodes, reads and changes their PDO configuration over SDO, walks the CiA 402 state
machine to OPERATION ENABLED, runs cyclic synchronous torque with a SYNC per millisecond of the drive's (test) clock,
and sees the limb move exactly as the plant model integrates it; then a soft-limit EMCY and FAULT, fault reset, SDO
abort codes and 1,000 malformed frames. The same rig runs on vcan0 in the UML guest (tests/socketcan/)."""
from __future__ import annotations

import queue
import struct
import uuid

import can
import pytest
from canopen.sdo.exceptions import SdoAbortedError

from sea_hil.dynamics import deflections, initial_state
from sea_hil.mechanics import limb_params
from sea_hil.plant_emulator.integrator import advance
from tests.cia402_rig import TIMEOUT_S, Rig, cia402_config

CST = "CYCLIC SYNCHRONOUS TORQUE"


@pytest.fixture
def rig():
    r = Rig(cia402_config(), "virtual", f"cia402-{uuid.uuid4().hex[:8]}")
    try:
        yield r
    finally:
        r.close()


def enable_cst(r: Rig) -> None:
    r.boot()
    for n in r.nodes:
        n.nmt.state = "OPERATIONAL"
    r.watch_tpdos()
    for n in r.nodes:
        n.state = "OPERATION ENABLED"
        n.op_mode = CST
        assert n.sdo[0x6061].raw == 10


def test_nmt_reset_sdo_identity_and_segmented_transfers(rig: Rig) -> None:
    rig.boot()
    for n in rig.nodes:
        n.sdo[0x1017].raw = 250
        n.nmt.send_command(0x82)                      # reset communication: boot-up, 0x1000-0x1FFF to defaults
        rig.wait_boot_up(n.id)
        assert n.sdo[0x1017].raw == 100
    for n, joint in zip(rig.nodes, ("hip", "knee"), strict=True):
        assert n.sdo[0x1000].raw == 0x00020192
        assert [n.sdo[0x1018][i].raw for i in range(1, 5)] == [0, 0x5EA40200, 0x10000, 0]
        assert n.sdo[0x1008].raw == f"sea-hil SEA drive ({joint})"        # 22 bytes: a segmented upload
        n.sdo.download(0x6072, 0, struct.pack("<H", 900), force_segment=True)   # a segmented download
        assert n.sdo[0x6072].raw == 900


def test_pdo_mapping_read_and_changed_over_sdo(rig: Rig) -> None:
    rig.boot()
    hip = rig.hip
    assert [v.index for v in hip.tpdo[2]] == [0x6064, 0x606C] and hip.tpdo[2].trans_type == 1
    assert [v.index for v in hip.rpdo[1]] == [0x6040, 0x6060] and hip.rpdo[1].trans_type == 255
    assert not hip.tpdo[4].enabled
    tp = hip.tpdo[4]
    tp.clear()
    tp.add_variable(0x6077)
    tp.add_variable(0x2103)
    tp.trans_type, tp.enabled = 1, True
    tp.save()
    hip.tpdo[4].read()
    assert hip.tpdo[4].enabled and [v.index for v in hip.tpdo[4]] == [0x6077, 0x2103]
    assert hip.sdo[0x1A03][0].raw == 2 and hip.sdo[0x1A03][2].raw == 0x21030020
    with pytest.raises(SdoAbortedError) as err:          # mapping changed while the PDO is valid
        hip.sdo[0x1A03][1].raw = 0x60640020
    assert err.value.code == 0x06010000
    tp.enabled = False
    tp.save()
    tp.clear()
    tp.add_variable(0x1000)                              # not mappable
    with pytest.raises(SdoAbortedError) as err:
        tp.save()
    assert err.value.code == 0x06040041


def test_cst_moves_the_limb_as_the_plant_model(rig: Rig) -> None:
    enable_cst(rig)
    cfg = rig.cfg
    p = limb_params(cfg.plant)
    x = initial_state(*cfg.plant.initial_theta_rad, 0.0, 0.0, p)
    torques = [(50, -50) if k < 150 else (-30, 40) for k in range(200)]
    limit = cfg.plant.voltage_limit_v
    for k in range(200):
        got = rig.cycle(torques[k])
        # sample k+1 integrated over period k with the torque sent in cycle k-1 (acting from SYNC k)
        t_cmd = torques[k - 2] if k >= 2 else (0, 0)
        x = advance(k * 1e-3, x, (t_cmd[0] / 1000 * limit, t_cmd[1] / 1000 * limit), 1e-3, cfg.sim.substeps, p)
        d = deflections(x, p)
        for j, values in enumerate(got):
            assert values[0x6064] == round(x[j] * 1e6), (k, j)
            assert values[0x606C] == round(x[2 + j] * 1e6), (k, j)
            assert values[0x2100] == round(d[j] * 1e9), (k, j)
            assert values[0x2101] == round(x[6 + j] * 1e9), (k, j)
    assert x[0] - cfg.plant.initial_theta_rad[0] > 0.03          # it moved: the hip by ~2.3 degrees
    assert rig.hip.sdo[0x6077].raw == -30 and rig.knee.sdo[0x6077].raw == 40
    assert rig.hip.state == "OPERATION ENABLED"


def test_soft_limit_emcy_fault_and_fault_reset(rig: Rig) -> None:
    enable_cst(rig)
    hip = rig.hip
    for _ in range(30):
        got = rig.cycle((50, 0))
    position = got[0][0x6064]
    default_max = hip.sdo[0x607D][2].raw
    hip.sdo[0x607D][2].raw = position + 2000            # 2 mrad ahead of the moving hip
    node_id, emcy = None, None
    for _ in range(100):
        rig.cycle((50, 0))
        try:
            node_id, emcy = rig.emcys.get_nowait()
            break
        except queue.Empty:
            continue
    assert node_id == hip.id and emcy.code == 0x8612 and emcy.register & 0x21 == 0x21
    rig.cycle((0, 0))
    rig.cycle(None)
    assert hip.state == "FAULT" and rig.knee.state == "OPERATION ENABLED"
    assert hip.sdo[0x603F].raw == 0x8612 and hip.sdo[0x1003][1].raw == 0x8612 and hip.sdo[0x1001].raw & 0x01
    hip.sdo[0x607D][2].raw = default_max
    rig.knee.state = "SWITCHED ON"     # else its command watchdog (0x2012, 100 ms, armed by its targets) trips
    with rig.pumping():     # canopen waits in wall-clock time for statusword TPDOs (every 50 ms of drive time)
        hip.reset_from_fault()      # controlword 0, then bit 7's rising edge, then on to OPERATION ENABLED
    assert hip.state == "OPERATION ENABLED" and hip.sdo[0x603F].raw == 0
    node_id, reset = rig.emcys.get(timeout=TIMEOUT_S)
    assert node_id == hip.id and reset.code == 0x0000 and reset.register == 0


def test_sdo_abort_codes(rig: Rig) -> None:
    rig.boot()
    sdo = rig.hip.sdo
    cases = [(lambda: sdo.upload(0x5000, 0), 0x06020000),                       # object does not exist
             (lambda: sdo.upload(0x1018, 9), 0x06090011),                       # sub-index does not exist
             (lambda: sdo.download(0x6040, 0, b"\0\0\0\0"), 0x06070010),        # length does not match
             (lambda: sdo.download(0x6041, 0, b"\0\0"), 0x06010002),            # read-only
             (lambda: sdo.upload(0x2010, 0), 0x06010001),                       # write-only
             (lambda: sdo.download(0x6060, 0, bytes([5])), 0x06090030)]         # value range (mode 5)
    for call, code in cases:
        with pytest.raises(SdoAbortedError) as err:
            call()
        assert err.value.code == code
    answers: queue.Queue[bytes] = queue.Queue()
    rig.network.subscribe(0x580 + rig.hip.id, lambda can_id, data, ts: answers.put(bytes(data)))
    rig.network.send_message(0x600 + rig.hip.id, bytes([0xE0, 0, 0x10, 0, 0, 0, 0, 0]))  # command specifier 7
    assert struct.unpack("<BHBI", answers.get(timeout=TIMEOUT_S)) == (0x80, 0x1000, 0, 0x05040001)
    rig.network.send_message(0x600 + rig.hip.id, bytes([0x21, 0x17, 0x10, 0, 2, 0, 0, 0]))  # segmented 0x1017
    assert answers.get(timeout=TIMEOUT_S)[0] == 0x60
    rig.network.send_message(0x600 + rig.hip.id, bytes([0x10 | 0x0B, 0x64, 0, 0, 0, 0, 0, 0]))  # toggle 1 first
    assert struct.unpack("<BHBI", answers.get(timeout=TIMEOUT_S)) == (0x80, 0x1017, 0, 0x05030000)
    assert sdo[0x1017].raw == 100                                              # nothing written


def test_keeps_working_after_1000_malformed_frames(rig: Rig) -> None:
    enable_cst(rig)
    hip = rig.hip
    before = hip.sdo[0x2011].raw
    bad = [(0x600 + hip.id, b"\x40\x00\x10", False, False),          # SDO request of 3 bytes
           (0x300 + hip.id, b"\x01", False, False),                  # RPDO 2 shorter than its mapping
           (0x600 + hip.id, b"", True, False),                       # remote frame on the SDO id
           (0x600 + hip.id, b"\x40\x00\x10\x00\x00\x00\x00\x00", False, True)]   # extended id
    bus = rig.network.bus
    for i in range(1000):
        can_id, data, remote, ext = bad[i % 4]
        bus.send(can.Message(arbitration_id=can_id, data=data, is_remote_frame=remote, is_extended_id=ext,
                             dlc=0 if remote else len(data)))
        if i % 50 == 49:    # an SDO round trip per 50: the drive has taken them (a socket's queue is finite)
            assert hip.sdo[0x2011].raw - before == i + 1
    node_id, emcy = rig.emcys.get(timeout=TIMEOUT_S)      # one EMCY 0x8210 for the episode, not 250
    assert node_id == hip.id and emcy.code == 0x8210 and rig.emcys.empty()
    got = rig.cycle((10, 10))
    assert got[0][0x6064] != 0 and hip.state == "OPERATION ENABLED"
    assert rig.drive.limbs[0].axes[0].slave.counters.rejected_frames == 1000 + before
