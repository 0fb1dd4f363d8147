"""Checks of SDO writes to the communication objects (0x1000-0x1FFF) of a `CanopenSlave`, as CiA 301 section 7.5.2
specifies them: COB-IDs (11-bit only; a valid PDO's id is not changed in place), transmission types (0-240, 254, 255;
RTR-only 252/253 not offered), inhibit time only while the TPDO is disabled, and the PDO mapping procedure (disable
the PDO, set sub-index 0 to 0, write the entries, set sub-index 0 to their number; each entry an existing mappable
object of its own length, readable for a TPDO and writable for an RPDO, together at most 64 bits). Pure: the abort
code, 0 if the write is allowed."""
from __future__ import annotations

from typing import TYPE_CHECKING

from sea_hil.plant_emulator.canopen_slave import NOT_MAPPABLE, PDO_TOO_LONG, RANGE, UNSUPPORTED
from sea_hil.protocol.cia402_od import PDO_INVALID, Entry

if TYPE_CHECKING:
    from sea_hil.plant_emulator.canopen_slave import CanopenSlave

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
