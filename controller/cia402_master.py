"""The edge's CANopen master for one limb in the CiA 402 profile (issue 31, step 4; not yet in `sea-hil run`): a pure
core (frames and time in, frames out; no plant import). Start-up as a CANopen master does it: reset communication,
wait for both boot-ups, configure by SDO (RPDO 3, target voltage, to transmission type 255 so a voltage acts on
arrival as in the sea profile; modes of operation -1, the paper's voltage input), walk the CiA 402 state machine
(shutdown, switch on, enable operation), NMT start. Then per SYNC: the SYNC frame out, TPDO 2 and 3 of both nodes in
(position, velocity, spring deflection, nut velocity: the inner loop's measurement), one RPDO 3 per node out with
the voltages. A FAULT statusword or an EMCY is counted, each statusword's drive state (`drive_state`,
`protocol.cia402_drive_state`) is the edge's latch count's input; `fault_reset()` clears it the way the edge clears the sea
profile's errors (controlword bit 7 rising edge, then the walk again). PDO layouts and units come from
`protocol.cia402_od`, the source of the drive's EDS."""
from __future__ import annotations

import struct
from dataclasses import dataclass, field
from typing import NamedTuple

from sea_hil.protocol.can_frames import Heartbeat
from sea_hil.protocol.cia402_drive_state import Cia402DriveStates
from sea_hil.protocol.cia402_od import MODE_VOLTAGE, PDO_INVALID


class Frame(NamedTuple):
    can_id: int
    data: bytes = b""


Measurement = tuple[float, float, float, float, float, float, float, float]   # th1 th2 w1 w2 d1 d2 rd1 rd2
WALK = (0x06, 0x07, 0x0F)


def _sdo_write(node: int, index: int, sub: int, fmt: str, value: int) -> Frame:
    data = struct.pack("<" + fmt, value)
    return Frame(0x600 + node, struct.pack("<BHB", 0x23 | (4 - len(data)) << 2, index, sub) + data.ljust(4, b"\0"))


def setup_writes(node: int) -> list[Frame]:
    """The SDO writes that configure one node for the inner loop (in pre-operational)."""
    return [_sdo_write(node, 0x1402, 1, "I", PDO_INVALID | 0x400 + node),    # disable RPDO 3
            _sdo_write(node, 0x1402, 2, "B", 255),                           # event-driven: acts on arrival
            _sdo_write(node, 0x1402, 1, "I", 0x400 + node),                  # enable
            _sdo_write(node, 0x6060, 0, "b", MODE_VOLTAGE),
            *(_sdo_write(node, 0x6040, 0, "H", cw) for cw in WALK)]


# the shortest payload each function code's frame this master reads may have (SDO reply, TPDO 1, TPDO 2 / 3)
MIN_BYTES = {0x580: 8, 0x180: 2, 0x280: 8, 0x380: 8}


@dataclass
class MasterCounters:
    sdo_aborts: int = 0
    emcys: int = 0
    faults: int = 0
    syncs: int = 0
    incomplete_syncs: int = 0    # a SYNC sent before the previous one's four TPDOs were all in
    rejected_frames: int = 0     # a frame of a node's SDO reply / TPDO ids shorter than that object's layout


@dataclass
class Cia402Master:
    node_ids: tuple[int, int]
    phase: str = "boot"          # boot -> setup -> run
    counters: MasterCounters = field(default_factory=MasterCounters)
    statusword: dict[int, int] = field(default_factory=dict)
    emcy_code: dict[int, int] = field(default_factory=dict)     # the newest EMCY error code per node
    drive_states: Cia402DriveStates = field(default_factory=Cia402DriveStates)
    drive_state: Heartbeat | None = None   # the drive state the last frame received reported (its statusword), else None
    _booted: set[int] = field(default_factory=set)
    _queue: dict[int, list[Frame]] = field(default_factory=dict)   # per node: SDO writes still to send, in order
    _parts: dict[int, bytes] = field(default_factory=dict)          # this SYNC's TPDO 2 / 3 data by COB-ID

    def start(self) -> list[Frame]:
        """Reset communication of both nodes (their boot-ups start the set-up)."""
        self.phase, self._booted = "boot", set()
        return [Frame(0x000, bytes([0x82, n])) for n in self.node_ids]

    def receive(self, f: Frame) -> list[Frame]:
        """One frame from the bus; the frames to send in answer (the next SDO write, NMT start)."""
        node = f.can_id & 0x7F
        kind = f.can_id & ~0x7F
        self.drive_state = None
        if node not in self.node_ids:
            return []
        if len(f.data) < MIN_BYTES.get(kind, 0):   # malformed: rejected and counted, never raised out of the node
            self.counters.rejected_frames += 1
            return []
        if kind == 0x700 and f.data == b"\0" and self.phase == "boot":
            self._booted.add(node)
            if self._booted == set(self.node_ids):
                self.phase = "setup"
                self._queue = {n: setup_writes(n) for n in self.node_ids}
                return [q.pop(0) for q in self._queue.values()]
        elif kind == 0x580 and self.phase == "setup":
            if f.data[0] == 0x80:
                self.counters.sdo_aborts += 1
            q = self._queue[node]
            if q:
                return [q.pop(0)]
            if not any(self._queue.values()):
                self.phase = "run"
                return [Frame(0x000, bytes([0x01, 0]))]
        elif kind == 0x080 and f.can_id != 0x080:
            self.counters.emcys += 1
            if len(f.data) >= 2:
                self.emcy_code[node] = struct.unpack_from("<H", f.data)[0]
                self.drive_states.on_emcy(node, self.emcy_code[node])
        elif kind == 0x180:
            self.statusword[node] = struct.unpack_from("<H", f.data)[0]
            self.drive_state = self.drive_states.on_statusword(node, self.statusword[node])
            if self.statusword[node] & 0x4F == 0x08:
                self.counters.faults += 1
        elif kind in (0x280, 0x380):
            self._parts[f.can_id] = f.data
        return []

    @property
    def faulted(self) -> bool:
        """A node's statusword says FAULT (or FAULT REACTION ACTIVE)."""
        return any(self.statusword.get(n, 0) & 0x4F in (0x08, 0x0F) for n in self.node_ids)

    @property
    def enabled(self) -> bool:
        """Both nodes report OPERATION ENABLED."""
        return all(self.statusword.get(n, 0) & 0x6F == 0x27 for n in self.node_ids)

    def sync(self) -> list[Frame]:
        if self._parts:
            self.counters.incomplete_syncs += self.measurement() is None
        self._parts = {}
        self.counters.syncs += 1
        return [Frame(0x080)]

    def measurement(self) -> Measurement | None:
        """The state of this SYNC's sample once both nodes' TPDO 2 and 3 are in (SI units), else None."""
        hip, knee = self.node_ids
        try:
            p1, v1 = struct.unpack("<ii", self._parts[0x280 + hip])
            p2, v2 = struct.unpack("<ii", self._parts[0x280 + knee])
            d1, r1 = struct.unpack("<ii", self._parts[0x380 + hip])
            d2, r2 = struct.unpack("<ii", self._parts[0x380 + knee])
        except KeyError:
            return None
        return (p1 * 1e-6, p2 * 1e-6, v1 * 1e-6, v2 * 1e-6, d1 * 1e-9, d2 * 1e-9, r1 * 1e-9, r2 * 1e-9)

    def command(self, voltage_v: tuple[float, float]) -> list[Frame]:
        """RPDO 3 (target voltage, mV) to each node."""
        out = []
        for node, u in zip(self.node_ids, voltage_v, strict=True):
            mv = max(-32768, min(32767, round(u * 1000.0)))
            out.append(Frame(0x400 + node, struct.pack("<h", mv)))
        return out

    def fault_reset(self) -> list[Frame]:
        """Controlword 0 then 0x80 (bit 7's rising edge), then the walk to OPERATION ENABLED, by SDO."""
        self.phase = "setup"
        self._queue = {n: [_sdo_write(n, 0x6040, 0, "H", cw) for cw in (0x80, *WALK)] for n in self.node_ids}
        return [_sdo_write(n, 0x6040, 0, "H", 0x00) for n in self.node_ids]
