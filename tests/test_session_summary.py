"""`session_summary` splits a session by the controller's time axis: the measured cycles (t >= 0), the lead-in
(t < 0) and states outside both (before the controller's first, after its last handled state)."""
from __future__ import annotations

from sea_hil.recorder.reader import RecordedMessage, SessionData
from sea_hil.report.session_summary import session_summary

MS = 1_000_000
T0_SAMPLE_NS = 5_000 * MS        # sample time of the controller's t = 0 (the driver booted 5 s earlier)
LEAD_IN_MS = 500


def _msg(payload: dict) -> RecordedMessage:
    return RecordedMessage(0, 0, payload)


def _session(first_handled: int, last_handled: int, published: range, events: set[int]) -> SessionData:
    """States every 10 ms (seq k sampled at T0 - lead-in + (k - first_handled) * 10 ms); the controller handled
    first_handled..last_handled and answered the seqs in `events` with a setpoint."""
    def sample_ns(seq: int) -> int:
        return T0_SAMPLE_NS - LEAD_IN_MS * MS + (seq - first_handled) * 10 * MS

    states = [_msg({"key": "sea/limb1/state", "seq": k, "sample_t_ns": sample_ns(k), "payload_bytes": 88})
              for k in published]
    tracking, setpoints = [], []
    for k in range(first_handled, last_handled + 1):
        t_s = (sample_ns(k) - T0_SAMPLE_NS) * 1e-9
        err = 0.01 if t_s < 0 else 0.001            # the lead-in tracks worse than the cycle
        tracking.append(_msg({"key": "sea/limb1/event", "t_s": t_s, "state_seq": k, "theta1_rad": err,
                              "theta2_rad": 0.0, "theta1_d_rad": 0.0, "theta2_d_rad": 0.0, "event": k in events,
                              "reason": "ERROR_BOUND" if k in events else ""}))
        if k in events:
            setpoints.append(_msg({"key": "sea/limb1/setpoint", "seq": len(setpoints) + 1, "state_seq": k,
                                   "payload_bytes": 53}))
    return SessionData(messages={"/zenoh/state": states, "/tracking": tracking, "/zenoh/setpoint": setpoints})


def test_cycles_lead_in_and_outside_are_counted_apart() -> None:
    first, last = 20, 20 + 50 + 100           # 50 lead-in samples, then t = 0 .. 1.0 s
    events = {20, 30, 60, 69, 70, 100, 170}   # 4 in the lead-in (t < 0), 3 in the cycle
    data = _session(first, last, range(1, last + 6), events)   # 19 states before the controller, 5 after
    s = session_summary(data, "et")
    assert s["transmissions"] == {"downlink_msgs": 3, "downlink_bytes": 159, "uplink_msgs": 101,
                                  "uplink_bytes": 101 * 88, "total_msgs": 104, "total_bytes": 159 + 101 * 88}
    lead = s["lead_in"]
    assert (lead["downlink_msgs"], lead["uplink_msgs"], lead["duration_s"]) == (4, 50, 0.5)
    assert lead["tracking"]["max_abs_error_rad"][0] == 0.01
    assert s["tracking"]["max_abs_error_rad"][0] == 0.001 and s["duration_s"] == 1.0
    assert s["uplink_outside_msgs"] == 19 + 5
    assert s["events_by_reason"] == {"ERROR_BOUND": 3}


def test_without_lead_in_everything_handled_is_the_cycle() -> None:
    data = _session(1, 101, range(1, 102), {1, 50})
    data.messages["/tracking"] = [_msg({**m.payload, "t_s": m.payload["t_s"] + LEAD_IN_MS * 1e-3})
                                  for m in data.messages["/tracking"]]   # t = 0 at the first handled state
    data.messages["/zenoh/state"] = [_msg({**m.payload, "sample_t_ns": m.payload["sample_t_ns"] + LEAD_IN_MS * MS})
                                     for m in data.messages["/zenoh/state"]]
    s = session_summary(data, "et")
    assert s["transmissions"]["uplink_msgs"] == 101 and s["transmissions"]["downlink_msgs"] == 2
    assert s["lead_in"]["duration_s"] == 0.0 and s["lead_in"]["uplink_msgs"] == 0
    assert s["uplink_outside_msgs"] == 0
