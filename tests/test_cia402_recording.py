"""The recording of a cia402 session (issue 31): the recorder's CAN tap keeps every CANopen frame in `/can/raw`, the
limb's two target-voltage RPDOs make one `/can/command`, `sea-hil export` decodes the frames with the object
dictionary's names (taken from the shipped EDS here, through python canopen: independent of the decoder), following
a PDO mapping changed over SDO, and the summary's drive latches are read from the statusword TPDOs and EMCYs.

The bus traffic is the pure limb core's (frames and time in, frames out) driven by a scripted master: boot,
a TPDO 4 remap over SDO, NMT start, the hip in voltage mode, 12 V by RPDO 3 every SYNC until the spring-force limit
faults it. The whole-session recording (`sea-hil run --can-profile cia402 --lockstep`) is checked in
tests/test_cia402_session.py."""
from __future__ import annotations

import csv
import struct
from pathlib import Path

import canopen
import pytest

from sea_hil.cli import main
from sea_hil.config.loader import config_to_toml, load_config
from sea_hil.plant_emulator.canopen_slave import Frame
from sea_hil.plant_emulator.cia402_drive import Cia402Limb
from sea_hil.protocol.cia402_decode import field_name
from sea_hil.protocol.cia402_eds import eds_path
from sea_hil.recorder.can_tap import CanTap, RawFrame
from sea_hil.recorder.meta import write_session_header
from sea_hil.recorder.reader import read_session
from sea_hil.recorder.writer import SessionRecorder
from sea_hil.report.drive_faults import drive_faults

MS = 1_000_000
HIP, KNEE = 1, 2


def _sdo(node: int, index: int, sub: int, fmt: str, value: int) -> Frame:
    data = struct.pack("<" + fmt, value)
    return Frame(0x600 + node, struct.pack("<BHB", 0x23 | (4 - len(data)) << 2, index, sub) + data.ljust(4, b"\0"))


def _bus() -> list[tuple[int, Frame]]:
    """(t_ns, frame) of everything on the bus, in bus order: the master's frames and the drive's answers."""
    cfg = load_config(overrides={"can": {"profile": "cia402"}})
    limb = Cia402Limb.create(cfg, (HIP, KNEE))
    out = [(0, f) for f in limb.start(0)]

    def send(f: Frame, t_ns: int) -> None:
        out.append((t_ns, f))
        out.extend((t_ns, a) for a in limb.receive(f, t_ns))

    for f in (_sdo(HIP, 0x1803, 1, "I", 0xC000_0481), _sdo(HIP, 0x1A03, 0, "B", 0),      # TPDO 4: torque actual
              _sdo(HIP, 0x1A03, 1, "I", 0x6077_0010), _sdo(HIP, 0x1A03, 0, "B", 1),
              _sdo(HIP, 0x1803, 1, "I", 0x4000_0481), Frame(0x000, bytes([0x01, 0])),       # NMT start all
              _sdo(HIP, 0x6060, 0, "b", -1), *(_sdo(HIP, 0x6040, 0, "H", cw) for cw in (0x06, 0x07, 0x0F))):
        send(f, 0)
    for k in range(1, 120):
        t = k * MS
        out.extend((t, f) for f in limb.advance(t))
        send(Frame(0x080), t)
        send(Frame(0x401, struct.pack("<h", 12000)), t)
        send(Frame(0x402, struct.pack("<h", 0)), t)
    return out


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[tuple[int, Frame]]]:
    bus, path = _bus(), tmp_path_factory.mktemp("cia402rec") / "run.mcap"
    tap = CanTap()
    cfg = load_config(overrides={"can": {"profile": "cia402"}})
    with SessionRecorder(path) as rec:
        write_session_header(rec, cfg)
        tap.configure(config_to_toml(cfg))   # what the recorder process does with the attached config.toml
        for t, f in bus:
            for r in tap.records(RawFrame(t, f.can_id, len(f.data), f.data)):
                rec.record(*r)
    return path, bus


def _decoded(path: Path, tmp: Path) -> list[dict[str, str]]:
    log = tmp / "run.log"
    assert main(["export", str(path), "--candump", str(log), "--csv", str(tmp / "csv")]) == 0
    with (tmp / "run.canopen.csv").open(encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def test_every_canopen_frame_is_recorded_with_its_node(recording) -> None:
    path, bus = recording
    raw = read_session(path).messages["/can/raw"]
    assert [(m.payload["can_id"], bytes.fromhex(m.payload["data_hex"])) for m in raw] == \
        [(f.can_id, f.data) for _, f in bus]
    assert [m.log_time_ns for m in raw] == [t for t, _ in bus]
    assert {m.payload["node_id"] for m in raw if m.payload["can_id"] not in (0x000, 0x080)} == {HIP, KNEE}
    assert {m.payload["node_id"] for m in raw if m.payload["can_id"] == 0x080} == {0}


def test_export_names_every_frame_from_the_eds(recording, tmp_path: Path) -> None:
    path, bus = recording
    rows = _decoded(path, tmp_path)
    assert len(rows) == len(bus)
    kinds = {r["kind"] for r in rows}
    assert kinds >= {"NMT", "SYNC", "HEARTBEAT", "EMCY", "SDO_REQUEST", "SDO_RESPONSE", "RPDO3", "TPDO1", "TPDO2",
                     "TPDO3", "TPDO4"}, kinds
    texts = [r["canopen"] for r in rows]
    assert texts[:2] == ["BOOT-UP node 1", "BOOT-UP node 2"]
    assert "NMT start all nodes" in texts and "SYNC" in texts and "HEARTBEAT node 2 OPERATIONAL" in texts
    assert "SDO download node 1: 0x1A03:01 TPDO mapping parameter 4 / Mapped object 1 = 0x60770010" in texts
    od = canopen.objectdictionary.import_od(str(eds_path("hip")), HIP)   # the shipped EDS, read by python canopen
    for n in range(3):   # TPDO 1-3: the default mapping, in the EDS's names; values from the frame's bytes
        mapped = [od[od[0x1A00 + n][s].default >> 16] for s in range(1, od[0x1A00 + n][0].default + 1)]
        row = next(r for r in rows if r["kind"] == f"TPDO{n + 1}" and r["node_id"] == str(HIP))
        fmt = "<" + "".join({"Statusword": "H", "Modes of operation display": "b"}.get(v.name, "i") for v in mapped)
        values = struct.unpack(fmt, bytes.fromhex(row["data_hex"]))
        shown = [f"0x{x:04X}" if v.name == "Statusword" else str(x) for v, x in zip(mapped, values, strict=True)]
        assert row["canopen"] == f"TPDO{n + 1} node 1: " + " ".join(
            f"{field_name(v.name)}={x}" for v, x in zip(mapped, shown, strict=True))
    tpdo4 = [r["canopen"] for r in rows if r["kind"] == "TPDO4"]   # the mapping the SDO writes gave it
    assert tpdo4 and all(t.startswith("TPDO4 node 1: torque_actual_value=") and t.count("=") == 1 for t in tpdo4)
    emcy = next(r["canopen"] for r in rows if r["kind"] == "EMCY")
    assert emcy.startswith("EMCY node 1: error_code=0x8311 error_register=0x21"), emcy
    with (tmp_path / "csv" / "can_raw.csv").open(encoding="utf-8") as fh:
        assert [r["canopen"] for r in csv.DictReader(fh)] == texts
    log = (tmp_path / "run.log").read_text(encoding="utf-8").splitlines()
    assert len(log) == len(bus) and log[0].endswith("vcan0 701#00 R")   # a plain candump -L log


def test_target_voltages_pair_into_commands_and_the_fault_is_a_latch(recording) -> None:
    path, _ = recording
    data = read_session(path)
    cmds = data.messages["/can/command"]
    assert len(cmds) == 119 and {(c.payload["u1_v"], c.payload["u2_v"]) for c in cmds} == {(12.0, 0.0)}
    assert {c.payload["node_id"] for c in cmds} == {HIP}
    latches = drive_faults(data)
    assert [(f["node_id"], f["state"], f["flags"], f["cleared"]) for f in latches] == \
        [(HIP, "FAULT", ["FORCE_LIMIT"], False)]
    assert 0 < latches[0]["t_s"] < 0.12
