"""A CiA 402 node's drive state in the sea profile's terms (a `Heartbeat`: `DriverState` and `ErrorFlags`), from the
frames a bus monitor decodes (`protocol.cia402_decode`): one rule for the report's latches
(sea_hil/report/drive_faults.py), the edge's own latch count (controller/cia402_master.py: a recording without a CAN
tap), the live view's `/live/driver` (sea_hil/live/view.py) and the ROS 2 export's `/diagnostics`
(sea_hil/ros2/convert.py), so none of them reads a cia402 bus through the DBC (a TPDO of a node whose
COB-ID has the DBC's HEARTBEAT command bits would be misread as a heartbeat).

Each statusword (a TPDO mapping 0x6041) gives one state: FAULT for CiA 402 FAULT or FAULT REACTION ACTIVE, with the
flags of the EMCYs the node sent since its last statusword outside FAULT (`EMCY_CODES` back to the drive's error
flags); RUNNING in OPERATION ENABLED; INIT otherwise (not yet enabled, quick stop). A CANopen heartbeat (NMT state)
or any other frame gives none. A CANopen drive has no rejected-frame, overrun or heartbeat counters in its
statusword: those fields are 0. Pure.
"""
from __future__ import annotations

from sea_hil.protocol.can_frames import DriverState, ErrorFlags, Heartbeat
from sea_hil.protocol.cia402_decode import Decoded
from sea_hil.protocol.cia402_od import EMCY_CODES

FLAG_OF_CODE = {code: flag for flag, code in EMCY_CODES.items()}
FAULT_STATES = (0x08, 0x0F)   # statusword & 0x4F: FAULT, FAULT REACTION ACTIVE (CiA 402)
OPERATION_ENABLED = 0x27      # statusword & 0x6F


class Cia402DriveStates:
    """Per node: the EMCY flags of its current fault; `on_frame` the drive state a decoded frame reports, or None."""

    def __init__(self) -> None:
        self._flags: dict[int, ErrorFlags] = {}

    def on_frame(self, d: Decoded) -> Heartbeat | None:
        if d.kind == "EMCY":
            self.on_emcy(d.node_id, d.values.get("error_code", 0))
            return None
        sw = d.values.get("statusword")
        return None if sw is None else self.on_statusword(d.node_id, sw)

    def on_emcy(self, node_id: int, error_code: int) -> None:
        """An EMCY of the node: its error code's flag joins the current fault's."""
        flag = FLAG_OF_CODE.get(error_code, ErrorFlags(0))
        self._flags[node_id] = self._flags.get(node_id, ErrorFlags(0)) | flag

    def on_statusword(self, node_id: int, sw: int) -> Heartbeat:
        """The state a statusword of the node reports (module docstring)."""
        if sw & 0x4F in FAULT_STATES:
            return Heartbeat(node_id, DriverState.FAULT, self._flags.get(node_id, ErrorFlags(0)), 0, 0, 0)
        self._flags.pop(node_id, None)
        state = DriverState.RUNNING if sw & 0x6F == OPERATION_ENABLED else DriverState.INIT
        return Heartbeat(node_id, state, ErrorFlags(0), 0, 0, 0)
