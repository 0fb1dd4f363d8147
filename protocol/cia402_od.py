"""The object dictionary of the emulated SEA drive in the CiA 402 profile: the one source of both the drive's
dictionary (`sea_hil.plant_emulator.cia402_*`) and the shipped EDS files (`protocol/cia402_eds.py` writes them;
tests/test_cia402_eds.py checks python canopen's `import_od` of the shipped file equals `object_dictionary()`).

Every node (one SEA: hip or knee) has the same dictionary; only the defaults of the soft limits and the product name
depend on the joint (`JointDefaults`). Units (docs/cia402.md): position 1 inc = 1 urad, velocity urad/s, torque
per mille of the rated torque 0x6076 (mN m), voltage mV, spring deflection nm, nut velocity nm/s, spring force mN.
COB-ID defaults are node-relative (`$NODEID+0x180` in the EDS; `Entry.node_relative`).
"""
from __future__ import annotations

import struct
from dataclasses import dataclass

from sea_hil.protocol.can_frames import ErrorFlags

BOOLEAN, INTEGER8, INTEGER16, INTEGER32, UNSIGNED8, UNSIGNED16, UNSIGNED32, VISIBLE_STRING = 1, 2, 3, 4, 5, 6, 7, 9
FORMATS = {BOOLEAN: "<B", INTEGER8: "<b", INTEGER16: "<h", INTEGER32: "<i", UNSIGNED8: "<B", UNSIGNED16: "<H",
           UNSIGNED32: "<I"}
VAR, ARRAY, RECORD = 7, 8, 9
PDO_INVALID = 0x8000_0000     # COB-ID bit 31: the PDO does not exist / is disabled
RTR_NOT_ALLOWED = 0x4000_0000
NMT_ID, SYNC_DEFAULT = 0x000, 0x080                                   # CiA 301 pre-defined connection set
BOOT, STOPPED, OPERATIONAL, PRE_OPERATIONAL = 0x00, 0x04, 0x05, 0x7F  # NMT states (the heartbeat's byte)
DEVICE_TYPE = 0x0002_0192     # CiA 402 (0x192), servo drive (bit 17 of the additional information)
VENDOR_ID = 0x0000_0000       # no CiA-assigned vendor id: an emulator (docs/cia402.md)
PRODUCT_CODE = 0x5EA4_0200
REVISION = 0x0001_0000
MODE_CST = 10                 # cyclic synchronous torque
MODE_VOLTAGE = -1             # manufacturer-specific: target motor voltage 0x2000 (the paper's input, Eq. 6)
MODES = (0, MODE_CST, MODE_VOLTAGE)
SUPPORTED_MODES = 1 << 9 | 1 << 16   # 0x6502: CST (bit 9) and manufacturer bit 16 = mode -1

# EMCY error codes (CiA 301 / CiA 402): the drive's fault or warning -> code (docs/cia402.md, Faults and EMCY)
EMCY_CODES = {ErrorFlags.POSITION_LIMIT: 0x8612,   # reference limit (software position limit 0x607D)
              ErrorFlags.VELOCITY_LIMIT: 0x8400,   # velocity speed controller (0x607F exceeded)
              ErrorFlags.FORCE_LIMIT: 0x8311,      # excess torque (SEA spring force 0x2110 exceeded)
              ErrorFlags.WATCHDOG: 0x8250,         # RPDO timeout (no target within 0x2012)
              ErrorFlags.SATURATED: 0x3310,        # output over-voltage: demand above the voltage limit (warning)
              ErrorFlags.BUS_ERROR: 0x8110}        # CAN overrun, objects lost (a send failed; warning)
EMCY_COMM_LOSS = 0x8130                            # left NMT OPERATIONAL while OPERATION ENABLED (0x6007 = 1)


@dataclass(frozen=True)
class Entry:
    """One sub-index (a VAR object is its sub-index 0)."""
    index: int
    subindex: int
    name: str
    data_type: int
    access: str                     # ro | wo | rw | const
    default: int | str
    low: int | None = None
    high: int | None = None
    pdo_mappable: bool = False
    node_relative: bool = False     # default = node id + `default`

    @property
    def size(self) -> int:
        """Bytes on the wire (strings: their default's length; they are read-only here)."""
        if self.data_type == VISIBLE_STRING:
            return len(str(self.default).encode("ascii"))
        return struct.calcsize(FORMATS[self.data_type])

    @property
    def readable(self) -> bool:
        return self.access != "wo"

    @property
    def writable(self) -> bool:
        return self.access in ("rw", "wo")

    def default_for(self, node_id: int) -> int | str:
        return int(self.default) + node_id if self.node_relative else self.default

    def encode(self, value: int | str) -> bytes:
        if self.data_type == VISIBLE_STRING:
            return str(value).encode("ascii")
        return struct.pack(FORMATS[self.data_type], int(value))

    def decode(self, data: bytes) -> int:
        return int(struct.unpack(FORMATS[self.data_type], data)[0])


@dataclass(frozen=True)
class Obj:
    index: int
    name: str
    object_type: int
    entries: tuple[Entry, ...]


@dataclass(frozen=True)
class JointDefaults:
    """The joint-dependent defaults (from `[safety.drive]` and `[can]`): soft limits and the product name."""
    joint: str                       # "hip" | "knee"
    position_min_urad: int
    position_max_urad: int
    velocity_max_urad_s: int
    spring_force_max_mn: int
    heartbeat_ms: int
    watchdog_ms: int
    rated_torque_mnm: int
    voltage_limit_mv: int


def _var(index: int, name: str, dt: int, access: str, default: int | str, **kw: object) -> Obj:
    return Obj(index, name, VAR, (Entry(index, 0, name, dt, access, default, **kw),))  # type: ignore[arg-type]


def _record(index: int, name: str, subs: list[tuple[str, int, str, int | str, dict[str, object]]],
            object_type: int = RECORD) -> Obj:
    entries = [Entry(index, 0, "Highest sub-index supported", UNSIGNED8, "ro", len(subs))]
    entries += [Entry(index, i + 1, n, dt, acc, d, **kw) for i, (n, dt, acc, d, kw) in enumerate(subs)]  # type: ignore[arg-type]
    return Obj(index, name, object_type, tuple(entries))


# Default PDO set (docs/cia402.md, "Default PDO mapping"): (COB-ID base, transmission type, mapped (index, bits)).
RPDO_DEFAULTS = ((0x200, 255, ((0x6040, 16), (0x6060, 8))),
                 (0x300, 1, ((0x6071, 16),)),
                 (0x400, 1, ((0x2000, 16),)),
                 (0x500 | PDO_INVALID, 1, ()))
TPDO_DEFAULTS = ((0x180, 255, ((0x6041, 16), (0x6061, 8))),
                 (0x280, 1, ((0x6064, 32), (0x606C, 32))),
                 (0x380, 1, ((0x2100, 32), (0x2101, 32))),
                 (0x480 | PDO_INVALID, 1, ((0x6077, 16), (0x2001, 16), (0x2103, 32))))


TPDO_EVENT_TIMER_MS = 50   # the event-driven statusword TPDO also every 50 ms (canopen's BaseNode402 waits 0.2 s)


def _pdo_objects(tx: bool) -> list[Obj]:
    out = []
    for n, (cob, ttype, mapped) in enumerate(TPDO_DEFAULTS if tx else RPDO_DEFAULTS):
        kind = "TPDO" if tx else "RPDO"
        comm: list[tuple[str, int, str, int | str, dict[str, object]]] = [
            (f"COB-ID used by {kind}", UNSIGNED32, "rw", (cob | RTR_NOT_ALLOWED) if tx else cob,
             {"node_relative": True}),
            ("Transmission type", UNSIGNED8, "rw", ttype, {})]
        if tx:
            comm += [("Inhibit time", UNSIGNED16, "rw", 0, {}), ("Reserved", UNSIGNED8, "rw", 0, {}),
                     ("Event timer", UNSIGNED16, "rw", TPDO_EVENT_TIMER_MS if ttype >= 254 else 0, {})]
        out.append(_record((0x1800 if tx else 0x1400) + n, f"{kind} communication parameter {n + 1}", comm))
        entries = [Entry((0x1A00 if tx else 0x1600) + n, 0, "Number of mapped objects", UNSIGNED8, "rw", len(mapped),
                         0, 8)]
        for i in range(8):
            value = mapped[i][0] << 16 | mapped[i][1] if i < len(mapped) else 0
            entries.append(Entry((0x1A00 if tx else 0x1600) + n, i + 1, f"Mapped object {i + 1}", UNSIGNED32, "rw",
                                 value))
        out.append(Obj((0x1A00 if tx else 0x1600) + n, f"{kind} mapping parameter {n + 1}", RECORD, tuple(entries)))
    return out


def object_dictionary(j: JointDefaults) -> tuple[Obj, ...]:
    """Every object of one node, in index order."""
    objs = [
        _var(0x1000, "Device type", UNSIGNED32, "ro", DEVICE_TYPE),
        _var(0x1001, "Error register", UNSIGNED8, "ro", 0),
        Obj(0x1003, "Pre-defined error field", ARRAY, (
            Entry(0x1003, 0, "Number of errors", UNSIGNED8, "rw", 0, 0, 0),
            *(Entry(0x1003, i, f"Standard error field {i}", UNSIGNED32, "ro", 0) for i in range(1, 9)))),
        _var(0x1005, "COB-ID SYNC", UNSIGNED32, "rw", 0x80),
        _var(0x1008, "Manufacturer device name", VISIBLE_STRING, "const", f"sea-hil SEA drive ({j.joint})"),
        _var(0x1009, "Manufacturer hardware version", VISIBLE_STRING, "const", "emulated"),
        _var(0x100A, "Manufacturer software version", VISIBLE_STRING, "const", "sea-hil cia402 1"),
        _var(0x1014, "COB-ID EMCY", UNSIGNED32, "rw", 0x80, node_relative=True),
        _var(0x1017, "Producer heartbeat time", UNSIGNED16, "rw", j.heartbeat_ms),
        _record(0x1018, "Identity object", [("Vendor-ID", UNSIGNED32, "ro", VENDOR_ID, {}),
                                            ("Product code", UNSIGNED32, "ro", PRODUCT_CODE, {}),
                                            ("Revision number", UNSIGNED32, "ro", REVISION, {}),
                                            ("Serial number", UNSIGNED32, "ro", 0, {})]),
        *_pdo_objects(tx=False), *_pdo_objects(tx=True),
        _var(0x2000, "Target voltage", INTEGER16, "rw", 0, low=-j.voltage_limit_mv, high=j.voltage_limit_mv,
             pdo_mappable=True),
        _var(0x2001, "Voltage actual value", INTEGER16, "ro", 0, pdo_mappable=True),
        _var(0x2010, "Reset counters", UNSIGNED8, "wo", 0, low=1, high=1),
        _var(0x2011, "Rejected frames", UNSIGNED32, "ro", 0, pdo_mappable=True),
        _var(0x2012, "Command watchdog time", UNSIGNED16, "rw", j.watchdog_ms),
        _var(0x2100, "Spring deflection", INTEGER32, "ro", 0, pdo_mappable=True),
        _var(0x2101, "Nut velocity", INTEGER32, "ro", 0, pdo_mappable=True),
        _var(0x2102, "Nut position", INTEGER32, "ro", 0, pdo_mappable=True),
        _var(0x2103, "Spring joint torque", INTEGER32, "ro", 0, pdo_mappable=True),
        _var(0x2110, "Spring force limit", UNSIGNED32, "rw", j.spring_force_max_mn, low=1),
        _var(0x603F, "Error code", UNSIGNED16, "ro", 0, pdo_mappable=True),
        _var(0x6040, "Controlword", UNSIGNED16, "rw", 0, pdo_mappable=True),
        _var(0x6041, "Statusword", UNSIGNED16, "ro", 0, pdo_mappable=True),
        _var(0x6060, "Modes of operation", INTEGER8, "rw", 0, pdo_mappable=True),
        _var(0x6061, "Modes of operation display", INTEGER8, "ro", 0, pdo_mappable=True),
        _var(0x6064, "Position actual value", INTEGER32, "ro", 0, pdo_mappable=True),
        _var(0x606C, "Velocity actual value", INTEGER32, "ro", 0, pdo_mappable=True),
        _var(0x6071, "Target torque", INTEGER16, "rw", 0, pdo_mappable=True),
        _var(0x6072, "Max torque", UNSIGNED16, "rw", 1000, low=0, high=1000),
        _var(0x6076, "Motor rated torque", UNSIGNED32, "ro", j.rated_torque_mnm),
        _var(0x6077, "Torque actual value", INTEGER16, "ro", 0, pdo_mappable=True),
        Obj(0x607D, "Software position limit", ARRAY, (
            Entry(0x607D, 0, "Highest sub-index supported", UNSIGNED8, "ro", 2),
            Entry(0x607D, 1, "Min position limit", INTEGER32, "rw", j.position_min_urad),
            Entry(0x607D, 2, "Max position limit", INTEGER32, "rw", j.position_max_urad))),
        _var(0x607F, "Max profile velocity", UNSIGNED32, "rw", j.velocity_max_urad_s, low=1),
        _var(0x6502, "Supported drive modes", UNSIGNED32, "ro", SUPPORTED_MODES),
    ]
    return tuple(sorted(objs, key=lambda o: o.index))


def entries_by_key(objs: tuple[Obj, ...]) -> dict[tuple[int, int], Entry]:
    return {(e.index, e.subindex): e for o in objs for e in o.entries}


def joint_defaults(cfg: object, joint: int) -> JointDefaults:
    """The defaults of joint 0 (hip) or 1 (knee) from a `SeaHilConfig` (`[safety.drive]`, `[can]`, `[can.cia402]`,
    `[plant] voltage_limit_v`); limits off (`[safety.drive] enabled = false`) = the widest values the types hold."""
    drive, can = cfg.safety.drive, cfg.can      # type: ignore[attr-defined]
    on = drive.enabled
    return JointDefaults(
        joint=("hip", "knee")[joint],
        position_min_urad=round(drive.position_min_rad[joint] * 1e6) if on else -(2 ** 31),
        position_max_urad=round(drive.position_max_rad[joint] * 1e6) if on else 2 ** 31 - 1,
        velocity_max_urad_s=round(drive.velocity_max_rad_s[joint] * 1e6) if on else 2 ** 32 - 1,
        spring_force_max_mn=round(drive.spring_force_max_n[joint] * 1e3) if on else 2 ** 32 - 1,
        heartbeat_ms=round(1000.0 / can.heartbeat_rate_hz),
        watchdog_ms=round(can.watchdog_timeout_s * 1000.0),
        rated_torque_mnm=can.cia402.rated_torque_mnm,
        voltage_limit_mv=round(cfg.plant.voltage_limit_v * 1000.0))   # type: ignore[attr-defined]
