"""Trace-driven link emulation: a per-packet trace (t_s,delay_s,lost) replayed exactly, looped, validated."""
from __future__ import annotations

from pathlib import Path

import pytest

from sea_hil.config.comms import LinkDirectionConfig
from sea_hil.errors import ConfigError
from sea_hil.protocol.link import LinkEmulator, parse_link_spec
from sea_hil.protocol.link_trace import load_trace, parse_trace

REPO = Path(__file__).resolve().parents[1]
MS = 1_000_000


def _trace_file(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "trace.csv"
    p.write_text(text, encoding="utf-8")
    return p


def test_replay_matches_rows_and_loops(tmp_path: Path) -> None:
    p = _trace_file(tmp_path, "t_s,delay_s,lost\n5.00,0.004,0\n5.01,0.020,0\n5.02,0.003,1\n5.03,0.001,0\n")
    link = LinkEmulator(LinkDirectionConfig(trace_path=str(p), reorder=True), seed=0)
    # rows are relative to the first packet; duration = span 30 ms + median gap 10 ms = 40 ms
    assert link.submit(0, 50) == 4 * MS
    assert link.submit(10 * MS, 50) == 30 * MS
    assert link.submit(20 * MS, 50) is None                   # lost in the trace
    assert link.submit(39 * MS, 50) == 40 * MS                # row 5.03 covers 30..40 ms
    assert link.submit(40 * MS + 5 * MS, 50) == 49 * MS       # looped: row 5.00 again
    c = link.counters()
    assert (c.submitted, c.delivered, c.dropped_trace, c.dropped) == (5, 4, 1, 1)


def test_fifo_order_holds_back_a_fast_packet_behind_a_slow_one(tmp_path: Path) -> None:
    p = _trace_file(tmp_path, "t_s,delay_s,lost\n0,0.030,0\n0.01,0.001,0\n")
    link = LinkEmulator(LinkDirectionConfig(trace_path=str(p)), seed=0)
    assert link.submit(0, 10) == 30 * MS
    assert link.submit(10 * MS, 10) == 30 * MS                # would arrive at 11 ms, but FIFO like one stream


def test_same_trace_same_decisions_whatever_the_seed(tmp_path: Path) -> None:
    p = REPO / "configs" / "traces" / "wifi-synthetic.csv"
    runs = []
    for seed in (1, 2):
        link = LinkEmulator(LinkDirectionConfig(trace_path=str(p)), seed=seed)
        runs.append([link.submit(k * 10 * MS, 88) for k in range(4000)])   # 40 s: longer than the 30 s trace
    assert runs[0] == runs[1]
    trace = load_trace(p)
    lost = sum(r is None for r in runs[0])
    assert lost == sum(trace.at(k * 10 * MS)[1] for k in range(4000)) > 0


def test_shipped_traces_have_their_documented_character() -> None:
    wifi = load_trace(REPO / "configs" / "traces" / "wifi-synthetic.csv")
    g5 = load_trace(REPO / "configs" / "traces" / "5g-synthetic.csv")
    for t in (wifi, g5):
        assert len(t.t_ns) == 3000 and t.duration_ns == 30_000 * MS
        assert 0.002 < t.loss_fraction < 0.03
    med = {n: sorted(t.delay_ns)[len(t.delay_ns) // 2] / MS for n, t in (("wifi", wifi), ("5g", g5))}
    assert 1.5 < med["wifi"] < 5 and 7 < med["5g"] < 11


def test_spec_key_resolves_and_reads_the_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _trace_file(tmp_path, "t_s,delay_s,lost\n0,0.001,0\n0.01,0.002,0\n")
    monkeypatch.chdir(tmp_path)
    out = parse_link_spec("trace=trace.csv,rate=1Mbps")
    assert out == {"trace_path": str(tmp_path / "trace.csv"), "rate_bps": 1e6}
    with pytest.raises(ConfigError, match="link trace not found"):
        parse_link_spec("trace=missing.csv")
    with pytest.raises(ConfigError, match="do not combine trace"):
        parse_link_spec("trace=trace.csv,delay=5ms")


@pytest.mark.parametrize(("text", "match"), [
    ("t,delay,lost\n0,0,0\n1,0,0\n", "header"),
    ("t_s,delay_s,lost\n0,0.001,0\n", "at least 2 packets"),
    ("t_s,delay_s,lost\n0,0.001,0\n0.01,x,0\n", r":3: t_s and delay_s must be numbers"),
    ("t_s,delay_s,lost\n0,0.001,0\n0.01,-0.001,0\n", r":3: .*>= 0"),
    ("t_s,delay_s,lost\n0,0.001,0\n0.01,0.001,maybe\n", r":3: lost must be 0 or 1"),
    ("t_s,delay_s,lost\n0.02,0.001,0\n0.01,0.001,0\n", r":3: t_s 0.01 goes back in time"),
    ("t_s,delay_s,lost\n0,0.001\n", r":2: expected 3 columns"),
    ("t_s,delay_s,lost\n0,nan,0\n0.01,0.001,0\n", r":2: .*finite"),
])
def test_malformed_traces_are_rejected_with_the_line(text: str, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        parse_trace(text.splitlines(), "t.csv")
