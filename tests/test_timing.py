"""The `[timing]` policy of the real-time driver loop (sea_hil/runtime/realtime.py, docs/timing.md) as pure units:
the thread policy's fallbacks, the pacer's schedule on a stub node, the removed levers' legacy keys; and the payload
validation fast paths taken for the Zenoh hop (same verdicts as the general path)."""
from __future__ import annotations

import logging
import math
import os
import struct
import threading
from types import SimpleNamespace

import pytest

from bench import bench_session_timing as bst
from sea_hil.config.loader import load_config
from sea_hil.config.timing import TimingConfig
from sea_hil.errors import ConfigError
from sea_hil.protocol.payload_fields import PayloadRejected, RejectReason, pair_field, uint_field
from sea_hil.protocol.payloads import (
    MsgType,
    PayloadCounters,
    SetpointPayload,
    StatePayload,
    TriggerReason,
    decode,
    encode,
)
from sea_hil.runtime import clock as clock_module
from sea_hil.runtime.clock import RealTimePacer
from sea_hil.runtime.realtime import ThreadPolicy


def test_thread_policy_falls_back_with_one_log_line(monkeypatch, caplog) -> None:
    def refuse(*_a: object) -> None:
        raise PermissionError(1, "Operation not permitted")
    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    out: dict[str, object] = {}
    policy = ThreadPolicy(TimingConfig(realtime_priority=50, realtime_scope="process"))
    t = threading.Thread(target=lambda: out.update(policy.apply()))
    with caplog.at_level(logging.INFO, logger="sea_hil.runtime"):
        t.start()
        t.join()
    assert out == {}   # nothing took effect, nothing raised
    policy.undo()
    assert sum("SCHED_FIFO" in r.message for r in caplog.records) == 1


class _StubNode:
    """What `RealTimePacer` uses of a driver node, on a fake monotonic clock: a wait until t moves the clock to t."""

    def __init__(self, timing: TimingConfig, clock: list[int]) -> None:
        self.cfg = SimpleNamespace(timing=timing)
        self.period_ns, self.heartbeat_every, self.drivers = 1_000_000, 10**9, {}
        self.lateness = SimpleNamespace(record=lambda _v: None)
        self.stats = SimpleNamespace(overruns=0, ticks=0)
        self.clock, self.waits, self.exits, self.taken = clock, [], [], []

    def prepare_kernels(self) -> None:
        pass

    def on_loop_exit(self, fn: object) -> None:
        self.exits.append(fn)

    def step_drivers(self) -> list:
        return []                                   # no limbs: the pacer's schedule alone

    def publish_samples(self, samples: list, heartbeats: bool = False) -> None:
        pass

    def send_pending(self) -> None:
        pass

    def wait_until(self, deadline_ns: int) -> None:
        self.waits.append(deadline_ns)
        self.clock[0] = max(self.clock[0], deadline_ns)

    def take_pending(self, mono_now_ns: int) -> None:
        self.taken.append(mono_now_ns)


def test_pacer_waits_for_each_absolute_deadline(monkeypatch) -> None:
    clock = [10**9]
    monkeypatch.setattr(clock_module, "time", SimpleNamespace(monotonic_ns=lambda: clock[0]))
    node = _StubNode(TimingConfig(realtime_priority=0), clock)
    pacer = RealTimePacer(node)
    pacer.start(None)
    assert len(node.exits) == 1                     # the thread policy is undone when the loop ends
    pacer.tick()
    pacer.tick()
    assert node.waits == [10**9 + 1_000_000, 10**9 + 2_000_000]   # absolute deadlines: start + k periods
    assert node.taken == node.waits                 # one pass over the frames queued, at each wake
    assert node.stats.overruns == 0 and node.stats.ticks == 2
    for undo in node.exits:
        undo()


def test_timing_section_is_validated() -> None:
    assert load_config().timing == TimingConfig()
    with pytest.raises(ConfigError):
        load_config(overrides={"timing": {"realtime_priority": 100}})


@pytest.mark.parametrize("key", ["spin_us", "gc_in_slack", "gc_slack_us", "switch_interval_us", "driver_cpu"])
def test_removed_levers_load_with_a_warning(key: str) -> None:
    """An older config file with a lever measured as no gain still loads: the key is dropped, with a warning
    saying why (sea_hil/config/legacy.py)."""
    with pytest.warns(FutureWarning, match=f"timing.{key} was removed.*docs/timing.md"):
        cfg = load_config(overrides={"timing": {key: 1, "realtime_priority": 7}})
    assert cfg.timing.realtime_priority == 7 and not hasattr(cfg.timing, key)


def test_payload_fast_paths_give_the_general_verdicts() -> None:
    assert pair_field("x", [1, 2]) == (1.0, 2.0)
    t = (0.5, -1.0)
    assert pair_field("x", t) is t
    for bad, reason in (((math.nan, 1.0), RejectReason.NONFINITE), ((1.0, math.inf), RejectReason.NONFINITE),
                        ((1.0, 2.0, 3.0), RejectReason.RANGE), ("ab", RejectReason.RANGE)):
        with pytest.raises(PayloadRejected) as err:
            pair_field("x", bad)
        assert err.value.reason is reason
    assert uint_field("n", 7, 10) == 7
    for bad in (True, -1, 11, 2.0):
        with pytest.raises(PayloadRejected):
            uint_field("n", bad, 10)
    data = bytearray(encode(SetpointPayload(1, 2, 3, (0.1, 0.2), (0.0, 0.0), TriggerReason.HEARTBEAT)))
    p = decode(bytes(data))
    assert p.reason is TriggerReason.HEARTBEAT
    c = PayloadCounters()
    data[-1] = 99                                    # unknown trigger reason
    assert c.try_decode(bytes(data)) is None and c.rejected["enum"] == 1
    data[3] = 77                                     # unknown message type
    assert c.try_decode(bytes(data)) is None and c.rejected["type"] == 1
    assert int(MsgType.SETPOINT) == 2
    state = StatePayload(4, 5, 6, (0.1, 0.2), (0.3, 0.4), (0.5, 0.6), (0.7, 0.8), epoch=9)
    back = decode(encode(state))                     # the trusted fast path: equal in every field, hash, repr
    assert back == state and hash(back) == hash(state) and repr(back) == repr(state)
    raw = bytearray(encode(state))
    raw[-8:] = struct.pack("<d", math.nan)           # a non-finite float still gets the constructor's verdict
    assert c.try_decode(bytes(raw)) is None and c.rejected["nonfinite"] == 1
    raw[-16:] = struct.pack("<2d", 1e308, 1e308)     # finite, but the sum overflows: the constructor accepts
    assert decode(bytes(raw)).nut_vel_m_s == (1e308, 1e308)


def test_sched_fifo_is_applied_and_undone_where_permitted() -> None:
    seen: list[int] = []

    def body() -> None:
        policy = ThreadPolicy(TimingConfig(realtime_priority=5))
        applied = policy.apply()
        seen.append(os.sched_getscheduler(0))
        policy.undo()
        seen.append(os.sched_getscheduler(0))
        seen.append(int("sched_fifo" in applied))
    t = threading.Thread(target=body)
    t.start()
    t.join()
    if not seen[2]:
        pytest.skip("SCHED_FIFO not permitted here")
    assert seen[:2] == [os.SCHED_FIFO, os.SCHED_OTHER]


def test_session_timing_bench_records() -> None:
    """bench/bench_session_timing.py (figure 4s) from rows, without a session: median of the runs, each run judged
    beside its own floor and, at 1 limb, on latency; loaded figures are not judged; A/B."""
    def row(m: int, floor_pct: float = 0.0, limbs: int = 1, p50: float = 400.0, p99: float = 1400.0) -> dict:
        return {"limbs": limbs, "ticks": 10_000, "tick_misses": m, "miss_pct": m / 100, "floor_miss_pct": floor_pct,
                "cpu_us_per_tick": 500.0, "cpu_us_per_limb_sample": 500.0 / limbs, "latency_p50_us": p50,
                "latency_p99_us": p99, "wall_s": 12.0}
    rows = [row(m) for m in (5, 8, 9)]
    rec = bst.default_record(rows)
    assert rec["figure"] == "4s" and rec["median"] == pytest.approx(0.08) and rec["goal_met"] is True
    assert rec["baseline"] == 0.0
    assert bst.default_record([row(30)])["goal_met"] is False                  # 0.30 % beside a 0 % floor
    assert bst.default_record([row(30, floor_pct=0.25)])["goal_met"] is True   # 0.05 % beyond its floor
    assert bst.default_record([row(5, p50=600.0)])["goal_met"] is False        # latency p50 above 0.5 ms
    assert bst.default_record([row(30, limbs=2)], limbs=2)["figure"] == "4s-2l"
    four = bst.default_record([row(90, limbs=4, p50=2000.0, p99=2900.0)], limbs=4)
    assert four["figure"] == "4s-4l" and four["goal_met"] is True               # <= 1 %, p99 <= 3 ms
    assert bst.default_record([row(90, limbs=4, p99=3100.0)], limbs=4)["goal_met"] is False
    loaded = bst.default_record([row(300)], loaded=True)
    assert loaded["figure"] == "4s-loaded" and loaded["goal_met"] is None
    lev = bst.lever_record("fifo", [(row(30), row(5)), (row(30), row(8))])
    assert lev["baseline"] == pytest.approx(0.30) and lev["median"] == pytest.approx(0.065)
    assert "realtime_priority = 50" in bst._toml(bst.LEVERS["fifo"]) and 'realtime_scope = "process"' in bst._toml(
        bst.LEVERS["fifo-process"])
