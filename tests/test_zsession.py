"""Zenoh session helpers: two peers on loopback TCP (no multicast), newest-only subscriber, LinkedPublisher."""
from __future__ import annotations

import time
from collections.abc import Iterator

import pytest
import zenoh

from sea_hil.config.comms import LinkDirectionConfig, ZenohConfig
from sea_hil.errors import ConfigError
from sea_hil.protocol.keys import Keys
from sea_hil.protocol.link import LinkEmulator
from sea_hil.protocol.payloads import StatePayload, decode, encode
from sea_hil.protocol.zlatest import LatestSubscriber
from sea_hil.protocol.zsession import (
    LinkedPublisher,
    await_subscriber,
    free_tcp_port,
    make_config,
    open_session,
    publisher,
)

DEADLINE_S = 10.0


@pytest.fixture()
def pair() -> Iterator[tuple[zenoh.Session, zenoh.Session]]:
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    a = open_session(make_config(listen=[ep]))
    b = open_session(ZenohConfig(connect=(ep,)))
    try:
        yield a, b
    finally:
        b.close()
        a.close()


def _until(cond, what: str):
    """Poll `cond()` until it returns something truthy; fail after DEADLINE_S."""
    end = time.monotonic() + DEADLINE_S
    while time.monotonic() < end:
        got = cond()
        if got:
            return got
        time.sleep(0.0005)  # polling pause only; the condition itself is what we wait for
    pytest.fail(f"timed out waiting for {what}")


def _state(seq: int) -> bytes:
    return encode(StatePayload(seq, time.monotonic_ns(), seq, (0.1, 0.2), (0.0, 0.0), (0.0, 0.0), (0.0, 0.0)))


def _seq_of(sample: zenoh.Sample | None) -> int | None:
    return None if sample is None else decode(sample.payload.to_bytes()).seq


def _wait_seq(sub: LatestSubscriber, seq: int) -> None:
    """Late connection probes (seq 0) may still arrive first; wait for `seq` itself."""
    _until(lambda: _seq_of(sub.recv(0.05)) == seq, f"seq {seq}")


def _connect(pub: zenoh.Publisher, sub: LatestSubscriber) -> None:
    """Wait until the subscription has propagated: publish probes (seq 0) until one arrives."""
    def probe():
        pub.put(_state(0))
        return sub.recv(0.005)
    _until(probe, "the subscriber to match")


def test_exchange_state_payload(pair):
    a, b = pair
    keys = Keys.make("test", "limb1")
    with LatestSubscriber(b, keys.state) as sub:
        pub = publisher(a, keys.state)
        _connect(pub, sub)
        pub.put(_state(42))
        got = _until(lambda: (s := sub.recv(0.05)) is not None and _seq_of(s) == 42 and s, "seq 42")
        p = decode(got.payload.to_bytes())
        assert p.seq == 42 and p.theta_rad == (0.1, 0.2)
        assert sub.recv(0.0) is None  # taken


def test_ring_subscriber_keeps_only_newest(pair):
    a, b = pair
    keys = Keys.make("test", "limb1")
    with LatestSubscriber(b, keys.state) as ring:
        marker = b.declare_subscriber(keys.control, zenoh.handlers.FifoChannel(16))
        pub = publisher(a, keys.state, congestion_control=zenoh.CongestionControl.BLOCK)
        _connect(pub, ring)
        # the marker's subscription propagates on its own (CI once put the marker before `a` knew of it): probe it too
        _until(lambda: (a.put(keys.control, b"probe"), marker.try_recv())[1], "the marker subscriber to match")
        ring.recv(0.0)
        for seq in range(1, 101):
            pub.put(_state(seq))
        # Same session, priority and transport: the marker is delivered after all 100 states.
        a.put(keys.control, b"burst-done", priority=zenoh.Priority.REAL_TIME, express=True,
              congestion_control=zenoh.CongestionControl.BLOCK)
        _until(lambda: (m := marker.try_recv()) is not None and m.payload.to_bytes() == b"burst-done",
               "the burst marker")          # late probes may come first
        newest = ring.recv(0.0)
        assert newest is not None and decode(newest.payload.to_bytes()).seq == 100
        assert ring.recv(0.0) is None
        marker.undeclare()


class _Recorder:
    def __init__(self) -> None:
        self.sent: list[bytes] = []

    def put(self, payload: bytes) -> None:
        self.sent.append(payload)


def test_linked_publisher_holds_until_poll():
    rec = _Recorder()
    lp = LinkedPublisher(rec, LinkEmulator(LinkDirectionConfig(delay_s=0.002), 0))
    assert lp.put(b"a", 0) == 2_000_000 and lp.put(b"b", 1_000_000) == 3_000_000
    assert rec.sent == [] and lp.pending == 2 and lp.next_due_ns() == 2_000_000
    assert lp.poll(1_999_999) == 0
    assert lp.poll(3_000_000) == 2 and rec.sent == [b"a", b"b"] and lp.published == 2
    direct = LinkedPublisher(rec, LinkEmulator(LinkDirectionConfig(), 0))
    direct.put(b"c", 5)
    assert rec.sent[-1] == b"c" and direct.pending == 0  # an unimpaired link publishes at once
    lossy = LinkedPublisher(rec, LinkEmulator(LinkDirectionConfig(loss=1.0), 0))
    assert lossy.put(b"d", 0) is None and lossy.pending == 0 and lossy.link.counters().dropped_random == 1


def test_linked_publisher_over_zenoh(pair):
    a, b = pair
    keys = Keys.make("test", "limb1")
    with LatestSubscriber(b, keys.setpoint) as sub:
        raw = publisher(a, keys.setpoint)
        _connect(raw, sub)
        lp = LinkedPublisher(raw, LinkEmulator(LinkDirectionConfig(delay_s=0.001), 0))
        lp.put(_state(7), 0)
        assert _seq_of(sub.recv(0.05)) in (None, 0)  # held by the emulated link, not yet published
        assert lp.pending == 1
        lp.poll(1_000_000)
        _wait_seq(sub, 7)


@pytest.mark.parametrize("kw", [dict(listen=["nonsense"]), dict(connect=["tcp/"]), dict(mode="bogus"),
                                dict(listen=["foo/bar"])])
def test_bad_endpoint_is_config_error(kw):
    with pytest.raises(ConfigError):
        s = open_session(make_config(**kw))
        s.close()


def test_config_validation_of_keys():
    with pytest.raises(ConfigError):
        Keys.from_config(ZenohConfig.model_construct(prefix="sea", limb="a*"))


def test_latest_recv_times_out_and_takes_the_newest_of_what_queued(pair):
    a, b = pair
    keys = Keys.make("test", "limb1")
    with LatestSubscriber(b, keys.state) as sub:
        assert sub.recv(0.01) is None and sub.recv(0.0) is None     # nothing came
        marker = b.declare_subscriber(keys.control, zenoh.handlers.FifoChannel(16))
        pub = publisher(a, keys.state, congestion_control=zenoh.CongestionControl.BLOCK)
        _connect(pub, sub)
        _until(lambda: (a.put(keys.control, b"probe"), marker.try_recv())[1], "the marker subscriber")
        sub.recv(0.0)
        for seq in (1, 2, 3):
            pub.put(_state(seq))
        a.put(keys.control, b"after-3", priority=zenoh.Priority.REAL_TIME, express=True,
              congestion_control=zenoh.CongestionControl.BLOCK)    # same session and priority: delivered after them
        _until(lambda: (m := marker.try_recv()) is not None and m.payload.to_bytes() == b"after-3", "the marker")
        before = sub.overwritten
        assert _seq_of(sub.recv(1.0)) == 3 and sub.overwritten == before + 2 and sub.recv(0.0) is None
        marker.undeclare()
    sub.close()                                             # idempotent


def test_await_subscriber_waits_for_a_subscription_declared_across_the_router():
    """Two clients of one listening peer (the guest topology's controller and recorder): the publisher's wait ends
    unmatched after its bound with no subscriber, and matched once the other client's subscription has reached it."""
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    router = open_session(make_config(listen=[ep]))
    ctl, rec = (open_session(make_config(connect=[ep], mode="client")) for _ in range(2))
    try:
        pub = publisher(ctl, "test/limb1/event", express=False)
        assert not await_subscriber(pub, 0.05)
        sub = rec.declare_subscriber("test/**", zenoh.handlers.FifoChannel(4))
        assert await_subscriber(pub, DEADLINE_S)
        sub.undeclare()
    finally:
        for s in (rec, ctl, router):
            s.close()
