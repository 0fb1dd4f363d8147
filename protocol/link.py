"""Seeded, pure network-link emulation for one direction, driven by explicit time (no clock reads).

Per submitted message, in this order:
1. Rate limit (if `rate_bps` > 0): the message is serialised after every earlier accepted message
   (`start = max(t, busy_until)`, `tx = 8 * bytes / rate_bps`); if it would wait longer than `queue_limit_s`
   (> 0) it is tail-dropped (`dropped_queue`) and consumes nothing.
2. Loss: Gilbert-Elliott state of the *current* message decides the loss probability (`loss` in GOOD,
   `ge_loss_bad` in BAD; `dropped_random` / `dropped_burst`); then the state moves (GOOD->BAD with
   `ge_p_good_to_bad`, BAD->GOOD with `ge_p_bad_to_good`). With p_good_to_bad = 0 this is independent loss.
   Lost messages have already used the link (lost on the wire, after serialisation).
3. Delay: `deliver = serialised_end + delay_s + jitter`, jitter ~ uniform(-j, +j) (j = half-width, std j/sqrt(3)),
   normal(0, j) (std j) or exponential(mean j) (std j, one-sided); the added delay is clipped at >= 0.
   With `trace_path` set, steps 2-3 come from the trace instead (`sea_hil.protocol.link_trace`: the delay and
   loss of the trace packet sent at the same time, the trace looped; `dropped_trace`).
4. Order: `reorder=False` (default, like one TCP stream) delivers FIFO: `deliver = max(deliver, last_deliver)`;
   `reorder=True` lets jitter reorder messages.

Independent RNG streams (loss, GE state, jitter) are derived from the seed, so e.g. changing the jitter does not
change which messages are lost. Same seed + same inputs -> identical decisions.
"""
from __future__ import annotations

import heapq
import random
from dataclasses import dataclass
from pathlib import Path
from typing import Generic, TypeVar

from pydantic import ValidationError

from sea_hil.config.comms import LinkDirectionConfig
from sea_hil.errors import ConfigError
from sea_hil.protocol.link_trace import load_trace

T = TypeVar("T")
NS_PER_S = 1_000_000_000


@dataclass(frozen=True)
class LinkCounters:
    submitted: int
    dropped_random: int
    dropped_burst: int
    dropped_queue: int
    delivered: int
    mean_added_delay_s: float
    dropped_trace: int = 0

    @property
    def dropped(self) -> int:
        return self.dropped_random + self.dropped_burst + self.dropped_queue + self.dropped_trace


class LinkEmulator:
    """One direction of an impaired link. `submit` returns the delivery time in ns, or None if dropped."""

    def __init__(self, cfg: LinkDirectionConfig, seed: int | str) -> None:
        self.cfg = cfg
        self._rng_loss = random.Random(f"sea-hil-link/{seed}/loss")
        self._rng_ge = random.Random(f"sea-hil-link/{seed}/ge")
        self._rng_jitter = random.Random(f"sea-hil-link/{seed}/jitter")
        self._delay_ns = round(cfg.delay_s * NS_PER_S)
        self._trace = load_trace(cfg.trace_path) if cfg.trace_path else None
        self._dropped_trace = 0
        self._bad = False
        self._busy_until_ns: int | None = None
        self._last_deliver_ns: int | None = None
        self._submitted = self._dropped_random = self._dropped_burst = self._dropped_queue = 0
        self._delivered = 0
        self._added_delay_sum_ns = 0

    def _jitter_ns(self) -> float:
        j = self.cfg.jitter_s
        if j <= 0:
            return 0.0
        r = self._rng_jitter
        if self.cfg.jitter_dist == "uniform":
            x = r.uniform(-j, j)
        elif self.cfg.jitter_dist == "normal":
            x = r.gauss(0.0, j)
        else:
            x = r.expovariate(1.0 / j)
        return x * NS_PER_S

    def _lost(self) -> bool:
        """Loss decision in the current GE state, then the state transition. Returns True if lost."""
        c = self.cfg
        bad = self._bad
        lost = self._rng_loss.random() < (c.ge_loss_bad if bad else c.loss)
        if c.ge_p_good_to_bad > 0 or bad:
            p = c.ge_p_bad_to_good if bad else c.ge_p_good_to_bad
            if self._rng_ge.random() < p:
                self._bad = not bad
        if lost:
            if bad:
                self._dropped_burst += 1
            else:
                self._dropped_random += 1
        return lost

    def submit(self, t_ns: int, payload_len_bytes: int) -> int | None:
        """Offer a message of `payload_len_bytes` (as counted against `rate_bps`) at time `t_ns`."""
        if payload_len_bytes < 0:
            raise ValueError("payload_len_bytes must be >= 0")
        self._submitted += 1
        c = self.cfg
        sent_ns = t_ns
        if c.rate_bps > 0:
            start = t_ns if self._busy_until_ns is None else max(t_ns, self._busy_until_ns)
            if c.queue_limit_s > 0 and start - t_ns > c.queue_limit_s * NS_PER_S:
                self._dropped_queue += 1
                return None
            sent_ns = start + round(payload_len_bytes * 8 * NS_PER_S / c.rate_bps)
            self._busy_until_ns = sent_ns
        if self._trace is not None:
            delay_ns, lost = self._trace.at(sent_ns)
            if lost:
                self._dropped_trace += 1
                return None
            deliver = sent_ns + delay_ns
        elif self._lost():
            return None
        else:
            deliver = sent_ns + self._delay_ns + round(self._jitter_ns())
        deliver = max(deliver, sent_ns)
        if not c.reorder and self._last_deliver_ns is not None:
            deliver = max(deliver, self._last_deliver_ns)
        self._last_deliver_ns = deliver if self._last_deliver_ns is None else max(deliver, self._last_deliver_ns)
        self._delivered += 1
        self._added_delay_sum_ns += deliver - t_ns
        return deliver

    def counters(self) -> LinkCounters:
        mean = self._added_delay_sum_ns / self._delivered / NS_PER_S if self._delivered else 0.0
        return LinkCounters(self._submitted, self._dropped_random, self._dropped_burst, self._dropped_queue,
                            self._delivered, mean, self._dropped_trace)


def release_sample_ns(deliver_ns: int, period_ns: int) -> int:
    """The sample (on a clock stepped every `period_ns`) at which a message delivered at `deliver_ns` is released:
    the first sample at or after its delivery (lockstep and the offline engine stamp a released state with it)."""
    return -(-deliver_ns // period_ns) * period_ns


class DelayQueue(Generic[T]):
    """Items held until their delivery time; ties leave in insertion order."""

    def __init__(self) -> None:
        self._heap: list[tuple[int, int, T]] = []
        self._n = 0

    def push(self, deliver_at_ns: int, item: T) -> None:
        heapq.heappush(self._heap, (deliver_at_ns, self._n, item))
        self._n += 1

    def pop_due(self, now_ns: int) -> list[T]:
        out: list[T] = []
        while self._heap and self._heap[0][0] <= now_ns:
            out.append(heapq.heappop(self._heap)[2])
        return out

    def next_due_ns(self) -> int | None:
        return self._heap[0][0] if self._heap else None

    def __len__(self) -> int:
        return len(self._heap)


# --- CLI spec parser ---------------------------------------------------------------------------------------------
_TIME_UNITS = {"ns": 1e-9, "us": 1e-6, "ms": 1e-3, "s": 1.0}
_RATE_UNITS = {"bps": 1.0, "kbps": 1e3, "mbps": 1e6, "gbps": 1e9}
_BOOLS = {"on": True, "true": True, "yes": True, "1": True, "off": False, "false": False, "no": False, "0": False}


def _number(text: str, what: str) -> float:
    try:
        v = float(text)
    except ValueError as err:
        raise ConfigError(f"link spec: {what} {text!r} is not a number") from err
    if v != v or v in (float("inf"), float("-inf")) or v < 0:
        raise ConfigError(f"link spec: {what} {text!r} must be a finite number >= 0")
    return v


def _with_unit(text: str, units: dict[str, float], what: str) -> float:
    low = text.strip().lower()
    for unit in sorted(units, key=len, reverse=True):
        if low.endswith(unit):
            return _number(low[: -len(unit)], what) * units[unit]
    if _number(low, what) == 0:
        return 0.0
    raise ConfigError(f"link spec: {what} {text!r} needs a unit ({', '.join(units)})")


def _probability(text: str, what: str) -> float:
    t = text.strip()
    v = _number(t[:-1], what) / 100 if t.endswith("%") else _number(t, what)
    if v > 1:
        raise ConfigError(f"link spec: {what} {text!r} is not a probability in [0, 1] (or 0..100%)")
    return v


def parse_link_spec(spec: str) -> dict[str, float | str | bool]:
    """`"delay=20ms,jitter=5ms,dist=normal,loss=1%,ge=0.01/0.3/0.8,rate=1Mbps,qlimit=50ms,reorder=on"` ->
    `LinkDirectionConfig` field overrides (validated). `ge=p_good_to_bad/p_bad_to_good[/loss_bad]`;
    `trace=FILE.csv` replays a per-packet trace (`sea_hil.protocol.link_trace`), optionally with rate/qlimit/reorder."""
    out: dict[str, float | str | bool] = {}
    for item in (s.strip() for s in spec.split(",")):
        if not item:
            continue
        key, sep, val = item.partition("=")
        key, val = key.strip().lower(), val.strip()
        if not sep or not val:
            raise ConfigError(f"link spec: {item!r} is not key=value")
        if key in ("delay", "jitter", "qlimit"):
            field = {"delay": "delay_s", "jitter": "jitter_s", "qlimit": "queue_limit_s"}[key]
            out[field] = _with_unit(val, _TIME_UNITS, key)
        elif key == "dist":
            out["jitter_dist"] = val.lower()
        elif key == "loss":
            out["loss"] = _probability(val, key)
        elif key == "ge":
            parts = val.split("/")
            if len(parts) not in (2, 3):
                raise ConfigError(f"link spec: ge={val!r} must be p_good_to_bad/p_bad_to_good[/loss_bad]")
            names = ("ge_p_good_to_bad", "ge_p_bad_to_good", "ge_loss_bad")
            out.update({n: _probability(p, f"ge.{n}") for n, p in zip(names, parts, strict=False)})
        elif key == "rate":
            out["rate_bps"] = _with_unit(val, _RATE_UNITS, key)
        elif key == "trace":   # resolved (a config written for another process stays valid) and read at once
            out["trace_path"] = trace_path = str(Path(val).expanduser().resolve())
            load_trace(trace_path)
        elif key == "reorder":
            if val.lower() not in _BOOLS:
                raise ConfigError(f"link spec: reorder={val!r} must be on/off")
            out["reorder"] = _BOOLS[val.lower()]
        else:
            raise ConfigError(f"link spec: unknown key {key!r} (delay, jitter, dist, loss, ge, rate, qlimit, reorder, "
                              "trace)")
    try:
        LinkDirectionConfig(**out)
    except ValidationError as err:
        msg = "; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in err.errors())
        raise ConfigError(f"link spec {spec!r}: {msg}") from err
    return out
