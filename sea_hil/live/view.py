"""The live view's pure core: recorded messages in, live messages out (no clock, no I/O, no SDK).

`LiveView.feed(topic, log_time_ns, payload)` takes exactly what the recorder writes to MCAP (`/tracking`,
`/zenoh/state`, `/zenoh/setpoint`, `/zenoh/voltage`, `/can/raw`, `/stats`; other topics are ignored) and returns the
`LiveMessage`s to publish (`sea_hil.live.channels`). A live message's log time is the log time of the recorded
message it comes from, so live values and times match the recording. Link and bus statistics and the running
verdict (`sea_hil.live.verdict`, under the session's `[verdict]` thresholds and lockstep flag) are emitted every
`period_s` of log time (and once more by `finish`, the verdict then `final`), with a `/live/events` line whenever
the verdict's status changes.

`/live/driver` comes from the drives' own frames, read by `protocol.drive_state` (the report's and the ROS 2
export's reader): the DBC's HEARTBEAT in the sea profile; on a cia402 bus (`follow_canopen`, the recorder calls it
when the session's config says so) each statusword TPDO is the node's state, so no TPDO is read as a DBC heartbeat.
"""
from __future__ import annotations

from typing import Any, NamedTuple

from sea_hil.config.verdict import VerdictConfig
from sea_hil.errors import MalformedFrame
from sea_hil.fault_explain import LATCH_WORD
from sea_hil.live.events import DriverWatch, event_log, log_message
from sea_hil.live.verdict import LiveVerdict
from sea_hil.protocol.cia402_decode import Cia402Decoder
from sea_hil.protocol.drive_state import DriveStateReader, drive_state_reader
from sea_hil.protocol.payloads import TriggerReason
from sea_hil.stats.histogram import LogHistogram
from sea_hil.stats.streams import BusLoad, SlidingRate, StreamStats

NS_PER_S = 1_000_000_000
RTT_STATES_KEPT = 4096   # states remembered for matching their setpoint (the controller answers within a few)
_REASON_CODES = {r.name: int(r) for r in TriggerReason}


class LiveMessage(NamedTuple):
    topic: str
    log_time_ns: int
    message: dict[str, Any]


def _sub(a: Any, b: Any) -> float | None:
    return a - b if isinstance(a, (int, float)) and isinstance(b, (int, float)) else None


class LiveView:
    """Derives the live channels from the recorded stream. One owner (not thread-safe)."""

    def __init__(self, *, bitrate_bps: int, period_s: float = 0.1, window_s: float = 1.0,
                 verdict: VerdictConfig | None = None, lockstep: bool = False,
                 floor: dict[str, float] | None = None, limbs: dict[int, str] | None = None) -> None:
        self.period_ns = int(period_s * NS_PER_S)
        self.window_s = window_s
        self.up = StreamStats("state", "up", window_s=window_s)
        self.down = StreamStats("setpoint", "down", window_s=window_s)
        self.bus = BusLoad(bitrate_bps, window_s)
        self._frame_rate = SlidingRate(window_s)
        self.rtt = LogHistogram(1e-6, 100.0)
        self.rtt_last_s: float | None = None
        self.ignored = 0
        self._state_rx: dict[int, int] = {}
        self._driver = DriverWatch()
        self.verdict = LiveVerdict(verdict, lockstep=lockstep, floor=floor, limbs=limbs)
        self._drive_states: DriveStateReader = drive_state_reader(None)   # the sea profile's until `follow_canopen`
        self._now_ns: int | None = None
        self._next_stats_ns: int | None = None

    def follow_canopen(self, decoder: Cia402Decoder) -> None:
        """The bus is a cia402 session's: the drives' state from their statuswords and EMCYs (module docstring).
        `decoder` is this view's own (it follows the bus's SDO remaps as it sees them)."""
        self._drive_states = drive_state_reader(decoder)

    # -- input ---------------------------------------------------------------------------------------------------
    def feed(self, topic: str, log_time_ns: int, payload: dict[str, Any]) -> list[LiveMessage]:
        """The live messages caused by one recorded message (possibly none)."""
        handler = self._HANDLERS.get(topic)
        if handler is None:
            return []
        out = handler(self, log_time_ns, payload)
        self._now_ns = log_time_ns if self._now_ns is None else max(self._now_ns, log_time_ns)
        if self._next_stats_ns is None:
            self._next_stats_ns = self._now_ns + self.period_ns
        elif self._now_ns >= self._next_stats_ns:
            out.extend(self.statistics())
            self._next_stats_ns += self.period_ns * max(1, (self._now_ns - self._next_stats_ns) // self.period_ns + 1)
        return out

    def finish(self) -> list[LiveMessage]:
        """The last statistics and the final verdict (at the end of the stream)."""
        return self.statistics(final=True) if self._now_ns is not None else []

    # -- per topic -----------------------------------------------------------------------------------------------
    def _tracking(self, t_ns: int, p: dict[str, Any]) -> list[LiveMessage]:
        self.verdict.on_tracking(t_ns, p)
        th1, th2, d1, d2 = (p.get(k) for k in ("theta1_rad", "theta2_rad", "theta1_d_rad", "theta2_d_rad"))
        msg = {"t_s": p.get("t_s"), "state_seq": int(p.get("state_seq", -1)), "theta1_rad": th1, "theta2_rad": th2,
               "theta1_d_rad": d1, "theta2_d_rad": d2, "e1_rad": _sub(d1, th1), "e2_rad": _sub(d2, th2),
               "event": bool(p.get("event", False)), "reason": str(p.get("reason", ""))}
        return [LiveMessage("/live/tracking", t_ns, msg)]

    def _state(self, t_ns: int, p: dict[str, Any]) -> list[LiveMessage]:
        self.up.add(t_ns, int(p.get("payload_bytes", 0)))
        self.verdict.on_state(p)
        seq = p.get("seq")
        if isinstance(seq, int):
            self._state_rx[seq] = t_ns
            if len(self._state_rx) > RTT_STATES_KEPT:
                del self._state_rx[next(iter(self._state_rx))]
        return []

    def _setpoint(self, t_ns: int, p: dict[str, Any]) -> list[LiveMessage]:
        self.down.add(t_ns, int(p.get("payload_bytes", 0)))
        self._round_trip(t_ns, p.get("state_seq"))
        reason = str(p.get("reason", ""))
        msg = {"seq": int(p.get("seq", -1)), "state_seq": int(p.get("state_seq", -1)),
               "delta1_ref_m": p.get("delta1_ref_m"), "delta2_ref_m": p.get("delta2_ref_m"), "s1": p.get("s1"),
               "s2": p.get("s2"), "reason": reason, "reason_code": _REASON_CODES.get(reason, -1)}
        out = [LiveMessage("/live/setpoint", t_ns, msg)]
        log = event_log(t_ns, msg)
        return out + ([LiveMessage("/live/events", t_ns, log)] if log is not None else [])

    def _voltage(self, t_ns: int, p: dict[str, Any]) -> list[LiveMessage]:
        self.down.add(t_ns, int(p.get("payload_bytes", 0)))
        self._round_trip(t_ns, p.get("state_seq"))
        return []

    def _can(self, t_ns: int, p: dict[str, Any]) -> list[LiveMessage]:
        self.verdict.on_can(t_ns)
        can_id, dlc, ext = p.get("can_id"), p.get("dlc"), bool(p.get("is_extended", False))
        if not isinstance(can_id, int) or not isinstance(dlc, int):
            self.ignored += 1
            return []
        try:
            self.bus.add_frame(t_ns, can_id, dlc, ext, bool(p.get("is_fd", False)))
            self._frame_rate.add(t_ns)
        except MalformedFrame:
            self.ignored += 1
            return []
        try:
            hb = self._drive_states.on_frame(can_id, bytes.fromhex(str(p.get("data_hex", ""))), dlc, extended=ext,
                                             fd=bool(p.get("is_fd", False)))
        except (MalformedFrame, ValueError):
            self.ignored += 1   # a malformed heartbeat: the recording keeps it in /can/raw
            return []
        if hb is None:
            return []
        self.verdict.on_heartbeat(t_ns, hb)
        msg, logs = self._driver.on_heartbeat(t_ns, hb)
        return [LiveMessage("/live/driver", t_ns, msg), *(LiveMessage("/live/events", t_ns, m) for m in logs)]

    def _stats(self, t_ns: int, p: dict[str, Any]) -> list[LiveMessage]:
        try:
            self.verdict.on_stats(p)
        except (KeyError, TypeError, ValueError):   # a record the verdict cannot read: shown, counted, not judged
            self.ignored += 1
        flat = {k: v for k, v in p.items() if isinstance(v, (int, float, bool))}
        return [LiveMessage("/live/node_stats", t_ns, flat)]

    def _fault(self, t_ns: int, p: dict[str, Any]) -> list[LiveMessage]:
        """A drive latch explained (limit, measured value, who clears it: sea_hil/fault_explain.py) goes to the Log
        panel as it is; the plain state changes are `_can`'s own."""
        return [LiveMessage("/live/events", t_ns, p)] if LATCH_WORD in str(p.get("message", "")) else []

    _HANDLERS = {"/tracking": _tracking, "/zenoh/state": _state, "/zenoh/setpoint": _setpoint,
                 "/zenoh/voltage": _voltage, "/can/raw": _can, "/stats": _stats, "/log/faults": _fault}

    # -- statistics ----------------------------------------------------------------------------------------------
    def _round_trip(self, t_ns: int, state_seq: Any) -> None:
        sent = self._state_rx.get(state_seq) if isinstance(state_seq, int) else None
        if sent is not None and t_ns >= sent:
            self.rtt_last_s = (t_ns - sent) / NS_PER_S
            self.rtt.record(self.rtt_last_s)

    def statistics(self, final: bool = False) -> list[LiveMessage]:
        """`/live/link`, `/live/bus` and `/live/verdict` (`final`: the last) at the latest log time seen, and a
        `/live/events` line when the verdict's status has changed."""
        now = self._now_ns
        if now is None:
            return []
        link: dict[str, Any] = {"window_s": self.window_s, "rtt_count": self.rtt.count}
        for name, s in (("up", self.up), ("down", self.down)):
            d = s.to_dict(now)
            link.update({f"{name}_msgs_per_s": d["msgs_per_s"], f"{name}_bytes_per_s": d["wire_bytes_per_s"],
                         f"{name}_msgs": d["messages"], f"{name}_bytes": d["wire_bytes"]})
        h = self.rtt.to_dict()
        link["rtt_last_us"] = None if self.rtt_last_s is None else self.rtt_last_s * 1e6
        for q in ("p50", "p90", "p99", "max"):
            v = h[q]
            link[f"rtt_{q}_us"] = None if v is None else float(v) * 1e6
        b = self.bus
        bus = {"frames": b.frames, "frames_per_s": self._frame_rate.rates(now)[0], "load_pct": b.window_load_pct(now),
               "load_pct_session": b.session_load_pct(now), "bitrate_bps": b.bitrate_bps, "window_s": self.window_s}
        verdict, level = self.verdict.message(final)
        out = [LiveMessage("/live/link", now, link), LiveMessage("/live/bus", now, bus),
               LiveMessage("/live/verdict", now, verdict)]
        if level is not None:
            out.append(LiveMessage("/live/events", now, log_message(now, level, "verdict", verdict_line(verdict))))
        return out


def verdict_line(msg: dict[str, Any]) -> str:
    """The `/live/events` line of a verdict status change: the status and every reason."""
    return f"verdict {msg['status']}" + ("" if not msg["reasons"] else ": " + "; ".join(msg["reasons"]))
