"""CiA 301 communication of one CANopen node, pure (frames and integer-nanosecond time in, frames out): NMT slave
(boot-up, pre-operational / operational / stopped, reset node / communication), heartbeat producer (0x1017), SYNC
consumer (0x1005), EMCY producer (0x1014, 0x1001, 0x1003), SDO server (expedited and segmented upload and download,
CiA 301 abort codes) and four RPDOs / TPDOs configurable over SDO (transmission types 0-240 synchronous, 254/255
event-driven with inhibit time and event timer; mapping changed only while the PDO is disabled and its sub-index 0 is
0, as CiA 301 section 7.5.2.35-36 specifies).

The device application (`SlaveApp`: the CiA 402 axis, `plant_emulator/cia402_axis.py`) owns the meaning of its
objects: it vets and applies writes and keeps the values it produces (actual values, statusword) in `values`.
Frames not meant for any service of this node are the caller's business; frames for it that break the protocol
(wrong length, remote or extended frames on its ids, unknown NMT commands) are counted in `rejected_frames`.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass, field
from typing import NamedTuple, Protocol

from sea_hil.protocol.cia402_od import (
    BOOT,
    FORMATS,
    NMT_ID,
    OPERATIONAL,
    PDO_INVALID,
    PRE_OPERATIONAL,
    STOPPED,
    SYNC_DEFAULT,
    Entry,
    Obj,
    entries_by_key,
)

# SDO abort codes (CiA 301 table 22)
TOGGLE, CS_INVALID, UNSUPPORTED, WRITE_ONLY, READ_ONLY = 0x05030000, 0x05040001, 0x06010000, 0x06010001, 0x06010002
NO_OBJECT, NOT_MAPPABLE, PDO_TOO_LONG, LENGTH = 0x06020000, 0x06040041, 0x06040042, 0x06070010
NO_SUBINDEX, RANGE, STATE = 0x06090011, 0x06090030, 0x08000022
EMCY_PDO_LENGTH, EMCY_SYNC_LENGTH = 0x8210, 0x8240


class Frame(NamedTuple):
    """One classic CAN frame (11-bit id unless `extended`)."""
    can_id: int
    data: bytes = b""
    remote: bool = False
    extended: bool = False


class SlaveApp(Protocol):
    """The device application behind the dictionary (CiA 402: `Cia402Axis`)."""

    def check_write(self, index: int, subindex: int, value: int) -> int:
        """0 if `value` may be written to the object, else the SDO abort code."""

    def on_write(self, index: int, subindex: int, value: int, t_ns: int) -> None:
        """A value was written (by SDO, or by an RPDO at the time it takes effect)."""

    def on_nmt(self, old: int, new: int, t_ns: int) -> None:
        """The NMT state changed (`BOOT` .. `PRE_OPERATIONAL`)."""

    def on_reset(self) -> None:
        """Power-on or reset node: every object is back at its default; the application restarts."""


@dataclass
class _Sdo:
    index: int = 0
    subindex: int = 0
    upload: bytes | None = None        # segmented upload: data left to send
    download: bytearray | None = None  # segmented download: data so far
    size: int | None = None
    toggle: int = 0


@dataclass
class _Tpdo:
    syncs: int = 0
    last_data: bytes | None = None
    last_sent_ns: int | None = None
    timer_due_ns: int | None = None


class _TpdoComm(NamedTuple):
    """TPDO n's communication parameters (0x1800 + n), cached between writes to the communication objects."""
    valid: bool
    ttype: int
    cob_id: int
    inhibit_ns: int
    timer_ms: int


@dataclass
class SlaveCounters:
    rejected_frames: int = 0
    sdo_aborts: int = 0
    emcy_sent: int = 0
    pdo_received: int = 0
    pdo_sent: int = 0
    syncs: int = 0
    tpdo_sent: list[int] = field(default_factory=lambda: [0, 0, 0, 0])


@dataclass
class CanopenSlave:
    node_id: int
    objects: tuple[Obj, ...]
    app: SlaveApp
    nmt: int = BOOT
    values: dict[tuple[int, int], int | str] = field(default_factory=dict)
    counters: SlaveCounters = field(default_factory=SlaveCounters)
    _entries: dict[tuple[int, int], Entry] = field(default_factory=dict)
    _indices: frozenset[int] = frozenset()
    _sdo: _Sdo = field(default_factory=_Sdo)
    _rpdo_pending: dict[int, bytes] = field(default_factory=dict)   # synchronous RPDO n -> data for the next SYNC
    _tpdo: list[_Tpdo] = field(default_factory=lambda: [_Tpdo() for _ in range(4)])
    _heartbeat_due_ns: int | None = None
    _pdo_length_error: bool = False
    # caches of the communication objects, dropped on every write to 0x1000-0x1FFF and at boot (1 kHz paths)
    _maps: dict[tuple[int, int], tuple[list[Entry], struct.Struct]] = field(default_factory=dict)
    _tpdo_keys: dict[int, tuple[tuple[int, int], ...]] = field(default_factory=dict)
    _rpdo_ids: dict[int, int] | None = None
    _sync_id: int | None = None
    _tpdo_comm: list[_TpdoComm] | None = None

    def __post_init__(self) -> None:
        self._entries = entries_by_key(self.objects)
        self._indices = frozenset(o.index for o in self.objects)

    # ---- NMT ------------------------------------------------------------------------------------------------------
    def boot(self, t_ns: int, communication_only: bool = False) -> list[Frame]:
        """Power-on / reset node (all objects to default) or reset communication (0x1000-0x1FFF): boot-up message,
        then PRE-OPERATIONAL."""
        self._set_nmt(BOOT, t_ns)    # the application sees OPERATIONAL left first (CiA 402 0x6007 reaction)
        for key, e in self._entries.items():
            if not communication_only or key[0] < 0x2000:
                self.values[key] = e.default_for(self.node_id)
        self._sdo, self._rpdo_pending = _Sdo(), {}
        self._tpdo = [_Tpdo() for _ in range(4)]
        self._drop_caches()
        if not communication_only:
            self.app.on_reset()
        self._set_nmt(PRE_OPERATIONAL, t_ns)
        self._restart_heartbeat(t_ns)
        return [Frame(0x700 + self.node_id, bytes([BOOT]))]

    def _set_nmt(self, new: int, t_ns: int) -> None:
        old, self.nmt = self.nmt, new
        if old != new:
            self.app.on_nmt(old, new, t_ns)
            if new == OPERATIONAL:
                for n, tp in enumerate(self._tpdo):
                    tp.last_data, tp.syncs = None, 0
                    timer = int(self.values[(0x1800 + n, 5)])
                    tp.timer_due_ns = t_ns + timer * 1_000_000 if timer else None

    def _restart_heartbeat(self, t_ns: int) -> None:
        period = int(self.values[(0x1017, 0)])
        self._heartbeat_due_ns = t_ns + period * 1_000_000 if period else None

    def _on_nmt(self, f: Frame, t_ns: int) -> list[Frame]:
        if len(f.data) != 2:
            return self._reject()
        cs, target = f.data
        if target not in (0, self.node_id):
            return []
        if cs == 0x01:
            self._set_nmt(OPERATIONAL, t_ns)
        elif cs == 0x02:
            self._set_nmt(STOPPED, t_ns)
        elif cs == 0x80:
            self._set_nmt(PRE_OPERATIONAL, t_ns)
        elif cs in (0x81, 0x82):
            return self.boot(t_ns, communication_only=cs == 0x82)
        else:
            return self._reject()
        return []

    # ---- dispatch -------------------------------------------------------------------------------------------------
    def owns(self, can_id: int) -> bool:
        """True if a frame with this 11-bit id is for a service of this node (NMT, SYNC, its SDO, its RPDOs)."""
        return can_id in (NMT_ID, self.sync_id, 0x600 + self.node_id) or self._rpdo_number(can_id) is not None

    def _drop_caches(self) -> None:
        self._maps, self._rpdo_ids, self._sync_id, self._tpdo_comm, self._tpdo_keys = {}, None, None, None, {}

    @property
    def sync_id(self) -> int:
        if self._sync_id is None:
            self._sync_id = int(self.values.get((0x1005, 0), SYNC_DEFAULT)) & 0x7FF
        return self._sync_id

    def _rpdo_number(self, can_id: int) -> int | None:
        if self._rpdo_ids is None:
            self._rpdo_ids = {}
            for n in range(4):
                cob = int(self.values.get((0x1400 + n, 1), PDO_INVALID))
                if not cob & PDO_INVALID:
                    self._rpdo_ids.setdefault(cob & 0x7FF, n)
        return self._rpdo_ids.get(can_id)

    def receive(self, f: Frame, t_ns: int) -> list[Frame]:
        """Handle one frame addressed to this node (`owns`)."""
        if f.remote or f.extended:
            return self._reject()
        if f.can_id == NMT_ID:
            return self._on_nmt(f, t_ns)
        if self.nmt == STOPPED:
            return []
        if f.can_id == self.sync_id:
            return self._on_sync(f, t_ns)
        if f.can_id == 0x600 + self.node_id:
            if len(f.data) != 8:
                return self._reject()
            return self._on_sdo(f.data, t_ns)
        n = self._rpdo_number(f.can_id)
        if n is not None and self.nmt == OPERATIONAL:
            return self._on_rpdo(n, f.data, t_ns)
        return []

    def _reject(self) -> list[Frame]:
        self.counters.rejected_frames += 1
        return []

    # ---- EMCY and heartbeat ---------------------------------------------------------------------------------------
    def emcy(self, code: int, register: int, extra: bytes = b"\0" * 5) -> list[Frame]:
        """Record an error (0x1001, 0x1003 newest first) and send its EMCY (code 0 = error reset: not recorded)."""
        self.values[(0x1001, 0)] = register
        if code:
            history = [int(self.values[(0x1003, i)]) for i in range(1, 9)]
            history = [code, *history[:7]]
            for i, v in enumerate(history, start=1):
                self.values[(0x1003, i)] = v
            self.values[(0x1003, 0)] = min(8, int(self.values[(0x1003, 0)]) + 1)
        cob = int(self.values[(0x1014, 0)])
        if self.nmt not in (PRE_OPERATIONAL, OPERATIONAL) or cob & PDO_INVALID:
            return []
        self.counters.emcy_sent += 1
        return [Frame(cob & 0x7FF, code.to_bytes(2, "little") + bytes([register]) + extra[:5].ljust(5, b"\0"))]

    def poll(self, t_ns: int) -> list[Frame]:
        """Time-driven output due at `t_ns`: heartbeat, event-driven and event-timer TPDOs."""
        out: list[Frame] = []
        if self._heartbeat_due_ns is not None and t_ns >= self._heartbeat_due_ns:
            out.append(Frame(0x700 + self.node_id, bytes([self.nmt])))
            period = int(self.values[(0x1017, 0)]) * 1_000_000
            self._heartbeat_due_ns += period * max(1, (t_ns - self._heartbeat_due_ns) // period + 1)
        if self.nmt == OPERATIONAL:
            for n, comm in enumerate(self._tpdos()):
                if comm.valid and comm.ttype >= 254:
                    out += self._tpdo_event(n, comm, t_ns)
        return out

    def next_deadline_ns(self) -> int | None:
        due = [d for d in (self._heartbeat_due_ns, *(tp.timer_due_ns for tp in self._tpdo)) if d is not None]
        return min(due) if due else None

    # ---- PDO ------------------------------------------------------------------------------------------------------
    def _packed(self, base: int, n: int) -> tuple[list[Entry], struct.Struct]:
        """The mapped entries of PDO n and one struct packing them all (cached)."""
        hit = self._maps.get((base, n))
        if hit is None:
            count = int(self.values[(base + n, 0)])
            out = []
            for i in range(1, count + 1):
                m = int(self.values[(base + n, i)])
                out.append(self._entries[(m >> 16, m >> 8 & 0xFF)])
            hit = self._maps[(base, n)] = (out, struct.Struct("<" + "".join(FORMATS[e.data_type][1] for e in out)))
        return hit

    def _tpdos(self) -> list[_TpdoComm]:
        if self._tpdo_comm is None:
            v = self.values
            self._tpdo_comm = [_TpdoComm(not int(v[(0x1800 + n, 1)]) & PDO_INVALID, int(v[(0x1800 + n, 2)]),
                                         int(v[(0x1800 + n, 1)]) & 0x7FF, int(v[(0x1800 + n, 3)]) * 100_000,
                                         int(v[(0x1800 + n, 5)])) for n in range(4)]
        return self._tpdo_comm

    def _on_rpdo(self, n: int, data: bytes, t_ns: int) -> list[Frame]:
        size = self._packed(0x1600, n)[1].size
        if len(data) < size:   # CiA 301: not processed; one EMCY per episode, every frame counted
            self.counters.rejected_frames += 1
            if not self._pdo_length_error:
                self._pdo_length_error = True
                return self.emcy(EMCY_PDO_LENGTH, int(self.values[(0x1001, 0)]) | 0x11)
            return []
        self._pdo_length_error = False
        self.counters.pdo_received += 1
        if int(self.values[(0x1400 + n, 2)]) <= 240:
            self._rpdo_pending[n] = bytes(data[:size])
        else:
            self._apply_rpdo(n, bytes(data[:size]), t_ns)
        return []

    def _apply_rpdo(self, n: int, data: bytes, t_ns: int) -> None:
        entries, packer = self._packed(0x1600, n)
        for e, value in zip(entries, packer.unpack(data), strict=True):
            if self.app.check_write(e.index, e.subindex, value) == 0:   # out of range in a PDO: the app saturates
                self.values[(e.index, e.subindex)] = value
                self.app.on_write(e.index, e.subindex, value, t_ns)

    def tpdo_data(self, n: int) -> bytes:
        """TPDO n's data now: its mapped values packed (the getter of the mapped keys cached with the mapping)."""
        entries, packer = self._packed(0x1A00, n)
        keys = self._tpdo_keys.get(n)
        if keys is None:
            keys = self._tpdo_keys[n] = tuple((e.index, e.subindex) for e in entries)
        return packer.pack(*map(self.values.__getitem__, keys))

    def _tpdo_frame(self, n: int, comm: _TpdoComm, data: bytes, t_ns: int) -> Frame:
        tp = self._tpdo[n]
        tp.last_data, tp.last_sent_ns = data, t_ns
        self.counters.pdo_sent += 1
        self.counters.tpdo_sent[n] += 1
        return Frame(comm.cob_id, data)

    def _tpdo_event(self, n: int, comm: _TpdoComm, t_ns: int) -> list[Frame]:
        """Event-driven TPDO n (valid, type 254/255): sent on a change outside its inhibit time, or at its timer."""
        tp, data = self._tpdo[n], self.tpdo_data(n)
        timer_due = tp.timer_due_ns is not None and t_ns >= tp.timer_due_ns
        inhibited = tp.last_sent_ns is not None and t_ns - tp.last_sent_ns < comm.inhibit_ns
        if (data != tp.last_data and not inhibited) or timer_due:
            tp.timer_due_ns = t_ns + comm.timer_ms * 1_000_000 if comm.timer_ms else None
            return [self._tpdo_frame(n, comm, data, t_ns)]
        return []

    def _on_sync(self, f: Frame, t_ns: int) -> list[Frame]:
        if len(f.data) not in (0, 1):
            self.counters.rejected_frames += 1
            return self.emcy(EMCY_SYNC_LENGTH, int(self.values[(0x1001, 0)]) | 0x11)
        self.counters.syncs += 1
        if self.nmt != OPERATIONAL:
            return []
        for n, data in sorted(self._rpdo_pending.items()):   # synchronous RPDOs act at the SYNC after reception
            self._apply_rpdo(n, data, t_ns)
        self._rpdo_pending = {}
        out = []
        for n, comm in enumerate(self._tpdos()):
            ttype = comm.ttype
            if not comm.valid or ttype > 240:
                continue
            tp = self._tpdo[n]
            tp.syncs += 1
            data = self.tpdo_data(n)
            if (ttype == 0 and data != tp.last_data) or (ttype > 0 and tp.syncs % ttype == 0):
                out.append(self._tpdo_frame(n, comm, data, t_ns))
        return out

    # ---- SDO (the transfer protocol `handle_request` below, object access here) --------------------------------------
    def _on_sdo(self, data: bytes, t_ns: int) -> list[Frame]:
        return handle_request(self, data, t_ns)

    def sdo_response(self, data: bytes) -> Frame:
        return Frame(0x580 + self.node_id, data)

    def entry(self, index: int, subindex: int) -> Entry | int:
        """The entry, or the abort code of a missing object / sub-index."""
        if index not in self._indices:
            return NO_OBJECT
        e = self._entries.get((index, subindex))
        return NO_SUBINDEX if e is None else e

    def read(self, index: int, subindex: int) -> bytes | int:
        """The encoded value, or an abort code."""
        e = self.entry(index, subindex)
        if isinstance(e, int):
            return e
        if not e.readable:
            return WRITE_ONLY
        return e.encode(self.values[(index, subindex)])

    def write(self, index: int, subindex: int, data: bytes, t_ns: int) -> int:
        """Write encoded `data` (0 = done, else the abort code)."""
        e = self.entry(index, subindex)
        if isinstance(e, int):
            return e
        if not e.writable:
            return READ_ONLY
        if e.data_type == 9 or len(data) != e.size:
            return LENGTH
        value = e.decode(data)
        if (e.low is not None and value < e.low) or (e.high is not None and value > e.high):
            return RANGE
        code = check_comm_write(self, e, value) if 0x1000 <= index < 0x2000 else 0
        code = code or self.app.check_write(index, subindex, value)
        if code:
            return code
        self.values[(index, subindex)] = value
        if index < 0x2000:
            self._drop_caches()
        if index == 0x1017:
            self._restart_heartbeat(t_ns)
        if index == 0x1003:
            for i in range(1, 9):
                self.values[(0x1003, i)] = 0
        self.app.on_write(index, subindex, value, t_ns)
        return 0

    def mapping_entry(self, index: int, subindex: int) -> Entry | None:
        return self._entries.get((index, subindex))


# The SDO server transfer protocol (CiA 301 section 7.2.4.3): expedited and segmented upload and download for one
# `CanopenSlave`, one transfer at a time. Pure: an 8-byte request in, the response frames out. Block transfer is not
# offered (command specifiers 5 and 6 are answered with abort 0x05040001, as for any unknown specifier); a segment
# without a transfer in progress, or with the toggle bit not alternated (0x05030000), aborts the transfer.

def abort(slave: CanopenSlave, index: int, subindex: int, code: int) -> list[Frame]:
    slave._sdo = _Sdo()
    slave.counters.sdo_aborts += 1
    return [slave.sdo_response(struct.pack("<BHBI", 0x80, index, subindex, code))]


def handle_request(slave: CanopenSlave, data: bytes, t_ns: int) -> list[Frame]:
    ccs = data[0] >> 5
    index, subindex = struct.unpack_from("<HB", data, 1)
    if ccs == 4:                                  # abort from the client: the transfer ends, no answer
        slave._sdo = _Sdo()
        return []
    if ccs == 1:
        return _initiate_download(slave, data, index, subindex, t_ns)
    if ccs == 2:
        return _initiate_upload(slave, index, subindex)
    s = slave._sdo
    if ccs == 0 and s.download is not None:
        return _download_segment(slave, data, t_ns)
    if ccs == 3 and s.upload is not None:
        return _upload_segment(slave, data)
    return abort(slave, s.index if ccs in (0, 3) else index, s.subindex if ccs in (0, 3) else subindex, CS_INVALID)


def _initiate_upload(slave: CanopenSlave, index: int, subindex: int) -> list[Frame]:
    value = slave.read(index, subindex)
    if isinstance(value, int):
        return abort(slave, index, subindex, value)
    if len(value) <= 4:
        slave._sdo = _Sdo()
        cmd = 0x43 | (4 - len(value)) << 2
        return [slave.sdo_response(struct.pack("<BHB", cmd, index, subindex) + value.ljust(4, b"\0"))]
    slave._sdo = _Sdo(index, subindex, upload=value)
    return [slave.sdo_response(struct.pack("<BHBI", 0x41, index, subindex, len(value)))]


def _upload_segment(slave: CanopenSlave, data: bytes) -> list[Frame]:
    s = slave._sdo
    toggle = data[0] >> 4 & 1
    if toggle != s.toggle:
        return abort(slave, s.index, s.subindex, TOGGLE)
    assert s.upload is not None
    chunk, rest = s.upload[:7], s.upload[7:]
    last = not rest
    cmd = toggle << 4 | (7 - len(chunk)) << 1 | int(last)
    s.upload, s.toggle = rest, toggle ^ 1
    if last:
        slave._sdo = _Sdo()
    return [slave.sdo_response(bytes([cmd]) + chunk.ljust(7, b"\0"))]


def _initiate_download(slave: CanopenSlave, data: bytes, index: int, subindex: int, t_ns: int) -> list[Frame]:
    expedited, sized = data[0] >> 1 & 1, data[0] & 1
    e = slave.entry(index, subindex)
    if isinstance(e, int):
        return abort(slave, index, subindex, e)
    ok = [slave.sdo_response(struct.pack("<BHBI", 0x60, index, subindex, 0))]
    if expedited:
        n = 4 - (data[0] >> 2 & 3) if sized else e.size if e.size <= 4 else 4
        code = slave.write(index, subindex, bytes(data[4:4 + n]), t_ns)
        return abort(slave, index, subindex, code) if code else _done(slave, ok)
    size = struct.unpack_from("<I", data, 4)[0] if sized else None
    if size is not None and size != e.size:
        return abort(slave, index, subindex, LENGTH)
    slave._sdo = _Sdo(index, subindex, download=bytearray(), size=size)
    return ok


def _done(slave: CanopenSlave, frames: list[Frame]) -> list[Frame]:
    slave._sdo = _Sdo()
    return frames


def _download_segment(slave: CanopenSlave, data: bytes, t_ns: int) -> list[Frame]:
    s = slave._sdo
    toggle = data[0] >> 4 & 1
    if toggle != s.toggle:
        return abort(slave, s.index, s.subindex, TOGGLE)
    assert s.download is not None
    n = 7 - (data[0] >> 1 & 7)
    s.download += data[1:1 + n]
    s.toggle ^= 1
    if s.size is not None and len(s.download) > s.size:
        return abort(slave, s.index, s.subindex, LENGTH)
    ack = [slave.sdo_response(bytes([0x20 | toggle << 4]) + b"\0" * 7)]
    if not data[0] & 1:
        return ack
    if s.size is not None and len(s.download) != s.size:
        return abort(slave, s.index, s.subindex, LENGTH)
    code = slave.write(s.index, s.subindex, bytes(s.download), t_ns)
    return abort(slave, s.index, s.subindex, code) if code else _done(slave, ack)


# Checks of SDO writes to the communication objects (0x1000-0x1FFF) of a `CanopenSlave`, as CiA 301 section 7.5.2
# specifies them: COB-IDs (11-bit only; a valid PDO's id is not changed in place), transmission types (0-240, 254, 255;
# RTR-only 252/253 not offered), inhibit time only while the TPDO is disabled, and the PDO mapping procedure (disable
# the PDO, set sub-index 0 to 0, write the entries, set sub-index 0 to their number; each entry an existing mappable
# object of its own length, readable for a TPDO and writable for an RPDO, together at most 64 bits). Pure: the abort
# code, 0 if the write is allowed.



EXTENDED = 0x2000_0000
RESTRICTED = (range(0x000, 0x001), range(0x001, 0x080), range(0x101, 0x181), range(0x581, 0x600),
              range(0x601, 0x680), range(0x6E0, 0x700), range(0x701, 0x780), range(0x780, 0x800))


def _restricted(can_id: int) -> bool:
    """CiA 301 table 73: ids no PDO may use (NMT, SYNC/EMCY region below 0x80 etc., SDO, NMT error control)."""
    return can_id == 0 or can_id > 0x7FF or any(can_id in r for r in RESTRICTED)


def check_mapped(slave: CanopenSlave, value: int, receive: bool) -> int:
    if value == 0:
        return 0
    e = slave.mapping_entry(value >> 16, value >> 8 & 0xFF)
    if e is None or not e.pdo_mappable or e.size * 8 != value & 0xFF:
        return NOT_MAPPABLE
    if (receive and not e.writable) or (not receive and not e.readable):
        return NOT_MAPPABLE
    return 0


def check_comm_write(slave: CanopenSlave, e: Entry, value: int) -> int:
    index, sub = e.index, e.subindex
    if index in (0x1005, 0x1014):
        return RANGE if value & (EXTENDED | 0x4000_0000) else 0
    group = index & 0xFE00
    if group in (0x1400, 0x1800) and index & 0x1FF < 4:
        valid = not int(slave.values[(index, 1)]) & PDO_INVALID
        if sub == 1:
            if value & EXTENDED:
                return RANGE
            if not value & PDO_INVALID:
                if valid and value & 0x7FF != int(slave.values[(index, 1)]) & 0x7FF:
                    return RANGE
                if _restricted(value & 0x7FF):
                    return RANGE
            return 0
        if sub == 2:
            return RANGE if 241 <= value <= 253 else 0
        if sub == 3 and valid:
            return UNSUPPORTED
        return 0
    if group in (0x1600, 0x1A00) and index & 0x1FF < 4:
        receive = group == 0x1600
        comm = index - 0x200
        if not int(slave.values[(comm, 1)]) & PDO_INVALID:
            return UNSUPPORTED
        if sub == 0:
            bits = 0
            for i in range(1, value + 1):
                m = int(slave.values[(index, i)])
                code = check_mapped(slave, m, receive)
                if code or m == 0:
                    return code or NOT_MAPPABLE
                bits += m & 0xFF
            return PDO_TOO_LONG if bits > 64 else 0
        if int(slave.values[(index, 0)]) != 0:
            return UNSUPPORTED
        return check_mapped(slave, value, receive)
    return 0
