"""What the offline session engine hands back: the messages a session's recorder would hold (`SessionRecords`), built
as the recorder builds them, and the run's counters (`EngineResult`)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from sea_hil.protocol.keys import Keys
from sea_hil.protocol.payloads import PAYLOAD_SIZE, MsgType, SetpointPayload
from sea_hil.recorder.reader import RecordedMessage, SessionData

STATE_BYTES, SETPOINT_BYTES = PAYLOAD_SIZE[MsgType.STATE], PAYLOAD_SIZE[MsgType.SETPOINT]
__all__ = ["SETPOINT_BYTES", "STATE_BYTES", "EngineResult", "SessionRecords"]


@dataclass
class EngineResult:
    data: SessionData            # the messages a session's recorder would hold (see module docstring)
    samples: int                 # driver periods simulated
    saturated_steps: int
    drive_faulted: bool = False          # a drive soft limit faulted the drive (0 V from then on)
    setpoints_out_of_envelope: int = 0   # setpoints the edge's envelope rejected
    edge: Any = None                     # trigger at the edge: its core (`EdgeEvents`: stats, stale holds)


class SessionRecords:
    """What a session's recorder would record of the Zenoh traffic: the dicts `sea_hil.recorder.node.zenoh_record`
    makes of the encoded payloads, built directly (no encode / decode / JSON round trip: float64 fields and JSON
    floats pass unchanged; `tests/test_session_engine.py` checks these dicts equal the recorder's own)."""

    def __init__(self, keys: Keys) -> None:
        self.keys = keys
        self.state_bytes = STATE_BYTES      # EVENT_STATE's size with the trigger at the edge
        self.messages: dict[str, list[RecordedMessage]] = {"/zenoh/state": [], "/zenoh/setpoint": [], "/tracking": []}

    def state(self, seq: int, sample_ns: int, fb: tuple, t_ns: int) -> None:
        (th, om, de, nut) = fb
        self.messages["/zenoh/state"].append(RecordedMessage(t_ns, t_ns, {
            "key": self.keys.state, "seq": seq, "sent_t_ns": sample_ns, "payload_bytes": self.state_bytes,
            "sample_t_ns": sample_ns, "theta1_rad": th[0], "theta2_rad": th[1], "omega1_rad_s": om[0],
            "omega2_rad_s": om[1], "delta1_m": de[0], "delta2_m": de[1], "nut_vel1_m_s": nut[0],
            "nut_vel2_m_s": nut[1]}, seq))

    def setpoint(self, sp: SetpointPayload, t_ns: int) -> None:
        self.setpoint_fields(sp.seq, sp.t_ns, sp.state_seq, sp.deflection_m, sp.sliding, sp.reason.name, t_ns)

    def setpoint_fields(self, seq: int, sent_ns: int, state_seq: int, deflection_m: tuple[float, float],
                        sliding: tuple[float, float], reason_name: str, t_ns: int) -> None:
        """`setpoint` of a payload with these fields (valid ones: see `SetpointPayload`)."""
        self.messages["/zenoh/setpoint"].append(RecordedMessage(t_ns, t_ns, {
            "key": self.keys.setpoint, "seq": seq, "sent_t_ns": sent_ns, "payload_bytes": SETPOINT_BYTES,
            "state_seq": state_seq, "delta1_ref_m": deflection_m[0], "delta2_ref_m": deflection_m[1],
            "s1": sliding[0], "s2": sliding[1], "reason": reason_name}, seq))

    def tracking(self, record: dict[str, Any], t_ns: int) -> None:
        self.messages["/tracking"].append(RecordedMessage(t_ns, t_ns, {**record, "key": self.keys.event},
                                                          record["state_seq"]))
