"""The one drive-state reader of the report, the live view and the ROS 2 export (protocol/drive_state.py)."""
from __future__ import annotations

import struct

import pytest

from sea_hil.config.loader import load_config
from sea_hil.errors import MalformedFrame
from sea_hil.protocol.can_codec import SeaCodec
from sea_hil.protocol.can_frames import DriverState, ErrorFlags, Heartbeat, VoltageCmd
from sea_hil.protocol.cia402_decode import decoder_for
from sea_hil.protocol.drive_state import drive_state_reader


def test_the_sea_reader_reads_heartbeats_only_and_raises_on_a_malformed_one():
    """A heartbeat is its state; another frame is None; a malformed heartbeat raises and does not stop the next one
    of the same drive from being read."""
    reader = drive_state_reader(None)
    hb = Heartbeat(3, DriverState.FAULT, ErrorFlags.POSITION_LIMIT, 1, 2, 9)
    msg = SeaCodec().encode(hb)
    cmd = SeaCodec().encode(VoltageCmd(3, (1.0, -1.0), 0))
    assert reader.on_frame(cmd.arbitration_id, bytes(cmd.data), cmd.dlc) is None
    with pytest.raises(MalformedFrame):
        reader.on_frame(msg.arbitration_id, bytes(msg.data)[:-1], msg.dlc - 1)
    assert reader.on_frame(msg.arbitration_id, bytes(msg.data), msg.dlc) == hb
    assert reader.on_frame(msg.arbitration_id, bytes(msg.data), msg.dlc, extended=True) is None


def test_the_cia402_reader_never_reads_a_tpdo_as_a_dbc_heartbeat():
    """Node 7's TPDO 2 (id 0x287, the DBC's HEARTBEAT command bits) is no state; its statusword TPDO 1 is."""
    reader = drive_state_reader(decoder_for(load_config(overrides={"can": {"profile": "cia402",
                                                                           "cia402": {"node_ids": [7, 8]}}})))
    assert reader.on_frame(0x287, struct.pack("<ii", 2, 0), 8) is None
    hb = reader.on_frame(0x187, bytes([0x08, 0x00, 0xFF]), 3)
    assert hb is not None and (hb.node_id, hb.state) == (7, DriverState.FAULT)
