"""The SDO server transfer protocol (CiA 301 section 7.2.4.3): expedited and segmented upload and download for one
`CanopenSlave`, one transfer at a time. Pure: an 8-byte request in, the response frames out. Block transfer is not
offered (command specifiers 5 and 6 are answered with abort 0x05040001, as for any unknown specifier); a segment
without a transfer in progress, or with the toggle bit not alternated (0x05030000), aborts the transfer."""
from __future__ import annotations

import struct
from typing import TYPE_CHECKING

from sea_hil.plant_emulator.canopen_slave import CS_INVALID, LENGTH, TOGGLE, Frame, _Sdo

if TYPE_CHECKING:
    from sea_hil.plant_emulator.canopen_slave import CanopenSlave


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
