"""Bits and time on the wire of classic CAN and CAN FD frames: the one copy of the formulas (bus load in reports,
benchmarks, the session's planned load, the bus-timing model `sea_hil.protocol.bus_timing`, docs/can-protocol.md).

Classic CAN (Davis et al. 2007): every bit at the nominal rate. CAN FD (ISO 11898-1:2015): the arbitration phase
(SOF .. BRS, and CRC delimiter .. interframe space) at the nominal rate, the data phase (ESI, DLC, data, stuff count,
CRC, fixed stuff bits) at the data rate when the bit rate switch (BRS) is set, else at the nominal rate too.
"""
from __future__ import annotations

from typing import NamedTuple

from sea_hil.errors import MalformedFrame

NS_PER_S = 1_000_000_000
FD_LENGTHS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)   # payload bytes of CAN FD DLC codes 0..15


def can_frame_bits(dlc: int, extended: bool = False, *, worst_case: bool = True) -> int:
    """Bits on the wire of one classic CAN data frame including the 3-bit interframe space (Davis et al. 2007):
    standard ``8n + 47 + stuff``, extended ``8n + 67 + stuff`` with ``n = min(dlc, 8)``; worst-case bit stuffing
    ``stuff = floor((34 + 8n - 1)/4)`` (extended: ``54`` instead of ``34``), 0 when not `worst_case`.
    8-byte frames: 135 (std), 160 (ext) bits. The single copy of this formula (bus load, reports, docs)."""
    if not isinstance(dlc, int) or not 0 <= dlc <= 15:
        raise MalformedFrame(f"classic CAN dlc must be 0..15, got {dlc!r}")
    n = min(dlc, 8)
    fixed, stuffed = (67, 54) if extended else (47, 34)
    return 8 * n + fixed + ((stuffed + 8 * n - 1) // 4 if worst_case else 0)


class FdBits(NamedTuple):
    """Bits of one CAN FD frame by phase: `nominal` at the arbitration rate, `data` at the data rate (with BRS)."""
    nominal: int
    data: int


def can_fd_frame_bits(length: int, extended: bool = False, *, worst_case: bool = True) -> FdBits:
    """Bits of one CAN FD data frame of `length` payload bytes (0..8, 12, 16, 20, 24, 32, 48 or 64), interframe
    space included, split by phase.

    Arbitration phase: SOF, 11-bit id, RRS, IDE, FDF, res, BRS = 17 bits (extended: SOF, 11 + 18 id bits, SRR, IDE,
    RRS, FDF, res, BRS = 36), then CRC delimiter, ACK, ACK delimiter, 7-bit EOF and 3-bit IFS = 13 bits. Data phase:
    ESI, 4-bit DLC, 8n data bits, 4-bit stuff count (3-bit gray code + parity), CRC-17 (n <= 16) or CRC-21 (n > 16)
    and its fixed stuff bits (one before the stuff count, then one after every 4 bits: 6 with CRC-17, 7 with
    CRC-21). Dynamic stuff bits (worst case: one per 4 bits after the first, SOF .. end of data) are counted in the
    phase they occur in; 0 when not `worst_case`."""
    if not isinstance(length, int) or length not in FD_LENGTHS:
        raise MalformedFrame(f"CAN FD payload must be one of {FD_LENGTHS} bytes, got {length!r}")
    head = 36 if extended else 17
    body = 1 + 4 + 8 * length                    # ESI, DLC, data: dynamically stuffed with the head
    crc, fixed_stuff = (17, 6) if length <= 16 else (21, 7)
    stuff_all = (head + body - 1) // 4 if worst_case else 0
    stuff_head = (head - 1) // 4 if worst_case else 0
    return FdBits(head + stuff_head + 13, body + (stuff_all - stuff_head) + 4 + crc + fixed_stuff)


def fd_length(dlc_or_len: int) -> int:
    """Payload bytes of a CAN FD frame from python-can's `dlc` (the length in bytes, or a 9..15 DLC code)."""
    if dlc_or_len in FD_LENGTHS:
        return dlc_or_len
    raise MalformedFrame(f"CAN FD frame length must be one of {FD_LENGTHS}, got {dlc_or_len!r}")


def frame_time_ns(dlc: int, *, extended: bool = False, fd: bool = False, bitrate_switch: bool = True,
                  bitrate_bps: int = 1_000_000, data_bitrate_bps: int = 5_000_000, worst_case: bool = True) -> int:
    """Transmission time of one frame in integer nanoseconds (rounded up), interframe space included: classic CAN
    at `bitrate_bps`; CAN FD with its data phase at `data_bitrate_bps` when `bitrate_switch`."""
    if bitrate_bps <= 0 or data_bitrate_bps <= 0:
        raise ValueError("bit rates must be > 0")
    if not fd:
        return -(-can_frame_bits(dlc, extended, worst_case=worst_case) * NS_PER_S // bitrate_bps)
    b = can_fd_frame_bits(fd_length(dlc), extended, worst_case=worst_case)
    data_rate = data_bitrate_bps if bitrate_switch else bitrate_bps
    return -(-(b.nominal * data_rate + b.data * bitrate_bps) * NS_PER_S // (bitrate_bps * data_rate))


def nominal_bits(dlc: int, *, extended: bool = False, fd: bool = False, bitrate_switch: bool = True,
                 bitrate_bps: int = 1_000_000, data_bitrate_bps: int = 5_000_000) -> float:
    """The bus time of one frame (worst-case stuffing) in nominal bit times: the bit count whose sum over frames
    divided by `bitrate_bps` is the bus occupancy (= `can_frame_bits` for classic frames)."""
    if not fd:
        return float(can_frame_bits(dlc, extended))
    b = can_fd_frame_bits(fd_length(dlc), extended)
    return b.nominal + b.data * (bitrate_bps / data_bitrate_bps if bitrate_switch else 1.0)
