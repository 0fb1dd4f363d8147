"""Which clock a recording's MCAP `log_time` is in (docs/recording.md, "Clocks").

* `wall` (real-time sessions, `sea-hil record`): the wall clock, `time.time_ns()` scale - CAN frames at their bus
  timestamp, Zenoh messages when the recorder took them.
* `sample` (lockstep sessions): the session's sample time, i.e. the emulated drive's own clock (`seq x period`, the
  feedback `t_us` unwrapped; 0 = the drive's first sample), so simulated seconds are seconds on every plot's time axis
  whatever the wall-clock pace of the run. A frame is logged at the sample time of its node's latest
  FEEDBACK_ANGLE (the VOLTAGE_CMD answering sample k at k's time); a Zenoh state at its `sample_t_ns`, a setpoint,
  voltage or trigger event at the sample time of the state it answers (`state_seq`); anything else at the newest
  sample time seen.

`SampleClock` is pure bookkeeping (no I/O); the CAN tap and the Zenoh tap each keep one (they may live in different
processes; both read the same drive clock off the wire).
"""
from __future__ import annotations

from collections import OrderedDict
from typing import Literal

from sea_hil.errors import RecordingError
from sea_hil.protocol.can_assembly import unwrap_us

TimeBase = Literal["wall", "sample"]
TIME_BASES: tuple[str, ...] = ("wall", "sample")


def check_time_base(time_base: str) -> TimeBase:
    if time_base == "wall":
        return "wall"
    if time_base == "sample":
        return "sample"
    raise RecordingError(f"time base must be one of {TIME_BASES}, got {time_base!r}")


class SampleClock:
    """The drive's sample time as seen in recorded traffic: per node from feedback `t_us`, per state seq from Zenoh
    states. `now_ns` is the newest sample time seen (0 before any)."""

    def __init__(self, keep_states: int = 4096) -> None:
        self._t_us: dict[int, int] = {}            # node id -> unwrapped feedback time, us
        self._state_ns: OrderedDict[int, int] = OrderedDict()
        self._keep = keep_states
        self.now_ns = 0

    def on_feedback(self, node_id: int, t_us: int) -> int:
        """A FEEDBACK_ANGLE with wrapped `t_us` from `node_id` -> its sample time (ns)."""
        prev = self._t_us.get(node_id)
        full = t_us if prev is None else unwrap_us(prev, t_us)
        self._t_us[node_id] = full
        self.now_ns = max(self.now_ns, full * 1000)
        return full * 1000

    def node_ns(self, node_id: int) -> int:
        """Sample time of `node_id`'s latest feedback (the newest sample time when none was seen)."""
        full = self._t_us.get(node_id)
        return self.now_ns if full is None else full * 1000

    def on_state(self, seq: int, sample_t_ns: int) -> int:
        self._state_ns[seq] = sample_t_ns
        self._state_ns.move_to_end(seq)
        while len(self._state_ns) > self._keep:
            self._state_ns.popitem(last=False)
        self.now_ns = max(self.now_ns, sample_t_ns)
        return sample_t_ns

    def state_ns(self, seq: int) -> int:
        """Sample time of the state `seq` answers (the newest sample time when that state was not seen)."""
        return self._state_ns.get(seq, self.now_ns)
