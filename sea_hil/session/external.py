"""`sea-hil run --controller external`: the session hosts plant, edge and recorder and waits for a controller from
outside (any program speaking docs/external-controller.md) instead of starting its own.

When the cycles are done (`ExternalWatch`, from what crosses Zenoh only, no edge internals): the controller's time
axis starts at the sample time T of the first state it answers (a SETPOINT, VOLTAGE or ACK naming `state_seq`) plus
`trajectory.lead_in_s`, exactly as the built-in controller's (controller/remote.py); the session is over once the
edge has published a state sampled after T + lead-in + cycles x period (the built-in controller stops at that state
too), and the controller's tracking records (`event` key) for every state it answered have arrived, or `grace_s`
of wall time has passed without them (records are optional for control, needed only for the summary's tracking).
No answer within `join_timeout_s` of wall time ends the session with a `SeaHilError`.

`OutsideController` has the part of `subprocess.Popen`'s interface the session uses (`wait`, `poll`,
`terminate`, `kill`, `returncode`), so `sea_hil.session.run` treats it like the controller child it replaces.
"""
from __future__ import annotations

import json
import logging
import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path

import zenoh

from sea_hil.config.root import SeaHilConfig
from sea_hil.errors import SeaHilError
from sea_hil.protocol.keys import KEY_PAYLOADS, Keys
from sea_hil.protocol.payloads import AckPayload, PayloadCounters, SetpointPayload, StatePayload, VoltagePayload

log = logging.getLogger("sea_hil.session")
_KEEP_STATES = 4096     # state seq -> sample time entries kept (an answer refers to a recent state)


class ExternalWatch:
    """Pure core: fed the states, answers and tracking records seen on Zenoh, says when the cycles are done."""

    def __init__(self, lead_in_s: float, duration_s: float, grace_s: float = 1.0) -> None:
        self.lead_in_ns = int(round(lead_in_s * 1e9))
        self.duration_ns = int(round(duration_s * 1e9))
        self.grace_ns = int(round(grace_s * 1e9))
        self._sampled: dict[int, int] = {}
        self.newest_sample_ns = 0
        self.first_answer_sample_ns: int | None = None
        self.answered: set[int] = set()
        self.recorded: set[int] = set()
        self._cycles_done_at_ns: int | None = None

    def on_state(self, seq: int, sample_t_ns: int) -> None:
        self._sampled[seq] = sample_t_ns
        self._sampled.pop(seq - _KEEP_STATES, None)
        self.newest_sample_ns = max(self.newest_sample_ns, sample_t_ns)

    def on_answer(self, state_seq: int) -> None:
        if self.first_answer_sample_ns is None:
            self.first_answer_sample_ns = self._sampled.get(state_seq, self.newest_sample_ns)
        self.answered.add(state_seq)

    def on_record(self, state_seq: int) -> None:
        self.recorded.add(state_seq)

    @property
    def joined(self) -> bool:
        return self.first_answer_sample_ns is not None

    @property
    def end_sample_ns(self) -> int | None:
        """Sample time of the last state inside the measured cycles (None before the controller joined)."""
        if self.first_answer_sample_ns is None:
            return None
        return self.first_answer_sample_ns + self.lead_in_ns + self.duration_ns

    def done(self, now_ns: int) -> bool:
        """True once the cycles are over and the records are in (or the grace time after the cycles has passed)."""
        end = self.end_sample_ns
        if end is None or self.newest_sample_ns <= end:
            return False
        if self._cycles_done_at_ns is None:
            self._cycles_done_at_ns = now_ns
        return self.answered <= self.recorded or now_ns - self._cycles_done_at_ns >= self.grace_ns


class OutsideController:
    """Stands in for the controller child process: watches Zenoh until an outside controller has done its cycles."""

    def __init__(self, cfg: SeaHilConfig, cycles: int, session: zenoh.Session, *, endpoint: str, config_path: Path,
                 lockstep: bool, join_timeout_s: float, log: Callable[[str], None] = print) -> None:
        self.returncode: int | None = None
        self.endpoint = endpoint          # where the outside controller connects (`sea_hil.Session.endpoint`)
        self.join_timeout_s = join_timeout_s
        self.watch = ExternalWatch(cfg.trajectory.lead_in_s, cfg.trajectory.period_s * cycles)
        self.payloads = PayloadCounters()
        self.bad_records = 0
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._t0 = time.monotonic()
        keys = Keys.from_config(cfg.zenoh)
        self._subs = [session.declare_subscriber(getattr(keys, ch), self._on_payload(ch))
                      for ch in ("state", "setpoint", "voltage", "control")]
        self._subs.append(session.declare_subscriber(keys.event, self._on_record))
        mode = " --lockstep" if lockstep else ""
        log(f"external controller: connect to Zenoh endpoint {endpoint}; session config {config_path}; keys "
            f"{keys.prefix}/{keys.limb}/*; waiting up to {join_timeout_s:.0f} s, e.g.\n"
            f"  python examples/external_controller/controller.py --connect {endpoint} --config {config_path} "
            f"--cycles {cycles}{mode}")

    def _on_payload(self, channel: str) -> Callable[[zenoh.Sample], None]:
        """The callback of key `channel`: a payload of another type than the key carries is not an answer."""
        accepts = KEY_PAYLOADS[channel]

        def on_payload(sample: zenoh.Sample) -> None:
            p = self.payloads.try_decode(sample.payload.to_bytes(), accepts)
            with self._lock:
                if isinstance(p, StatePayload):
                    self.watch.on_state(p.seq, p.sample_t_ns)
                elif isinstance(p, (SetpointPayload, VoltagePayload, AckPayload)):
                    self.watch.on_answer(p.state_seq)
            self._wake.set()
        return on_payload

    def _on_record(self, sample: zenoh.Sample) -> None:
        try:
            seq = int(json.loads(sample.payload.to_bytes())["state_seq"])
        except (ValueError, KeyError, TypeError) as err:
            self.bad_records += 1     # not a tracking record: counted, logged (first and every 1000th), ignored
            if self.bad_records % 1000 == 1:
                log.warning("ignored %d event-key message(s) that are not tracking records: %s", self.bad_records, err)
            return
        with self._lock:
            self.watch.on_record(seq)
        self._wake.set()

    def poll(self) -> int | None:
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        """0 once the controller's cycles are done; `subprocess.TimeoutExpired` after `timeout`; `SeaHilError` if no
        controller answered within the join timeout."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while self.returncode is None:
            with self._lock:
                done, joined = self.watch.done(time.monotonic_ns()), self.watch.joined
            if done:
                self._end(0)
                break
            now = time.monotonic()
            if not joined and now - self._t0 > self.join_timeout_s:
                self._end(2)
                raise SeaHilError(f"no external controller answered a state within {self.join_timeout_s:.0f} s "
                                  "(docs/external-controller.md)")
            if deadline is not None and now >= deadline:
                raise subprocess.TimeoutExpired("external controller", timeout or 0.0)
            self._wake.wait(0.1 if deadline is None else max(0.0, min(0.1, deadline - now)))
            self._wake.clear()
        code = self.returncode
        assert code is not None
        return code

    def _end(self, code: int) -> None:
        if self.returncode is None:
            self.returncode = code
            for sub in self._subs:
                sub.undeclare()
            rejected = self.payloads.as_dict()["rejected_total"]
            if rejected or self.bad_records:
                log.warning("external controller session: %s malformed payload(s), %d bad tracking record(s)",
                            rejected, self.bad_records)

    def terminate(self) -> None:
        self._end(-15)

    def kill(self) -> None:
        self._end(-9)
