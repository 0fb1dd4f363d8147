"""The datagram format of the `ipc` CAN bus (`sea_hil.protocol.ipc_bus`): one CAN or CAN FD frame per packet.

Pure: `encode_frame(msg, t_ns) -> bytes` and `decode_frame(packet, channel) -> can.Message`, which raises
`MalformedFrame` for anything that is not a frame python-can itself would accept (`can.Message(check=True)`'s
rules: id range for 11/29-bit ids, DLC <= 8 classic or <= 64 FD equal to the data length, remote frames without
data and not FD, no remote error frame, BRS/ESI only on FD). So a stray or corrupted packet is counted and dropped
by the bus, never handed to a node.

Layout (little endian, 16-byte header then the data bytes):
``magic u8 (0xC1: format 1) | flags u8 | dlc u8 | data length u8 | arbitration id u32 | send time i64 ns``.
flags: bit 0 extended id, 1 remote, 2 error, 3 FD, 4 bitrate switch, 5 error state indicator; other bits 0.
The send time is the sender's wall clock (`time.time_ns()`): the frame's python-can timestamp, the moment it went
on the bus, like the kernel's stamp on SocketCAN (the edge counts queueing from it, `protocol.canbus.rx_monotonic_ns`).
"""
from __future__ import annotations

import struct

import can

from sea_hil.errors import MalformedFrame

MAGIC = 0xC1
HEADER = struct.Struct("<BBBBIq")
HEADER_BYTES = HEADER.size            # 16
MAX_PACKET_BYTES = HEADER_BYTES + 64  # an FD frame's 64 data bytes

EXTENDED, REMOTE, ERROR, FD, BRS, ESI = 1, 2, 4, 8, 16, 32
_KNOWN_FLAGS = EXTENDED | REMOTE | ERROR | FD | BRS | ESI

_new_message = object.__new__


def encode_frame(msg: can.Message, t_ns: int) -> bytes:
    """The packet of `msg` sent at wall time `t_ns`; `MalformedFrame` if `msg` breaks python-can's frame rules."""
    flags = ((EXTENDED if msg.is_extended_id else 0) | (REMOTE if msg.is_remote_frame else 0)
             | (ERROR if msg.is_error_frame else 0) | (FD if msg.is_fd else 0)
             | (BRS if msg.bitrate_switch else 0) | (ESI if msg.error_state_indicator else 0))
    data = b"" if msg.is_remote_frame else bytes(msg.data or b"")
    _check(flags, msg.dlc, len(data), msg.arbitration_id)
    return HEADER.pack(MAGIC, flags, msg.dlc, len(data), msg.arbitration_id, t_ns) + data


def decode_frame(packet: bytes, channel: str) -> can.Message:
    """The received `can.Message` of `packet` (timestamp = its send time, `is_rx`, `channel`); `MalformedFrame`
    for a packet of another format, a truncated or padded one, or a frame python-can would reject."""
    if len(packet) < HEADER_BYTES:
        raise MalformedFrame(f"ipc packet of {len(packet)} bytes is shorter than its {HEADER_BYTES}-byte header")
    magic, flags, dlc, n, arbitration_id, t_ns = HEADER.unpack_from(packet)
    if magic != MAGIC:
        raise MalformedFrame(f"ipc packet has magic 0x{magic:02X}, expected 0x{MAGIC:02X}")
    if len(packet) != HEADER_BYTES + n:
        raise MalformedFrame(f"ipc packet of {len(packet)} bytes, its header says {HEADER_BYTES + n}")
    _check(flags, dlc, n, arbitration_id)
    if t_ns <= 0:
        raise MalformedFrame(f"ipc packet has send time {t_ns} ns")
    m = _new_message(can.Message)    # slot by slot: what can.Message(...) builds, without its keyword handling
    m.timestamp = t_ns / 1e9
    m.arbitration_id = arbitration_id
    m.is_extended_id = bool(flags & EXTENDED)
    m.is_remote_frame = bool(flags & REMOTE)
    m.is_error_frame = bool(flags & ERROR)
    m.is_fd = bool(flags & FD)
    m.bitrate_switch = bool(flags & BRS)
    m.error_state_indicator = bool(flags & ESI)
    m.channel = channel
    m.is_rx = True
    m.dlc = dlc
    m.data = bytearray(packet[HEADER_BYTES:])
    return m


def _check(flags: int, dlc: int, n: int, arbitration_id: int) -> None:
    """python-can's `Message._check` rules on the packed fields (the module docstring)."""
    if flags & ~_KNOWN_FLAGS:
        raise MalformedFrame(f"ipc frame has unknown flag bits 0x{flags & ~_KNOWN_FLAGS:02X}")
    fd, remote = flags & FD, flags & REMOTE
    limit = 0x20000000 if flags & EXTENDED else 0x800
    if not 0 <= arbitration_id < limit:
        raise MalformedFrame(f"ipc frame id 0x{arbitration_id:X} out of range for a "
                             f"{'29' if flags & EXTENDED else '11'}-bit id")
    if remote and (fd or flags & ERROR):
        raise MalformedFrame("ipc frame: a remote frame cannot be FD or an error frame")
    if not 0 <= dlc <= (64 if fd else 8):
        raise MalformedFrame(f"ipc frame DLC {dlc} out of range for {'CAN FD' if fd else 'classic CAN'}")
    if (n != 0) if remote else (n != dlc):
        raise MalformedFrame(f"ipc frame carries {n} data bytes with DLC {dlc}"
                             f"{' (remote frame)' if remote else ''}")
    if not fd and flags & (BRS | ESI):
        raise MalformedFrame("ipc frame: bitrate switch / error state indicator on a classic CAN frame")
