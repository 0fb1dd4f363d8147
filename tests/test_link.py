"""Link emulator statistics, determinism, rate limiting, ordering, DelayQueue and the CLI spec parser.

Statistical checks use Z = 4 standard errors derived from the distribution (binomial / CLT for the mean /
kurtosis-based SE of the sample variance); the seeds are fixed, so the tests are deterministic.
"""
from __future__ import annotations

import math
import statistics
from itertools import pairwise

import pytest

from sea_hil.config.comms import LinkDirectionConfig
from sea_hil.errors import ConfigError
from sea_hil.protocol.link import DelayQueue, LinkEmulator, parse_link_spec

N = 20_000
Z = 4.0
MS = 1_000_000
PERIOD_NS = 10 * MS


def _run(cfg: LinkDirectionConfig, seed: int = 1, n: int = N, size: int = 100) -> list[int | None]:
    link = LinkEmulator(cfg, seed)
    return [link.submit(i * PERIOD_NS, size) for i in range(n)]


def _added_s(out: list[int | None]) -> list[float]:
    return [(d - i * PERIOD_NS) / 1e9 for i, d in enumerate(out) if d is not None]


def test_fixed_delay_is_exact():
    out = _run(LinkDirectionConfig(delay_s=0.02), n=100)
    assert all(d == i * PERIOD_NS + 20 * MS for i, d in enumerate(out))


@pytest.mark.parametrize("dist,mean_extra,std_factor,kurtosis", [
    ("uniform", 0.0, 1 / math.sqrt(3), 1.8),
    ("normal", 0.0, 1.0, 3.0),
    ("exponential", 1.0, 1.0, 9.0),
])
def test_jitter_mean_and_std(dist, mean_extra, std_factor, kurtosis):
    delay, j = 0.020, 0.002  # normal: P(delay + N(0, j) < 0) ~ 1e-23, so clipping is irrelevant
    cfg = LinkDirectionConfig(delay_s=delay, jitter_s=j, jitter_dist=dist, reorder=True)
    x = _added_s(_run(cfg))
    sigma = j * std_factor
    assert abs(statistics.fmean(x) - (delay + mean_extra * j)) < Z * sigma / math.sqrt(N)
    se_var = sigma**2 * math.sqrt((kurtosis - 1) / N)
    assert abs(statistics.variance(x) - sigma**2) < Z * se_var


def test_independent_loss_rate():
    p = 0.05
    link = LinkEmulator(LinkDirectionConfig(loss=p), 3)
    lost = sum(link.submit(i * PERIOD_NS, 10) is None for i in range(N))
    assert abs(lost - N * p) < Z * math.sqrt(N * p * (1 - p))
    c = link.counters()
    assert (c.submitted, c.dropped_random, c.dropped_burst, c.delivered) == (N, lost, 0, N - lost)


def test_gilbert_elliott_burst_length():
    p_gb, p_bg = 0.02, 0.25
    cfg = LinkDirectionConfig(ge_p_good_to_bad=p_gb, ge_p_bad_to_good=p_bg, ge_loss_bad=1.0)
    link = LinkEmulator(cfg, 4)
    lost = [link.submit(i * PERIOD_NS, 10) is None for i in range(N)]
    bursts, run = [], 0
    for x in lost + [False]:
        if x:
            run += 1
        elif run:
            bursts.append(run)
            run = 0
    # burst length ~ geometric(p_bg): mean 1/p_bg, std sqrt(1 - p_bg)/p_bg
    se = math.sqrt(1 - p_bg) / p_bg / math.sqrt(len(bursts))
    assert abs(statistics.fmean(bursts) - 1 / p_bg) < Z * se
    expected_bursts = N * p_gb * p_bg / (p_gb + p_bg)  # entries into BAD
    assert abs(len(bursts) - expected_bursts) < 0.25 * expected_bursts
    c = link.counters()
    assert c.dropped_burst == sum(lost) and c.dropped_random == 0


def test_rate_limit_serialises_and_queues():
    cfg = LinkDirectionConfig(rate_bps=1e6)  # 125 bytes = 1000 bits = 1 ms
    link = LinkEmulator(cfg, 0)
    out = [link.submit(i * MS // 2, 125) for i in range(1000)]  # offered at 2x the link rate
    assert out[0] == 1 * MS and out[-1] == 1000 * MS
    assert all(b - a == MS for a, b in pairwise(out))  # throughput = rate exactly
    assert link.counters().mean_added_delay_s == pytest.approx((1 + 0.5 * 499.5) * 1e-3, rel=1e-9)  # (i+1) - i/2 ms


def test_rate_limit_queue_limit_tail_drops():
    link = LinkEmulator(LinkDirectionConfig(rate_bps=1e6, queue_limit_s=0.01), 0)
    out = [link.submit(0, 125) for _ in range(50)]
    assert sum(d is not None for d in out) == 11  # waits of 0..10 ms are allowed
    assert link.counters().dropped_queue == 39


def test_same_seed_same_decisions_and_independent_streams():
    cfg = LinkDirectionConfig(delay_s=0.01, jitter_s=0.003, loss=0.1, ge_p_good_to_bad=0.05, reorder=True)
    assert _run(cfg, seed=9, n=2000) == _run(cfg, seed=9, n=2000)
    assert _run(cfg, seed=9, n=2000) != _run(cfg, seed=10, n=2000)
    no_jitter = cfg.model_copy(update={"jitter_s": 0.0})
    dropped = [d is None for d in _run(cfg, seed=9, n=2000)]
    assert dropped == [d is None for d in _run(no_jitter, seed=9, n=2000)]
    up, down = LinkEmulator(cfg, "5/up"), LinkEmulator(cfg, "5/down")   # the edge's two directions' streams
    assert [up.submit(0, 1) for _ in range(200)] != [down.submit(0, 1) for _ in range(200)]


def test_order_preserved_unless_reorder():
    base = dict(delay_s=0.005, jitter_s=0.004, jitter_dist="normal")
    period = MS  # jitter >> period, so reordering would be common
    fifo = LinkEmulator(LinkDirectionConfig(**base), 2)
    out = [fifo.submit(i * period, 10) for i in range(2000)]
    assert all(b >= a for a, b in pairwise(out))
    loose = LinkEmulator(LinkDirectionConfig(**base, reorder=True), 2)
    out = [loose.submit(i * period, 10) for i in range(2000)]
    assert any(b < a for a, b in pairwise(out))
    assert all(d >= i * period for i, d in enumerate(out))  # never before it was sent


def test_delay_queue():
    q: DelayQueue[str] = DelayQueue()
    assert q.next_due_ns() is None and q.pop_due(10**18) == []
    for t, item in [(30, "c"), (10, "a"), (20, "b1"), (20, "b2")]:
        q.push(t, item)
    assert q.next_due_ns() == 10 and len(q) == 4
    assert q.pop_due(9) == []
    assert q.pop_due(20) == ["a", "b1", "b2"]
    assert q.pop_due(100) == ["c"] and len(q) == 0


def test_parse_link_spec():
    d = parse_link_spec("delay=20ms, jitter=500us,dist=normal,loss=1%,ge=0.01/0.3/80%,rate=1Mbps,qlimit=1s,reorder=on")
    assert d == {"delay_s": 0.02, "jitter_s": pytest.approx(5e-4), "jitter_dist": "normal", "loss": 0.01,
                 "ge_p_good_to_bad": 0.01, "ge_p_bad_to_good": 0.3, "ge_loss_bad": 0.8, "rate_bps": 1e6,
                 "queue_limit_s": 1.0, "reorder": True}
    LinkDirectionConfig(**d)
    assert parse_link_spec("") == {} and parse_link_spec("delay=0") == {"delay_s": 0.0}
    assert parse_link_spec("rate=64kbps")["rate_bps"] == 64e3


@pytest.mark.parametrize("spec", ["delay=20", "delay=-1ms", "delay=xms", "loss=2", "loss=101%", "ge=0.1",
                                  "ge=0.1/0.2/0.3/0.4", "rate=1MB", "dist=pareto", "reorder=maybe", "foo=1",
                                  "delay", "loss=nan"])
def test_parse_link_spec_rejects(spec):
    with pytest.raises(ConfigError, match="link spec"):
        parse_link_spec(spec)
