"""What a CANopen frame of a cia402 session means, in the object dictionary's own names (`protocol.cia402_od`, the
source of the shipped EDS): "SYNC", "NMT start all nodes", "HEARTBEAT node 2 OPERATIONAL",
"TPDO1 node 2: statusword=0x0027 modes_of_operation_display=-1", "SDO download node 1: 0x1402:01 RPDO
communication parameter 3 / COB-ID used by RPDO = 0x80000401", "EMCY node 1: error_code=0x8612 ...".

Pure and stateful like a bus monitor: it starts from the dictionary's defaults (COB-IDs, PDO mappings, SYNC and EMCY
ids) for the given node ids and follows what the bus changes: an expedited SDO download to a communication object
(0x1005, 0x1014, 0x1400-0x1A03) takes effect when the node confirms it, an NMT reset node / communication restores
the defaults. So a PDO is decoded with the mapping its node had when it was sent. Used by the recorder's CAN tap
(the target voltages of the RPDOs as `/can/command`) and by `sea-hil export` (the decoded frames as CSV).
Malformed frames are named, never raised: a bus monitor sees everything.
"""
from __future__ import annotations

import re
import struct
from dataclasses import dataclass, field

from sea_hil.config.root import SeaHilConfig
from sea_hil.protocol.cia402_od import (
    BOOT,
    FORMATS,
    NMT_ID,
    OPERATIONAL,
    PDO_INVALID,
    PRE_OPERATIONAL,
    STOPPED,
    SYNC_DEFAULT,
    VAR,
    VISIBLE_STRING,
    Entry,
    Obj,
    entries_by_key,
    joint_defaults,
    object_dictionary,
)

NMT_STATES = {BOOT: "BOOT-UP", STOPPED: "STOPPED", OPERATIONAL: "OPERATIONAL", PRE_OPERATIONAL: "PRE-OPERATIONAL"}
NMT_COMMANDS = {0x01: "start", 0x02: "stop", 0x80: "enter pre-operational", 0x81: "reset node",
                0x82: "reset communication"}
SDO_RX, SDO_TX, HEARTBEAT = 0x600, 0x580, 0x700      # client -> server, server -> client, NMT error control
_TRACKED = {0x1005, 0x1014, *range(0x1400, 0x1404), *range(0x1600, 0x1604), *range(0x1800, 0x1804),
            *range(0x1A00, 0x1A04)}
_SIGNED = {"<b", "<h", "<i"}


def field_name(name: str) -> str:
    """An OD name as a field name: "Position actual value" -> "position_actual_value"."""
    return re.sub(r"[^0-9a-z]+", "_", name.lower()).strip("_")


@dataclass(frozen=True)
class Decoded:
    """One frame: its CANopen service (`kind`: NMT, SYNC, EMCY, TPDO1..4, RPDO1..4, SDO_REQUEST, SDO_RESPONSE,
    HEARTBEAT, UNKNOWN), the node it is from or for (0: broadcast), one line of text, and the values it carries by
    field name (a PDO's mapped objects, raw integers in the dictionary's units)."""
    kind: str
    node_id: int
    text: str
    values: dict[str, int] = field(default_factory=dict)


@dataclass
class Cia402Decoder:
    objects: tuple[Obj, ...]
    node_ids: tuple[int, ...]
    _entries: dict[tuple[int, int], Entry] = field(default_factory=dict)
    _names: dict[int, str] = field(default_factory=dict)
    _var: set[int] = field(default_factory=set)
    _values: dict[int, dict[tuple[int, int], int]] = field(default_factory=dict)   # node -> tracked objects
    _pending: dict[int, tuple[int, int, int]] = field(default_factory=dict)       # node -> unconfirmed download
    _ids: dict[int, tuple[str, int]] | None = None                                  # COB-ID -> (kind, node)

    def __post_init__(self) -> None:
        self._entries = entries_by_key(self.objects)
        self._names = {o.index: o.name for o in self.objects}
        self._var = {o.index for o in self.objects if o.object_type == VAR}
        for n in self.node_ids:
            self._reset(n)

    # ---- what the bus changed -------------------------------------------------------------------------------------
    def fresh(self) -> Cia402Decoder:
        """A second monitor of the same bus, at the dictionary's defaults (each reader follows the bus itself)."""
        return Cia402Decoder(self.objects, self.node_ids)

    def _reset(self, node: int) -> None:
        self._values[node] = {k: int(e.default_for(node)) for k, e in self._entries.items() if k[0] in _TRACKED}
        self._pending.pop(node, None)
        self._ids = None

    def _cob_ids(self) -> dict[int, tuple[str, int]]:
        if self._ids is None:
            ids: dict[int, tuple[str, int]] = {}
            for node, v in self._values.items():
                for n in range(4):
                    for kind, base in (("RPDO", 0x1400), ("TPDO", 0x1800)):
                        cob = v.get((base + n, 1), PDO_INVALID)
                        if not cob & PDO_INVALID:
                            ids.setdefault(cob & 0x7FF, (f"{kind}{n + 1}", node))
                emcy = v.get((0x1014, 0), PDO_INVALID)
                if not emcy & PDO_INVALID:
                    ids.setdefault(emcy & 0x7FF, ("EMCY", node))
            sync = {v.get((0x1005, 0), SYNC_DEFAULT) & 0x7FF for v in self._values.values()} or {SYNC_DEFAULT}
            for s in sync:
                ids[s] = ("SYNC", 0)
            self._ids = ids
        return self._ids

    # ---- names and values -----------------------------------------------------------------------------------------
    def object_name(self, index: int, sub: int) -> str:
        """`0x6041:00 Statusword`, `0x1402:01 RPDO communication parameter 3 / COB-ID used by RPDO`."""
        e = self._entries.get((index, sub))
        if e is None:
            return f"0x{index:04X}:{sub:02X} (not in the dictionary)"
        name = e.name if index in self._var else f"{self._names[index]} / {e.name}"
        return f"0x{index:04X}:{sub:02X} {name}"

    def _value(self, index: int, sub: int, data: bytes) -> str:
        e = self._entries.get((index, sub))
        if e is None or e.data_type == VISIBLE_STRING:
            return repr(data.decode("ascii", "replace")) if e is not None else f"0x{data.hex()}"
        fmt = FORMATS[e.data_type]
        size = struct.calcsize(fmt)
        if len(data) < size:
            return f"0x{data.hex()} (short)"
        v = struct.unpack_from(fmt, data)[0]
        return str(v) if fmt in _SIGNED else f"0x{v:0{2 * size}X}"

    # ---- one frame ------------------------------------------------------------------------------------------------
    def decode(self, can_id: int, data: bytes, *, remote: bool = False, extended: bool = False) -> Decoded:
        """The frame's meaning (see the module docstring); a frame that is none of the dictionary's is UNKNOWN."""
        if extended or remote:
            return Decoded("UNKNOWN", 0, f"{'extended' if extended else 'remote'} frame 0x{can_id:X}: not CANopen "
                                         "here")
        if can_id == NMT_ID:
            return self._nmt(data)
        kind, node = self._cob_ids().get(can_id, ("", can_id & 0x7F))
        if kind == "SYNC":
            return Decoded("SYNC", 0, "SYNC" if not data else f"SYNC counter={data[0]}" if len(data) == 1
                           else f"SYNC (malformed: {len(data)} bytes)")
        if kind == "EMCY":
            return self._emcy(node, data)
        if kind:
            return self._pdo(kind, node, data)
        if can_id & ~0x7F in (SDO_RX, SDO_TX) and node:
            return self._sdo(node, data, request=can_id & ~0x7F == SDO_RX)
        if can_id & ~0x7F == HEARTBEAT and node:
            if len(data) != 1:
                return Decoded("HEARTBEAT", node, f"HEARTBEAT node {node} (malformed: {len(data)} bytes)")
            state = data[0] & 0x7F
            text = f"BOOT-UP node {node}" if state == BOOT else \
                f"HEARTBEAT node {node} {NMT_STATES.get(state, f'state 0x{state:02X}')}"
            return Decoded("HEARTBEAT", node, text, {"nmt_state": state})
        return Decoded("UNKNOWN", node, f"frame 0x{can_id:03X}: no service of the dictionary's nodes")

    def _nmt(self, data: bytes) -> Decoded:
        if len(data) != 2:
            return Decoded("NMT", 0, f"NMT (malformed: {len(data)} bytes)")
        cs, target = data
        if cs in (0x81, 0x82):
            for n in list(self._values) if target == 0 else [target] if target in self._values else []:
                self._reset(n)
        who = "all nodes" if target == 0 else f"node {target}"
        return Decoded("NMT", target, f"NMT {NMT_COMMANDS.get(cs, f'command 0x{cs:02X}')} {who}",
                       {"command": cs, "node": target})

    def _emcy(self, node: int, data: bytes) -> Decoded:
        if len(data) < 3:
            return Decoded("EMCY", node, f"EMCY node {node} (malformed: {len(data)} bytes)")
        code, reg = struct.unpack_from("<HB", data)
        extra = f" manufacturer=0x{data[3:].hex().upper()}" if len(data) > 3 else ""
        what = " (error reset)" if code == 0 else ""
        return Decoded("EMCY", node, f"EMCY node {node}: error_code=0x{code:04X}{what} error_register=0x{reg:02X}"
                                     f"{extra}", {"error_code": code, "error_register": reg})

    def _pdo(self, kind: str, node: int, data: bytes) -> Decoded:
        base = 0x1600 if kind.startswith("R") else 0x1A00
        v = self._values[node]
        m = base + int(kind[-1]) - 1
        parts, values, offset = [], {}, 0
        for sub in range(1, v.get((m, 0), 0) + 1):
            entry = v.get((m, sub), 0)
            index, subindex, bits = entry >> 16, entry >> 8 & 0xFF, entry & 0xFF
            e = self._entries.get((index, subindex))
            size = bits // 8
            name = field_name(e.name) if e is not None else f"0x{index:04X}_{subindex:02X}"
            chunk = data[offset:offset + size]
            offset += size
            if len(chunk) < size:
                parts.append(f"{name}=(missing)")
                continue
            parts.append(f"{name}={self._value(index, subindex, chunk)}")
            if e is not None and e.data_type in FORMATS:
                values[name] = int(struct.unpack(FORMATS[e.data_type], chunk)[0])
        short = f" (short: {len(data)} of {offset} bytes)" if len(data) < offset else ""
        return Decoded(kind, node, f"{kind} node {node}: {' '.join(parts) or '(no mapped objects)'}{short}", values)

    def _sdo(self, node: int, data: bytes, *, request: bool) -> Decoded:
        kind = "SDO_REQUEST" if request else "SDO_RESPONSE"
        if len(data) != 8:
            return Decoded(kind, node, f"SDO {'request' if request else 'response'} node {node} (malformed: "
                                       f"{len(data)} bytes)")
        cs = data[0] >> 5
        index, sub = struct.unpack_from("<HB", data, 1)
        obj = self.object_name(index, sub)
        expedited = data[0] & 0x02 and data[0] & 0x01
        payload = data[4:8 - (data[0] >> 2 & 3)] if expedited else data[4:8]
        if cs == 4:                               # abort, either way
            code = struct.unpack_from("<I", data, 4)[0]
            self._pending.pop(node, None)
            return Decoded(kind, node, f"SDO abort node {node}: {obj}: 0x{code:08X}", {"abort_code": code})
        if request:
            if cs == 1:
                if expedited and index in _TRACKED:
                    self._pending[node] = (index, sub, int.from_bytes(payload, "little"))
                value = f" = {self._value(index, sub, payload)}" if expedited else " (segmented)"
                return Decoded(kind, node, f"SDO download node {node}: {obj}{value}")
            if cs == 2:
                return Decoded(kind, node, f"SDO upload node {node}: {obj}")
            names = {0: "download segment", 3: "upload segment", 5: "block upload", 6: "block download"}
            return Decoded(kind, node, f"SDO {names.get(cs, f'command 0x{data[0]:02X}')} node {node}")
        if cs == 3:
            pending = self._pending.pop(node, None)
            if pending is not None and pending[:2] == (index, sub):
                self._values[node][(index, sub)] = pending[2]
                self._ids = None
            return Decoded(kind, node, f"SDO download ok node {node}: {obj}")
        if cs == 2:
            value = f" = {self._value(index, sub, payload)}" if expedited else \
                f" ({struct.unpack_from('<I', data, 4)[0]} bytes, segmented)" if data[0] & 0x01 else " (segmented)"
            return Decoded(kind, node, f"SDO upload node {node}: {obj}{value}")
        names = {0: "upload segment", 1: "download segment ok", 5: "block download", 6: "block upload"}
        return Decoded(kind, node, f"SDO {names.get(cs, f'command 0x{data[0]:02X}')} node {node}")


def decoder_for(cfg: SeaHilConfig) -> Cia402Decoder:
    """The decoder of a cia402 session's bus: the drive's dictionary (names, types, default PDO set) for the
    `[can.cia402] node_ids` of `cfg`."""
    return Cia402Decoder(object_dictionary(joint_defaults(cfg, 0)), cfg.can.cia402.node_ids)
