"""A drive's state (a `Heartbeat`) from the raw frames of its bus, one shape for both profiles: the one reader of the
report's latches (sea_hil/report/drive_faults.py), the live view's `/live/driver` (sea_hil/live/view.py) and the ROS 2
export's `/diagnostics` (sea_hil/ros2/convert.py).

`drive_state_reader(decoder)` gives the bus's reader: without a CANopen decoder the sea profile's (`SeaHeartbeats`:
a frame with the DBC's HEARTBEAT command bits, decoded through the DBC), with one a cia402 bus's (`Cia402States`: the
CANopen bus monitor's frame, then `protocol.cia402_drive_state`'s statusword and EMCY rule), so no TPDO of a cia402
node is read through the DBC. `on_frame` returns the state a frame reports, None for a frame that reports none, and
raises `MalformedFrame` for a malformed heartbeat (the caller counts it). Pure (the cia402 reader follows the bus's
remaps and EMCYs as it sees them).
"""
from __future__ import annotations

from typing import Protocol

from sea_hil.protocol.can_codec import SeaCodec, load_database
from sea_hil.protocol.can_frames import CMD_MASK, Heartbeat
from sea_hil.protocol.cia402_decode import Cia402Decoder
from sea_hil.protocol.cia402_drive_state import Cia402DriveStates


class DriveStateReader(Protocol):
    """Raw frames of one bus in, the drive state each reports out (module docstring)."""

    def on_frame(self, can_id: int, data: bytes, dlc: int, *, extended: bool = False,
                 fd: bool = False) -> Heartbeat | None: ...


class SeaHeartbeats:
    """The sea profile: a DBC HEARTBEAT frame's content; any other frame None (not decoded)."""

    def __init__(self) -> None:
        self._codec = SeaCodec(fd=None)
        self._cmd = load_database().get_message_by_name(Heartbeat.DBC).frame_id & CMD_MASK

    def on_frame(self, can_id: int, data: bytes, dlc: int, *, extended: bool = False,
                 fd: bool = False) -> Heartbeat | None:
        if extended or can_id & CMD_MASK != self._cmd:
            return None
        frame = self._codec.decode_raw(can_id, data, dlc, is_fd=fd)
        return frame if isinstance(frame, Heartbeat) else None


class Cia402States:
    """A cia402 bus: the state a statusword TPDO reports (EMCYs set its flags); any other frame None."""

    def __init__(self, decoder: Cia402Decoder) -> None:
        self._decoder = decoder
        self._states = Cia402DriveStates()

    def on_frame(self, can_id: int, data: bytes, dlc: int, *, extended: bool = False,
                 fd: bool = False) -> Heartbeat | None:
        return self._states.on_frame(self._decoder.decode(can_id, data, extended=extended))


def drive_state_reader(decoder: Cia402Decoder | None) -> DriveStateReader:
    """The reader of a bus: a cia402 session's with its CANopen decoder, else the sea profile's."""
    return SeaHeartbeats() if decoder is None else Cia402States(decoder)
